"""Scenario files (TOML) → a frozen, validated :class:`Scenario`, in SI units.

This is the file edge (units and typed reading in :mod:`cdpr_twin.scenario.toml_reading`): poses
are written ``[x, y, z, rx, ry, rz]`` in metres and degrees, angles elsewhere carry ``_deg`` in
their key, and the PBVS goal is given in ViSP's tag frame as in the paper. The controller's and
each estimator's options are parsed from their own ``Options`` dataclasses (no name is special
here); errors name the file, the field and the fix. A scenario file is documented by
``scenarios/paper_open_loop.toml`` and ``paper_pbvs.toml``.

The tables that are values of their own (``[truth]``, ``[realism]``, ``[monitor]``,
``[[events]]``, plugins, the model files) are read first, one function each; then the rule of a
run without the camera (:func:`without_camera`), whose errors name the command-line option or
the file's field that asked for what conflicts; then the :class:`Scenario` itself.
"""

from __future__ import annotations

import copyreg
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from cdpr_twin import plugins, resources
from cdpr_twin.files.inputs import read_toml, shown
from cdpr_twin.files.paths import path_kind
from cdpr_twin.options import OptionError
from cdpr_twin.robot.deviations import DeviationSpec
from cdpr_twin.robot.realism import (
    MAX_POSITION_ERROR_STD,
    MAX_PULLEY_RADIUS_STD,
    MAX_ROTATION_ERROR_STD,
    MAX_TENSION_NOISE_STD,
    PARTS,
    PROFILES,
    TENSION_NOISE_WHY,
    Realism,
    check_at_most,
    check_relative_std,
    profile,
    profile_part,
    without_source,
)
from cdpr_twin.robot.schema import MAX_TIMESTEP, MIN_TIMESTEP
from cdpr_twin.scenario.toml_reading import (
    OptionReader,
    ScenarioError,
    build_options,
    parse_options,
    read_options,
)
from cdpr_twin.sim.events import EVENT_KINDS, Event


# ------------------------------------------------------- the tables that are values of their own
# Truth, realism, monitor, events, plugins, the model files: each function takes the top-level
# reader and returns the table's value in SI units, with errors naming the file and field.
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
        cls = EVENT_KINDS[r.string("kind", choices=tuple(EVENT_KINDS))]
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
    try:
        return profile(name, **values)
    except OptionError as exc:  # a rule across the parts (each part's own are checked above)
        raise r.fail(exc.field.removeprefix("realism."), exc.problem) from None


