"""Scenario files (TOML) → a frozen, validated :class:`Scenario`, in SI units.

This is the file edge: poses are written ``[x, y, z, rx, ry, rz]`` in metres and degrees,
angles elsewhere carry ``_deg`` in their key, and the PBVS goal is given in ViSP's tag frame as
in the paper. Everything is converted here; errors name the file, the field and the fix. A
scenario file is documented by ``scenarios/paper_open_loop.toml`` and ``paper_pbvs.toml``.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from cdpr_twin.controllers import CONTROLLERS
from cdpr_twin.deviations import DeviationSpec
from cdpr_twin.estimators import ESTIMATORS
from cdpr_twin.se3 import pose_from_vector
from cdpr_twin.vision import T_TAGPUPIL_TAGVISP

ESTIMATOR_NAMES = tuple(ESTIMATORS)
CONTROLLER_NAMES = tuple(CONTROLLERS)
CABLE_MODELS = ("straight", "pulley")


class ScenarioError(ValueError):
    """A scenario file is missing, malformed, or has a bad field."""


def _frozen_array(a: Any) -> np.ndarray:
    out = np.array(a, dtype=float)
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class ModelConfig:
    """Which model, and how to step it.

    Attributes:
        file: MJCF scene.
        timestep: physics step [s].
        control_rate: control (and sensing) rate [Hz].
        align_every: physics steps between swivel/stiffness refreshes.
    """

    file: Path
    timestep: float
    control_rate: float
    align_every: int

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
    """

    tension_noise_std: float
    camera: bool


@dataclass(frozen=True)
class ControllerConfig:
    """Controller name and its keyword parameters, in SI (4×4 poses, radians).

    Attributes:
        type: a name of :data:`cdpr_twin.controllers.CONTROLLERS`.
        params: keyword arguments of that controller.
    """

    type: str
    params: Mapping[str, Any]


@dataclass(frozen=True)
class EstimatorConfig:
    """Which estimators run, and which one closes the loop.

    Attributes:
        in_loop: the estimator whose estimate feeds the controller.
        passive: estimators that run beside it.
        options: keyword options by estimator name.
    """

    in_loop: str
    passive: tuple[str, ...]
    options: Mapping[str, Mapping[str, Any]]

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
    overrides: Mapping[str, Any] = field(default_factory=dict)

    def with_overrides(
        self,
        seed: int | None = None,
        in_loop: str | None = None,
        duration: float | None = None,
        camera: bool | None = None,
    ) -> Scenario:
        """A copy with command-line overrides applied (and validated)."""
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
        if camera is not None:
            s = replace(s, sensors=replace(s.sensors, camera=bool(camera)))
            done["camera"] = bool(camera)
        if in_loop is not None:
            if in_loop not in ESTIMATOR_NAMES:
                raise ScenarioError(
                    f"--in-loop {in_loop!r}: unknown estimator; choose one of "
                    f"{', '.join(ESTIMATOR_NAMES)}"
                )
            passive = tuple(n for n in s.estimators.names if n != in_loop)
            s = replace(s, estimators=replace(s.estimators, in_loop=in_loop, passive=passive))
            done["in_loop"] = in_loop
        if not s.sensors.camera:
            if s.estimators.in_loop == "image":
                raise ScenarioError(
                    f"{s.source}: estimators.in_loop: 'image' needs the camera; "
                    "choose another in-loop estimator or keep the camera on"
                )
            if s.controller.type == "pbvs":
                raise ScenarioError(f"{s.source}: controller.type: 'pbvs' needs the camera")
            if "image" in s.estimators.passive:  # nothing to see: drop it, and say so
                passive = tuple(n for n in s.estimators.passive if n != "image")
                s = replace(s, estimators=replace(s.estimators, passive=passive))
                done["dropped_estimators"] = ["image"]
        return replace(s, overrides=MappingProxyType(done))


