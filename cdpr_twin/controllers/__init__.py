"""Controllers at the control rate, chosen by name: ``open_loop`` (§IV-B) and ``pbvs`` (§IV-C).

Each registers itself in :mod:`cdpr_twin.plugins`, the registry it shares with estimators.
"""

from __future__ import annotations

from typing import Any

from cdpr_twin import plugins
from cdpr_twin.controllers.base import Controller, RunEnd
from cdpr_twin.controllers.open_loop import OpenLoopController
from cdpr_twin.controllers.pbvs import PbvsController
from cdpr_twin.geometry import CdprGeometry
from cdpr_twin.types import Command


def make_controller(name: str, geometry: CdprGeometry, **options: Any) -> Controller:
    """Build a registered controller by name with keyword options (SI units).

    Raises:
        ValueError: for an unknown name or bad options.
    """
    return plugins.build("controller", name, geometry, **options)


__all__ = [
    "Command",
    "Controller",
    "OpenLoopController",
    "PbvsController",
    "RunEnd",
    "make_controller",
]
