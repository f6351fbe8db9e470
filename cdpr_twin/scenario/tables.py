"""Tables of a scenario file that are values of their own: truth, realism, events, plugins.

Read by :func:`cdpr_twin.scenario.loading.load_scenario`; each function takes the top-level reader
and
returns the table's value in SI units, with errors naming the file and field. Also the rule of
a run without the camera (:func:`without_camera`), whose errors name the command-line option
or the file's field that asked for what conflicts.
"""

from __future__ import annotations

import copyreg
import functools
import math
from dataclasses import dataclass, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

from cdpr_twin import plugins, resources
from cdpr_twin.files.inputs import shown
from cdpr_twin.files.paths import path_kind
from cdpr_twin.options import OptionError
from cdpr_twin.robot.deviations import DeviationSpec
from cdpr_twin.robot.realism import PARTS, PROFILES, Realism, profile
from cdpr_twin.robot.realism_limits import (
    MAX_POSITION_ERROR_STD,
    MAX_PULLEY_RADIUS_STD,
    MAX_ROTATION_ERROR_STD,
    check_at_most,
    check_relative_std,
)
from cdpr_twin.scenario.toml_reading import (
    OptionReader,
    ScenarioError,
    build_options,
    parse_options,
    read_options,
)
from cdpr_twin.sim.events import EVENT_KINDS, Event


def _read_only(items: dict) -> MappingProxyType:
    return MappingProxyType(items)


# A scenario pickles (to worker processes, e.g. a calibration's recording segments): its
# read-only mappings (overrides, estimator options) travel as copies and come back read-only.
copyreg.pickle(MappingProxyType, lambda m: (_read_only, (dict(m),)))


@dataclass(frozen=True)
class MonitorConfig:
    """``[monitor]``: what the run does when the robot reports a fault.

    Attributes:
        on_fault: ``"stop"`` (the default: the run ends at the tick of the fault with status
            ``fault: <what>``, exit code 3) or ``"continue"`` (the fault is recorded, the run
            goes on).
        enabled: check the robot's limits at all (faults of MuJoCo's divergence stay errors).
    """

    on_fault: str = "stop"
    enabled: bool = True


def read_monitor(top: OptionReader) -> MonitorConfig:
    """``[monitor]`` (optional)."""
    r = top.table_of("monitor", required=False)
    out = MonitorConfig(
        r.string("on_fault", "stop", choices=("stop", "continue")), r.boolean("enabled", True)
    )
    r.done()
    return out


def read_events(top: OptionReader) -> tuple[Event, ...]:
    """``[[events]]``: timed events, in file order."""
    raw = top.raw("events", [], "array of tables [[events]]")
    if not isinstance(raw, list) or not all(isinstance(e, dict) for e in raw):
        raise top.fail("events", "must be an array of tables [[events]] (kind, at, …)")
    out = []
    for i, table in enumerate(raw):
        r = OptionReader(top.source, table, f"events[{i}]")
        cls = EVENT_KINDS.get(r.string("kind", choices=tuple(EVENT_KINDS)))
        out.append(parse_options(r, cls, skip=("kind",)))
    return tuple(out)  # in file order (errors name events[i] as the file numbers them)


def read_realism(top: OptionReader) -> Realism:
    """``[realism]``: a named profile and its overridden fields (``[realism.<part>]``)."""
    r = top.table_of("realism", required=False)
    name = r.string("profile", "ideal", choices=PROFILES)
    values = {}
    for part, cls in PARTS.items():
        if r.has(part):
            t = r.table_of(part)
            v = read_options(t, cls, required=False)
            build_options(t, cls, functools.partial(_one_part, name, part), v)  # names a bad field
            values[part] = v
    r.done(tuple(PARTS))
    return profile(name, **values)


def _one_part(name: str, part: str, **values: Any) -> Realism:
    return profile(name, **{part: values})


def read_plugins(top: OptionReader) -> tuple[str, ...]:
    """``plugins``: import them (they register estimators or controllers) and list them."""
    refs = top.raw("plugins", [], "list of module names or .py files")
    if not isinstance(refs, list) or not all(isinstance(x, str) and "\x00" not in x for x in refs):
        raise top.fail("plugins", f"must be a list of module names or .py files, got {shown(refs)}")
    try:
        plugins.load_modules(refs, top.source.parent)
    except Exception as exc:  # an import error in the user's module: say which and why
        raise top.fail("plugins", f"cannot import: {type(exc).__name__}: {exc}") from None
    return tuple(refs)


_POINT = " m (a built robot's points are off its description by millimetres)"
_MOUNT = "° (a calibrated camera mount or a tag placed by hand: tenths of a degree)"
TRUTH_BOUNDS = {
    "exit_point_std": ("m", MAX_POSITION_ERROR_STD, _POINT),
    "anchor_point_std": ("m", MAX_POSITION_ERROR_STD, _POINT),
    "pulley_radius_std": ("m", MAX_PULLEY_RADIUS_STD, " m (sheaves are machined to ±0.2 mm)"),
    "camera_position_std": ("m", MAX_POSITION_ERROR_STD, _POINT),
    "camera_rotation_std_deg": ("deg", math.degrees(MAX_ROTATION_ERROR_STD), _MOUNT),
    "tag_position_std": ("m", MAX_POSITION_ERROR_STD, _POINT),
    "tag_rotation_std_deg": ("deg", math.degrees(MAX_ROTATION_ERROR_STD), _MOUNT),
}
"""``[truth]``'s stds in the file's units: (unit, bound, why)
(:mod:`cdpr_twin.robot.realism_limits`)."""