class _Reader:
    """Typed, unit-aware access to one TOML table, with errors naming file and field."""

    def __init__(self, source: Path, table: Mapping[str, Any], where: str) -> None:
        self.source, self.table, self.where = source, table, where
        self.used: set[str] = set()

    def fail(self, key: str, problem: str) -> ScenarioError:
        name = f"{self.where}.{key}" if self.where else key
        return ScenarioError(f"{self.source}: {name}: {problem}")

    def has(self, key: str) -> bool:
        return key in self.table

    def raw(self, key: str, default: Any = ..., kind: str = "") -> Any:
        self.used.add(key)
        if key in self.table:
            return self.table[key]
        if default is ...:
            raise self.fail(key, f"missing; add {key} = <{kind}>")
        return default

    def number(
        self,
        key: str,
        default: Any = ...,
        minimum: float | None = None,
        exclusive: bool = False,
        unit: str = "",
    ) -> float:
        v = self.raw(key, default, f"number{' ' + unit if unit else ''}")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.fail(
                key, f"must be a finite number{' in ' + unit if unit else ''}, got {v!r}"
            )
        if minimum is not None and (v <= minimum if exclusive else v < minimum):
            raise self.fail(
                key,
                f"must be {'>' if exclusive else '≥'} {minimum}"
                f"{' ' + unit if unit else ''}, got {v}",
            )
        return float(v)

    def integer(self, key: str, default: Any = ..., minimum: int | None = None) -> int:
        v = self.raw(key, default, "integer")
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(key, f"must be an integer, got {v!r}")
        if minimum is not None and v < minimum:
            raise self.fail(key, f"must be ≥ {minimum}, got {v}")
        return int(v)

    def string(self, key: str, default: Any = ..., choices: tuple[str, ...] = ()) -> str:
        v = self.raw(key, default, "string")
        if not isinstance(v, str):
            raise self.fail(key, f"must be a string, got {v!r}")
        if choices and v not in choices:
            raise self.fail(key, f"{v!r} is not one of {', '.join(choices)}")
        return v

    def boolean(self, key: str, default: Any = ...) -> bool:
        v = self.raw(key, default, "true/false")
        if not isinstance(v, bool):
            raise self.fail(key, f"must be true or false, got {v!r}")
        return v

    def pose(self, key: str, value: Any = ...) -> np.ndarray:
        v = self.raw(key, kind="[x, y, z, rx, ry, rz] (m, deg)") if value is ... else value
        if (
            not isinstance(v, list)
            or len(v) != 6
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)
            or not all(math.isfinite(x) for x in v)
        ):
            raise self.fail(
                key, f"must be a pose [x, y, z, rx, ry, rz] in m and degrees, got {v!r}"
            )
        return _frozen_array(pose_from_vector(v))

    def table_of(self, key: str, required: bool = True) -> _Reader:
        v = self.raw(key, ... if required else {}, "table")
        if not isinstance(v, dict):
            raise self.fail(key, f"must be a table [{key}], got {v!r}")
        return _Reader(self.source, v, f"{self.where}.{key}" if self.where else key)

    def done(self) -> None:
        unknown = sorted(set(self.table) - self.used)
        if unknown:
            raise self.fail(
                unknown[0],
                f"unknown field; known fields here: {', '.join(sorted(self.used)) or 'none'}",
            )


def _controller(r: _Reader) -> ControllerConfig:
    kind = r.string("type", choices=CONTROLLER_NAMES)
    params: dict[str, Any] = {}
    if kind == "open_loop":
        raw = r.raw("waypoints", kind="list of poses")
        if not isinstance(raw, list) or not raw:
            raise r.fail("waypoints", "must be a non-empty list of poses [x, y, z, rx, ry, rz]")
        waypoints = tuple(r.pose(f"waypoints[{i}]", w) for i, w in enumerate(raw))
        durations = r.raw("durations", kind="list of seconds")
        if (
            not isinstance(durations, list)
            or len(durations) != len(waypoints)
            or any(
                isinstance(d, bool) or not isinstance(d, (int, float)) or not d > 0
                for d in durations
            )
        ):
            raise r.fail(
                "durations",
                f"must list {len(waypoints)} segment durations > 0 s "
                f"(one per waypoint), got {durations!r}",
            )
        params = {"waypoints": waypoints, "durations": tuple(float(d) for d in durations)}
    else:
        goal = r.pose("goal_tag_pose_visp") @ T_TAGPUPIL_TAGVISP
        goal.flags.writeable = False
        params = {
            "goal_T_cam_tag": goal,
            "gain": r.number("gain", 0.5, minimum=0, exclusive=True, unit="1/s"),
            "max_linear_speed": r.number(
                "max_linear_speed", 0.03, minimum=0, exclusive=True, unit="m/s"
            ),
            "max_angular_speed": math.radians(
                r.number("max_angular_speed_deg", 10.0, minimum=0, exclusive=True, unit="deg/s")
            ),
            "converged_translation": r.number(
                "converged_translation", 5e-4, minimum=0, exclusive=True, unit="m"
            ),
            "converged_rotation": math.radians(
                r.number("converged_rotation_deg", 0.1, minimum=0, exclusive=True, unit="deg")
            ),
        }
    params["jacobian_model"] = r.string("jacobian_model", "straight", choices=CABLE_MODELS)
    r.done()
    return ControllerConfig(kind, MappingProxyType(params))


