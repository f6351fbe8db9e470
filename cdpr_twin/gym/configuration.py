"""What an environment's arguments make of its scenario, checked before anything is built."""

from __future__ import annotations

import dataclasses
import numbers
from collections.abc import Mapping
from types import MappingProxyType

import numpy as np

from cdpr_twin import plugins
from cdpr_twin.scenario.loading import EstimatorConfig, Scenario, load_scenario


def configure(
    scenario: str | Scenario,
    estimator: str,
    camera: bool | None,
    wants: Mapping[str, bool],
    scale: float,
    realism: str | None,
) -> Scenario:
    """The scenario an episode runs: one estimator, the camera as asked, scaled truth.

    ``camera`` ``None``: on where ``wants`` (the environment's own needs, named) or the
    estimator needs it — asked once the scenario is loaded, whose plugins may register it.

    Raises:
        ScenarioError: an unknown estimator or profile, or the camera off where it is needed.
        ValueError: a truth scale that is not a number ≥ 0; ``camera=False`` against ``wants``.
    """
    s = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    camera = camera_choice(camera, wants, needs_camera(estimator))
    s = s if realism is None else s.with_realism(realism, label="realism")
    opts = {n: o for n, o in s.estimators.options.items() if n == estimator}
    s = dataclasses.replace(s, estimators=EstimatorConfig(estimator, (), MappingProxyType(opts)))
    if not (np.isfinite(scale) and scale >= 0):
        raise ValueError(f"truth_scale must be ≥ 0 (0: the nominal robot), got {scale}")
    stds = {f.name: getattr(s.truth, f.name) * scale for f in dataclasses.fields(s.truth)}
    del stds["seed"]
    s = dataclasses.replace(s, truth=dataclasses.replace(s.truth, **stds))
    return s.with_overrides(in_loop=estimator, camera=camera, names=("estimator=", "camera=False"))


def needs_camera(estimator: str) -> bool:
    """Whether the estimator reads the tag (an unknown name: False; the scenario refuses it)."""
    try:
        return bool(getattr(plugins.lookup("estimator", estimator), "needs_camera", False))
    except ValueError:
        return False


def camera_choice(camera: bool | None, wants: Mapping[str, bool], estimator: bool) -> bool:
    """The camera: as given, or (``None``) on where ``wants`` or the ``estimator`` needs it.

    An estimator's need against ``camera=False`` is the scenario's to refuse, naming both.

    Raises:
        ValueError: ``camera=False`` where something in ``wants`` needs it (named).
    """
    needing = [who for who, need in wants.items() if need]
    if camera is None:
        return bool(needing) or estimator
    if needing and not camera:
        verb = "needs" if len(needing) == 1 else "need"
        raise ValueError(f"{' and '.join(needing)} {verb} the camera: drop camera=False")
    return bool(camera)


def check_arguments(on_fault: str | None, **scales: float) -> None:
    """Refuse an unknown ``on_fault`` and scales that are not positive numbers (ValueError)."""
    if on_fault not in (None, "stop", "continue"):
        raise ValueError(f"on_fault must be 'stop', 'continue' or None, got {on_fault!r}")
    for name, v in scales.items():
        if isinstance(v, bool) or not (isinstance(v, numbers.Real) and v > 0 and v < np.inf):
            raise ValueError(f"{name} must be a positive number, got {v!r}")