def _one_part(name: str, part: str, **values: Any) -> Any:
    return profile_part(name, part, **values)


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
(:mod:`cdpr_twin.robot.realism`)."""


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
        found = {"dir": "is a directory", "other": "is not a regular file"}
        what = found.get(kind or "", "not found")
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


MAX_NAME_BYTES = 255
"""The longest run name [bytes of UTF-8]: it names the output directory, and no file system
takes a longer name (NAME_MAX)."""
MAX_TICKS = 10**9
"""The most control periods a run may last (10⁹: 116 days at 100 Hz); more is a typo."""


@dataclass(frozen=True)
class ModelConfig:
    """Which model, and how to step it.

    Attributes:
        file: MJCF scene: a shipped robot's (``robot = "<name>"``) or any (``file = "<path>"``,
            relative to the scenario file).
        timestep: physics step [s].
        control_rate: control (and sensing) rate [Hz].
        align_every: physics steps between swivel/stiffness refreshes.
        nominal: a ``robot.toml`` (``cdpr-twin calibrate``'s output) the software believes.
        payload: mass fixed to the platform [kg] (``payload_kg``; ≤ the robot's rated one).
        payload_com: (3,) its centre of mass in F_p [m] (``payload_com_m``).
    """

    file: Path
    timestep: float
    control_rate: float
    align_every: int
    payload: float = 0.0
    payload_com: tuple[float, ...] = (0.0, 0.0, 0.0)
    nominal: Path | None = None

    @property
    def control_period(self) -> float:
        """Control period [s]."""
        return 1.0 / self.control_rate


@dataclass(frozen=True)
class SensorConfig:
    """Sensor settings.

    Attributes:
        tension_noise_std: std of tension noise [N].
        camera: render the onboard camera and detect the tag.
        tag_window: search the tag near its last place first (``vision.TagDetector``'s
            ``roi``): faster, equal to the whole-frame search to ~1e-5 px, not bit for bit.
    """

    tension_noise_std: float
    camera: bool
    tag_window: bool = False


@dataclass(frozen=True)
class ControllerConfig:
    """Controller name and its options.

    Attributes:
        type: a registered controller name.
        options: an instance of that controller's ``Options`` (SI units).
    """

    type: str
    options: Any


@dataclass(frozen=True)
class EstimatorConfig:
    """Which estimators run, and which one closes the loop.

    Attributes:
        in_loop: the estimator whose estimate feeds the controller.
        passive: estimators that run beside it.
        options: each estimator's ``Options`` instance, by name (defaults when absent).
    """

    in_loop: str
    passive: tuple[str, ...]
    options: Mapping[str, Any]

    @property
    def names(self) -> tuple[str, ...]:
        """All estimators, the in-loop one first, each once."""
        return tuple(dict.fromkeys((self.in_loop, *self.passive)))


@dataclass(frozen=True)
class Scenario:
    """One experiment.

    Attributes:
        name: run name (output directory name by default).
        source: the file it was read from.
        description: free text.
        duration: run length [s] (the run also stops when the controller is done).
        seed: run seed (sensor noise).
        start_pose: (4, 4) initial platform pose ᵇp_p0, known to every estimator.
        model: model and stepping.
        truth: the robot's calibration errors (robot seed inside).
        sensors: sensor settings.
        controller: controller configuration.
        estimators: estimator configuration.
        events: timed events (faults), in file order.
        monitor: what a fault of the robot does to the run (``[monitor]``).
        realism: the robot's and sensors' imperfections (``[realism]``; default: ideal).
        plugins: modules imported before the file's names were checked.
        overrides: the command-line overrides applied.
    """

    name: str
    source: Path
    description: str
    duration: float
    seed: int
    start_pose: np.ndarray
    model: ModelConfig
    truth: DeviationSpec
    sensors: SensorConfig
    controller: ControllerConfig
    estimators: EstimatorConfig
    events: tuple[Event, ...] = ()
    monitor: MonitorConfig = field(default_factory=MonitorConfig)
    plugins: tuple[str, ...] = ()
    realism: Realism = field(default_factory=Realism)
    overrides: Mapping[str, Any] = field(default_factory=dict)

    def with_overrides(
        self,
        seed: int | None = None,
        in_loop: str | None = None,
        duration: float | None = None,
        camera: bool | None = None,
        names: tuple[str, str] = ("--in-loop ", "--no-camera"),
    ) -> Scenario:
        """A copy with command-line overrides applied (and validated).

        ``names``: how the caller's errors name ``in_loop`` (a prefix to the estimator's name)
        and ``camera=False`` (the CLI's options; the gym env gives its own arguments).
        """
        s, done = self, dict(self.overrides)
        if seed is not None and (isinstance(seed, bool) or int(seed) != seed or seed < 0):
            raise ScenarioError(f"--seed must be an integer ≥ 0, got {seed}")
        if seed is not None:
            s = replace(s, seed=int(seed))
            done["seed"] = int(seed)
        if duration is not None:
            if not (math.isfinite(duration) and duration > 0):
                raise ScenarioError(f"--duration must be > 0 s, got {duration}")
            s = replace(s, duration=float(duration))
            done["duration"] = float(duration)
        ticks = s.duration / s.model.control_period
        if not (ticks <= MAX_TICKS and round(ticks) >= 1):  # as the run rounds: ≥ 1 tick
            where = "--duration" if duration is not None else f"{s.source}: duration"
            raise ScenarioError(
                f"{where}: {s.duration:g} s must span 1 to {MAX_TICKS:.0e} control periods "
                f"({s.model.control_period:g} s each)"
            )
        if camera is not None:
            s = replace(s, sensors=replace(s.sensors, camera=bool(camera)))
            done["camera"] = bool(camera)
        if in_loop is not None:
            try:
                plugins.lookup("estimator", in_loop)
            except ValueError as exc:  # named as the caller names it: --in-loop, estimator=
                raise ScenarioError(f"{names[0].strip(' =')}: {exc}") from None
            passive = tuple(n for n in s.estimators.names if n != in_loop)
            s = replace(s, estimators=replace(s.estimators, in_loop=in_loop, passive=passive))
            done["in_loop"] = in_loop
        if not s.sensors.camera:
            s = without_camera(s, done, names)
        return replace(s, overrides=MappingProxyType(done))

    def without(self, *sources: str) -> Scenario:
        """A copy with per-run sources of variation switched off (the decomposition's runs).

        Args:
            *sources: names from :data:`cdpr_twin.robot.realism.RUN_SOURCES`.

        Raises:
            ScenarioError: for an unknown source.
        """
        s = self
        for source in sources:
            if source == "tension_noise":
                s = replace(s, sensors=replace(s.sensors, tension_noise_std=0.0))
            try:
                s = replace(s, realism=without_source(s.realism, source))
            except ValueError as exc:
                raise ScenarioError(str(exc)) from None
        done = {**self.overrides, "without": [*self.overrides.get("without", ()), *sources]}
        return replace(s, overrides=MappingProxyType(done))

    def with_realism(self, name: str, label: str = "--realism") -> Scenario:
        """A copy with a named realism profile (no field overridden): ``--realism ideal``.

        Args:
            name: the profile.
            label: how the caller's errors name the choice (the CLI's option, an argument).

        Raises:
            ScenarioError: for an unknown profile.
        """
        try:
            realism = profile(name)
        except ValueError as exc:
            raise ScenarioError(f"{label}: {exc}") from None
        done = {**self.overrides, "realism": name}
        return replace(self, realism=realism, overrides=MappingProxyType(done))

    def with_controller_options(self, **options: Any) -> Scenario:
        """A copy with some controller options replaced (SI units), validated.

        Raises:
            ScenarioError: for an unknown option or an invalid value.
        """
        try:
            opts = replace(self.controller.options, **options)
        except (TypeError, ValueError) as exc:
            raise ScenarioError(f"{self.source}: controller: {exc}") from None
        done = {**self.overrides, "controller": {**options}}
        return replace(
            self,
            controller=replace(self.controller, options=opts),
            overrides=MappingProxyType(done),
        )


def _plugin(r: OptionReader, key: str, kind: str, name: str) -> type[plugins.Plugin]:
    """The registered class of a name the file gives; unknown: the installed ones listed."""
    try:
        return plugins.lookup(kind, name)
    except ValueError as exc:
        raise r.fail(key, str(exc)) from None


def _controller(r: OptionReader) -> ControllerConfig:
    kind = r.string("type")
    cls = _plugin(r, "type", "controller", kind)
    return ControllerConfig(kind, parse_options(r, cls.Options, skip=("type",)))


def _estimators(r: OptionReader) -> EstimatorConfig:
    in_loop = r.string("in_loop")
    _plugin(r, "in_loop", "estimator", in_loop)
    passive = r.raw("passive", [], "list of estimator names")
    if not isinstance(passive, list) or not all(isinstance(p, str) for p in passive):
        raise r.fail("passive", f"must be a list of estimator names, got {shown(passive)}")
    for name in passive:
        _plugin(r, "passive", "estimator", name)
    options: dict[str, Any] = {}
    for name in [k for k in r.table if k not in ("in_loop", "passive")]:
        cls = _plugin(r, name, "estimator", name)
        options[name] = parse_options(r.table_of(name), cls.Options)
    r.done()
    passive_t = tuple(p for p in dict.fromkeys(passive) if p != in_loop)
    return EstimatorConfig(in_loop, passive_t, MappingProxyType(options))


def _model(top: OptionReader, source: Path) -> ModelConfig:
    m = top.table_of("model", required=False)
    file = read_model_file(m, source)
    timestep = m.number("timestep", 0.0005, minimum=MIN_TIMESTEP, unit="s")
    if timestep > MAX_TIMESTEP:
        raise m.fail("timestep", f"must be ≤ {MAX_TIMESTEP} s for stiff cables, got {timestep}")
    control_rate = m.number("control_rate", 25.0, minimum=0, exclusive=True, unit="Hz")
    align_every = m.integer("align_every", 10, minimum=1)
    nominal = read_nominal(m, source)
    payload = m.number("payload_kg", 0.0, minimum=0, unit="kg"), read_payload_com(m)
    m.done(("file", "nominal"))
    steps = 1.0 / control_rate / timestep  # whole as the run steps it (winch.whole_steps)
    whole = math.isfinite(steps) and math.isclose(
        round(steps) * timestep, 1.0 / control_rate, rel_tol=1e-9, abs_tol=1e-12
    )
    if not whole or round(steps) < 1:
        raise m.fail(
            "control_rate",
            f"the control period 1/{control_rate:g} s is not a whole "
            f"number of physics steps of {timestep:g} s ({steps:.4f});"
            " choose a rate or timestep that divide evenly",
        )
    return ModelConfig(file, timestep, control_rate, align_every, *payload, nominal)


def _read(source: Path) -> OptionReader:
    return OptionReader(source, read_toml(source, "scenario file", ScenarioError), "")


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file.

    Args:
        path: a TOML scenario file, or a shipped scenario's name (``paper_open_loop``).

    Raises:
        ScenarioError: naming the file, the field and the fix.
    """
    try:
        source = resources.scenario_file(path)
    except resources.ResourceError as exc:
        raise ScenarioError(str(exc)) from None
    return _scenario(_read(source), source)


def scenario_from_data(data: Mapping[str, Any], source: str | Path) -> Scenario:
    """Validate a scenario given as parsed TOML ``data`` (a campaign's variation of a file).

    Relative paths resolve beside ``source``, and errors name it (:class:`ScenarioError`).
    """
    return _scenario(OptionReader(Path(source), dict(data), ""), Path(source))


def _scenario(top: OptionReader, source: Path) -> Scenario:
    loaded = read_plugins(top)  # first: the file may name what they register
    name = top.raw("name", source.stem, "string")  # (its NUL: the plain-name rule's words)
    if not isinstance(name, str):
        raise top.fail("name", f"must be a string, got {shown(name)}")
    control = any(ord(c) < 0x20 or c == "\x7f" for c in name)  # NUL, newline, tab, DEL
    if len(name.encode("utf-8", "surrogatepass")) > MAX_NAME_BYTES:
        raise top.fail(
            "name",
            f"must be at most {MAX_NAME_BYTES} bytes (it names the output directory), got "
            f"{shown(name)}",
        )
    if not name or any(c in name for c in "/\\") or name in (".", "..") or control:
        raise top.fail(
            "name",
            f"must be a plain name usable as a directory (no /, \\ or control characters), "
            f"got {shown(name)}",
        )
    description = top.string("description", "")
    duration = top.number("duration", minimum=0, exclusive=True, unit="s")
    seed = top.integer("seed", 0, minimum=0)
    model, truth = _model(top, source), read_truth(top, source)
    s = top.table_of("sensors", required=False)
    sensors = SensorConfig(
        s.number("tension_noise_std", 0.24, minimum=0, unit="N"),
        s.boolean("camera", True),
        s.boolean("tag_window", False),
    )
    s.done()
    try:
        check_at_most(
            "tension_noise_std", sensors.tension_noise_std, MAX_TENSION_NOISE_STD, TENSION_NOISE_WHY
        )
    except OptionError as exc:
        raise s.fail(exc.field, exc.problem) from None
    st = top.table_of("start")
    start = st.pose("pose")
    st.done()
    controller = _controller(top.table_of("controller"))
    estimators = _estimators(top.table_of("estimators"))
    events, monitor = read_events(top), read_monitor(top)
    realism = read_realism(top)
    top.done()
    scenario = Scenario(
        name,
        source,
        description,
        duration,
        seed,
        start,
        model,
        truth,
        sensors,
        controller,
        estimators,
        events,
        monitor,
        loaded,
        realism,
    )
    return scenario.with_overrides()