def _estimators(r: _Reader) -> EstimatorConfig:
    in_loop = r.string("in_loop", choices=ESTIMATOR_NAMES)
    passive = r.raw("passive", [], "list of estimator names")
    if not isinstance(passive, list) or any(p not in ESTIMATOR_NAMES for p in passive):
        raise r.fail(
            "passive",
            f"must list estimator names among {', '.join(ESTIMATOR_NAMES)}, got {passive!r}",
        )
    options: dict[str, Mapping[str, Any]] = {}
    for name in ESTIMATOR_NAMES:
        if not r.has(name):
            continue
        t = r.table_of(name)
        if name == "image":
            opts = {"reference": t.string("reference", "previous", choices=("previous", "first"))}
        elif name.startswith("model_"):
            opts = {
                "backend": t.string("backend", "fast", choices=("fast", "scipy")),
                "taut_threshold": t.number("taut_threshold", 1.0, minimum=0, unit="N"),
                "tension0": t.number("tension0", 0.0, unit="N"),
            }
        else:
            opts = {}
        t.done()
        options[name] = MappingProxyType(opts)
    r.done()
    passive_t = tuple(p for p in dict.fromkeys(passive) if p != in_loop)
    return EstimatorConfig(in_loop, passive_t, MappingProxyType(options))


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file.

    Args:
        path: a TOML scenario file.

    Raises:
        ScenarioError: naming the file, the field and the fix.
    """
    source = Path(path)
    if not source.is_file():
        raise ScenarioError(f"{source}: scenario file not found")
    try:
        data = tomllib.loads(source.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{source}: not valid TOML: {exc}") from None
    top = _Reader(source, data, "")
    name = top.string("name", source.stem)
    if not name or any(c in name for c in "/\\") or name in (".", ".."):
        raise top.fail("name", f"must be a plain name usable as a directory, got {name!r}")
    description = top.string("description", "")
    duration = top.number("duration", minimum=0, exclusive=True, unit="s")
    seed = top.integer("seed", 0, minimum=0)

    m = top.table_of("model", required=False)
    file = Path(m.string("file", "../models/acrobot/scene.xml"))
    file = file if file.is_absolute() else (source.parent / file).resolve()
    timestep = m.number("timestep", 0.0005, minimum=0, exclusive=True, unit="s")
    control_rate = m.number("control_rate", 25.0, minimum=0, exclusive=True, unit="Hz")
    align_every = m.integer("align_every", 10, minimum=1)
    m.done()
    steps = 1.0 / control_rate / timestep
    if abs(steps - round(steps)) > 1e-6 * steps or round(steps) < 1:
        raise m.fail(
            "control_rate",
            f"the control period 1/{control_rate:g} s is not a whole "
            f"number of physics steps of {timestep:g} s ({steps:.4f});"
            " choose a rate or timestep that divide evenly",
        )
    model = ModelConfig(file, timestep, control_rate, align_every)

    t = top.table_of("truth", required=False)
    try:
        truth = DeviationSpec(
            exit_point_std=t.number("exit_point_std", 0.0, minimum=0, unit="m"),
            anchor_point_std=t.number("anchor_point_std", 0.0, minimum=0, unit="m"),
            es_scale_std=t.number("es_scale_std", 0.0, minimum=0),
            pulley_radius_std=t.number("pulley_radius_std", 0.0, minimum=0, unit="m"),
            camera_position_std=t.number("camera_position_std", 0.0, minimum=0, unit="m"),
            camera_rotation_std=math.radians(
                t.number("camera_rotation_std_deg", 0.0, minimum=0, unit="deg")
            ),
            tag_position_std=t.number("tag_position_std", 0.0, minimum=0, unit="m"),
            tag_rotation_std=math.radians(
                t.number("tag_rotation_std_deg", 0.0, minimum=0, unit="deg")
            ),
            seed=t.integer("seed", 0, minimum=0),
        )
    except ValueError as exc:
        raise ScenarioError(f"{source}: truth: {exc}") from None
    t.done()

    s = top.table_of("sensors", required=False)
    sensors = SensorConfig(
        s.number("tension_noise_std", 0.24, minimum=0, unit="N"), s.boolean("camera", True)
    )
    s.done()

    st = top.table_of("start")
    start = st.pose("pose")
    st.done()
    controller = _controller(top.table_of("controller"))
    estimators = _estimators(top.table_of("estimators"))
    top.done()
    return Scenario(
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
    ).with_overrides()