def read_truth(top: OptionReader, source: Path) -> DeviationSpec:
    """``[truth]``: the robot's calibration errors (standard deviations) and its seed.

    Each std is bounded by how far a built robot can be off its description
    (:data:`TRUTH_BOUNDS`; ``es_scale_std`` as a relative std), so that a draw is a robot.
    """
    t = top.table_of("truth", required=False)
    values = {
        key: t.number(key, 0.0, minimum=0, unit=unit) for key, (unit, *_) in TRUTH_BOUNDS.items()
    }
    values["es_scale_std"] = t.number("es_scale_std", 0.0, minimum=0)
    try:
        for key, (_, bound, why) in TRUTH_BOUNDS.items():
            check_at_most(key, values[key], bound, why)
        check_relative_std("es_scale_std", values["es_scale_std"], "cable's E·S")
    except OptionError as exc:
        raise t.fail(exc.field, exc.problem) from None
    for key in ("camera_rotation_std_deg", "tag_rotation_std_deg"):
        values[key.removesuffix("_deg")] = math.radians(values.pop(key))
    truth = DeviationSpec(**values, seed=t.integer("seed", 0, minimum=0))
    t.done()
    return truth


def read_nominal(m: OptionReader, source: Path) -> Path | None:
    """``[model] nominal``: the robot description the software believes, or ``None``.

    A ``robot.toml`` (e.g. ``cdpr-twin calibrate``'s ``calibrated_robot.toml``) whose geometry,
    camera mount and tag pose replace the model file's in what estimators and controllers see.
    """
    if not m.has("nominal"):
        return None
    path = Path(m.string("nominal"))
    path = path if path.is_absolute() else (source.parent / path).resolve()
    kind = path_kind(path, lambda why: m.fail("nominal", why))
    if kind != "file":
        what = {"dir": "is a directory", "other": "is not a regular file"}.get(kind, "not found")
        raise m.fail("nominal", f"{path} {what}; give a robot.toml (cdpr-twin calibrate)")
    return path


def read_model_file(m: OptionReader, source: Path) -> Path:
    """``robot = "<name>"`` (a shipped robot, the default ``acrobot``) or ``file = "<path>"``."""
    if m.has("robot") and m.has("file"):
        raise m.fail("robot", "give either robot (a shipped robot's name) or file, not both")
    if m.has("file"):
        file = Path(m.string("file"))
        return file if file.is_absolute() else (source.parent / file).resolve()
    name = m.string("robot", "acrobot")
    try:
        return resources.robot_scene(name)
    except resources.ResourceError as exc:
        raise m.fail("robot", str(exc)) from None


def read_payload_com(m: OptionReader) -> tuple[float, ...]:
    """``[model] payload_com_m``: the payload's centre of mass in F_p [m] (default the origin)."""
    com = m.raw("payload_com_m", [0.0, 0.0, 0.0], "array of 3 numbers [m]")
    ok = isinstance(com, list) and len(com) == 3
    number = (int, float)
    if not ok or not all(
        isinstance(v, number) and not isinstance(v, bool) and math.isfinite(v) for v in com
    ):
        raise m.fail("payload_com_m", f"must be 3 numbers [x, y, z] in metres, got {shown(com)}")
    return tuple(float(v) for v in com)


def _needs_camera(kind: str, name: str) -> bool:
    return bool(getattr(plugins.lookup(kind, name), "needs_camera", False))


def without_camera(
    s: Any, done: dict, names: tuple[str, str] = ("--in-loop ", "--no-camera")
) -> Any:
    """Refuse what needs the camera in the loop; drop passive estimators that need it.

    Args:
        s: the :class:`cdpr_twin.scenario.loading.Scenario`, its camera off.
        done: its overrides so far (``in_loop``; ``camera`` false), to name who asked for each
            side of a conflict; dropped estimators are added.
        names: how the caller names those overrides: a prefix to the in-loop estimator's
            name, and the camera turned off (the CLI's ``--in-loop``, ``--no-camera``).

    Raises:
        ScenarioError: the in-loop estimator or the controller needs the camera.

    Passive estimators that need the camera and ``tag_occlusion`` events are dropped, and
    listed in ``done`` (``dropped_estimators``, ``dropped_events``).
    """
    (pick, no_cam), off = names, done.get("camera") is False  # else the file's camera = false
    fix, other = f"drop {no_cam}" if off else "set sensors.camera = true", pick.strip(" =")
    in_loop = s.estimators.in_loop
    if _needs_camera("estimator", in_loop) and "in_loop" in done:  # the caller's in_loop
        why = f"{no_cam} turned it off" if off else f"{s.source} has sensors.camera = false"
        raise ScenarioError(
            f"{pick}{in_loop} needs the camera, but {why}; {fix} or give another {other}"
        )
    if _needs_camera("estimator", in_loop):
        field = f"{s.source}: estimators.in_loop: {in_loop!r} needs the camera"
        if off:
            raise ScenarioError(f"{no_cam}: {field}; {fix} or give another {other}")
        raise ScenarioError(f"{field}; choose another in-loop estimator or keep the camera on")
    if _needs_camera("controller", s.controller.type):
        field = f"{s.source}: controller.type: {s.controller.type!r} needs the camera; {fix}"
        raise ScenarioError(f"{no_cam}: {field}" if off else field)
    dropped = [n for n in s.estimators.passive if _needs_camera("estimator", n)]
    if dropped:  # nothing to see: drop them, and say so
        passive = tuple(n for n in s.estimators.passive if n not in dropped)
        s = replace(s, estimators=replace(s.estimators, passive=passive))
        done["dropped_estimators"] = dropped
    hidden = [f"events[{i}]" for i, e in enumerate(s.events) if e.kind == "tag_occlusion"]
    if hidden:  # no image to hide the tag in (its occluder would be a body in the physics)
        s = replace(s, events=tuple(e for e in s.events if e.kind != "tag_occlusion"))
        done["dropped_events"] = hidden
    return s
