"""Controllers at the control rate, chosen by name: ``open_loop`` (§IV-B) and ``pbvs`` (§IV-C)."""

from __future__ import annotations

from typing import Any

from cdpr_twin.controllers.base import Command, Controller
from cdpr_twin.controllers.open_loop import OpenLoopController
from cdpr_twin.controllers.pbvs import PbvsController
from cdpr_twin.geometry import CdprGeometry

CONTROLLERS: dict[str, type[Controller]] = {
    cls.name: cls for cls in (OpenLoopController, PbvsController)
}
"""Controller classes by name."""


def make_controller(name: str, geometry: CdprGeometry, **params: Any) -> Controller:
    """Build a controller by name.

    Raises:
        ValueError: for an unknown name or bad parameters.
    """
    try:
        cls = CONTROLLERS[name]
    except KeyError:
        raise ValueError(
            f"unknown controller {name!r}; choose one of {', '.join(CONTROLLERS)}"
        ) from None
    try:
        return cls(geometry, **params)
    except TypeError as exc:
        raise ValueError(f"controller {name!r}: bad parameters {sorted(params)}: {exc}") from None


__all__ = ["CONTROLLERS", "Command", "Controller", "make_controller"]
