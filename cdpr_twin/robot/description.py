"""Robot description files (``models/<robot>/robot.toml``) → a frozen :class:`Robot` value.

A description holds every number of one cable robot in SI units, each key naming its unit
(``_m``, ``_kg``, ``_n``, ``_s``, ``_deg``…): the frame, per-cable exit points and swivel
pulleys, platform anchor points, the platform's mass, inertia and box, the cable material, the
winches, the camera, the tag, the monitor's limits and the viewer's scene. The schema is strict:
an unknown, missing or badly typed key is a one-line :class:`RobotError` naming the file and the
field. :mod:`cdpr_twin.sim.mjcf_from_robot` turns a :class:`Robot` into MJCF through
``mujoco.MjSpec``; this module is numpy + tomllib only.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cdpr_twin.files.inputs import read_toml
from cdpr_twin.robot.schema import (
    MAX_TIMESTEP,
    MIN_TIMESTEP,
    RobotError,
    TensionSensorSpec,
    _Table,
    check_gravity,
    check_inertia,
    payload,
    tension_sensors,
)

__all__ = ["Camera", "Robot", "RobotError", "Tag", "TensionSensorSpec", "load_robot"]

SECTIONS = (
    "frame",
    "cables",
    "pulleys",
    "platform",
    "winches",
    "tension_sensors",
    "payload",
    "camera",
    "tag",
    "monitor",
)
OPTIONAL_SECTIONS = ("camera", "tag", "monitor", "scene")


@dataclass(frozen=True, eq=False)
class Camera:
    """The onboard camera: pose in F_p (MuJoCo camera frame: looks along −z, y up)."""

    position: np.ndarray  # (3,) [m]
    quat_wxyz: np.ndarray  # (4,)
    resolution: tuple[int, int]  # (width, height) [px]
    fovy_deg: float  # vertical field of view [deg]


@dataclass(frozen=True, eq=False)
class Tag:
    """The AprilTag on a static plate; its body frame is the pupil-apriltags tag frame."""

    family: str
    id: int
    size: float  # edge of the black square [m]
    plate_half_size: float  # [m]
    plate_thickness: float  # [m]
    position: np.ndarray  # (3,) [m] in F_b
    quat_wxyz: np.ndarray  # (4,)
    texture: str  # PNG file, relative to the description file


@dataclass(frozen=True, eq=False)
class Robot:
    """One cable robot, every number in SI units (see ``models/acrobot/robot.toml``).

    Attributes:
        name: model name; files are ``models/<name>/<name>.xml`` and ``scene.xml``.
        source: the description file.
        timestep: physics step [s].
        gravity: (3,) [m/s²].
        frame_min, frame_max: (3,) inner box of the frame, the workspace bound [m].
        frame_outer_min, frame_outer_max: (3,) outer box of the visual frame [m].
        frame_member_half_width: half-width of the visual posts and beams [m].
        floor_height: height of the floor plane [m].
        exit_points: (m, 3) A_i in F_b [m] (sheave point on each swivel axis).
        anchor_points: (m, 3) B_i in F_p [m].
        sheave_radius: (m,) r_p [m]; sheave_half_width: (m,) [m] (visual).
        entry_height: cable entry segment down the swivel axis [m].
        es: (m,) axial stiffness E·S [N]; damping_time: η [s] (c = η E·S / l0).
        cable_diameter [m], linear_density [kg/m], breaking_load [N]; sag: the cables' weight
            acts in the physics (Irvine's catenary, :mod:`cdpr_twin.sim.sag`).
        mass [kg], box_half_size (3,) [m], box_center (3,) [m] in F_p; inertia: (3,) principal
            or (6,) Ixx Iyy Izz Ixy Ixz Iyz [kg m²] at the centre of mass com (3,) [m] in F_p,
            or both None (a uniform box); home_pose: (6,) [x, y, z m, rx, ry, rz deg], the
            pose of the viewer's keyframe named home_key.
        rate_limit [m/s], force_limit [N], length_range (2,) [m], tension_range (2,) [N]:
            the winches; drum_radius [m]: their drums' radius; drum_radius_scale: (m,) each
            drum's radius over it, as a calibration estimated it (``None``: all as built).
        tension_sensors: the sensors' range, accuracy, repeatability and location.
        max_payload: the rated payload [kg] (0: none rated).
        camera, tag: or None.
        max_speed [m/s], max_angular_speed [rad/s]: the monitor's limits (inf: unchecked).
        view_center (3,) [m], view_extent [m], floor_half_size [m]: the viewer's scene.
    """

    name: str
    source: Path
    timestep: float
    gravity: np.ndarray
    frame_min: np.ndarray
    frame_max: np.ndarray
    frame_outer_min: np.ndarray
    frame_outer_max: np.ndarray
    frame_member_half_width: float
    floor_height: float
    exit_points: np.ndarray
    anchor_points: np.ndarray
    sheave_radius: np.ndarray
    sheave_half_width: np.ndarray
    entry_height: float
    es: np.ndarray
    damping_time: float
    cable_diameter: float
    linear_density: float
    sag: bool
    breaking_load: float
    mass: float
    box_half_size: np.ndarray
    box_center: np.ndarray
    inertia: np.ndarray | None
    com: np.ndarray | None
    home_pose: np.ndarray
    home_key: str
    rate_limit: float
    force_limit: float
    length_range: np.ndarray
    tension_range: np.ndarray
    drum_radius: float
    tension_sensors: TensionSensorSpec
    max_payload: float
    camera: Camera | None
    tag: Tag | None
    max_speed: float
    max_angular_speed: float
    view_center: np.ndarray
    view_extent: float
    floor_half_size: float
    drum_radius_scale: np.ndarray | None = None

    @property
    def n_cables(self) -> int:
        """Number of cables m."""
        return self.exit_points.shape[0]


def _simulation(t: _Table) -> dict:
    timestep = t.number("timestep_s", positive=True)
    if not MIN_TIMESTEP <= timestep <= MAX_TIMESTEP:
        raise t.fail(
            "timestep_s",
            f"must be in [{MIN_TIMESTEP:g}, {MAX_TIMESTEP:g}] s (stiff "
            f"cables diverge above), got {timestep:g}",
        )
    return {"timestep": timestep, "gravity": t.array("gravity_m_s2", (3,))}


def _frame(t: _Table) -> dict:
    out: dict[str, Any] = {
        "frame_min": t.array("inner_min_m", (3,)),
        "frame_max": t.array("inner_max_m", (3,)),
        "frame_outer_min": t.array("outer_min_m", (3,)),
        "frame_outer_max": t.array("outer_max_m", (3,)),
        "frame_member_half_width": t.number("member_half_width_m", positive=True),
        "floor_height": t.number("floor_height_m"),
    }
    if np.any(out["frame_min"] >= out["frame_max"]):
        raise t.fail("inner_min_m", "must be below inner_max_m on every axis")
    if np.any(out["frame_outer_min"] >= out["frame_outer_max"]):
        raise t.fail("outer_min_m", "must be below outer_max_m on every axis")
    if out["floor_height"] > out["frame_min"][2]:  # the workspace cannot reach under the floor
        raise t.fail(
            "floor_height_m",
            f"must be at most inner_min_m's z "
            f"({out['frame_min'][2]:g} m), got {out['floor_height']:g}",
        )
    return out


def _cables(t: _Table, p: _Table) -> dict:
    a = t.array("exit_points_m", (-1, 3))
    m = a.shape[0]
    if m < 6:
        raise t.fail("exit_points_m", f"a 6-DoF cable robot needs m ≥ 6 cables, got {m}")
    b = t.array("anchor_points_m", (m, 3))
    es = t.per_cable("axial_stiffness_n", m)
    d = t.number("diameter_m", positive=True)
    if t.get("youngs_modulus_pa", None) is not None:  # optional: then E·S must agree with it
        es_e = t.number("youngs_modulus_pa", positive=True) * math.pi * d * d / 4
        if not np.allclose(es, es_e, rtol=1e-6):
            raise t.fail(
                "axial_stiffness_n", f"differs from youngs_modulus_pa·πd²/4 = {es_e:.7g} N"
            )
    axis = p.array("swivel_axis", (3,), [0.0, 0.0, 1.0])
    if not np.allclose(axis, [0.0, 0.0, 1.0]):
        raise p.fail("swivel_axis", "only vertical swivel axes [0, 0, 1] are supported")
    return {
        "exit_points": a,
        "anchor_points": b,
        "es": es,
        "damping_time": t.number("damping_time_s", positive=True),
        "cable_diameter": d,
        "linear_density": t.number("linear_density_kg_m", positive=True),
        "sag": t.boolean("sag", False),
        "breaking_load": t.number("breaking_load_n", positive=True),
        "sheave_radius": p.per_cable("sheave_radius_m", m),
        "sheave_half_width": p.per_cable("sheave_half_width_m", m),
        "entry_height": p.number("entry_height_m", positive=True),
    }


def _platform(t: _Table) -> dict:
    box = t.array("box_half_size_m", (3,))
    if np.any(box <= 0):
        raise t.fail("box_half_size_m", "must be > 0 on every axis")
    inertia = t.get("inertia_kg_m2", None)
    if inertia is not None:  # 3 principal moments, or Ixx Iyy Izz Ixy Ixz Iyz (at the CoM)
        n = len(inertia) if isinstance(inertia, list) else 0
        inertia = t.array("inertia_kg_m2", (6 if n == 6 else 3,))
        if np.any(inertia[:3] <= 0):
            raise t.fail("inertia_kg_m2", "the moments Ixx, Iyy, Izz must be > 0")
        check_inertia(t, inertia)
    com = t.get("com_m", None)
    if com is not None and inertia is None:
        raise t.fail("com_m", "needs inertia_kg_m2 (without it the platform is a uniform box)")
    return {
        "mass": t.number("mass_kg", positive=True),
        "box_half_size": box,
        "box_center": t.array("box_center_m", (3,), [0.0, 0.0, 0.0]),
        "inertia": inertia,
        "com": None if com is None else t.array("com_m", (3,)),
        "home_pose": t.array("home_pose", (6,)),
        "home_key": t.string("home_key", "home"),
    }


def _winches(t: _Table) -> dict:
    lengths, tensions = t.array("length_range_m", (2,)), t.array("tension_range_n", (2,))
    if not 0 < lengths[0] < lengths[1]:
        raise t.fail("length_range_m", f"must be [min, max] with 0 < min < max, got {lengths}")
    if not 0 <= tensions[0] < tensions[1]:
        raise t.fail("tension_range_n", f"must be [min, max] with 0 ≤ min < max, got {tensions}")
    return {
        "rate_limit": t.number("rate_limit_m_s", positive=True),
        "force_limit": t.number("force_limit_n", positive=True),
        "length_range": lengths,
        "tension_range": tensions,
        "drum_radius": t.number("drum_radius_m", positive=True),
    }


DRUM_SCALE_TOLERANCE = 0.1
"""A drum's radius may differ from the robot's ``drum_radius_m`` by this fraction at most: a
calibration's estimate is near 1 (a larger one is a unit mistake or another robot's radius)."""


def _drum_scale(t: _Table, m: int) -> np.ndarray | None:
    """``[winches] drum_radius_scale``, or ``None`` when absent.

    Each drum's radius over ``drum_radius_m``, as a calibration estimated it (near 1).
    """
    if (raw := t.get("drum_radius_scale", None)) is None:
        return None
    items = raw if isinstance(raw, list) else [raw]
    booleans = any(isinstance(x, bool) for x in items)
    if booleans or np.any(abs(t.per_cable("drum_radius_scale", m) - 1) > DRUM_SCALE_TOLERANCE):
        raise t.fail(
            "drum_radius_scale",
            f"must be each drum's radius over drum_radius_m (≈ 1, not metres), got {items}",
        )
    return t.per_cable("drum_radius_scale", m)


def _camera(t: _Table) -> Camera:
    res = t.array("resolution_px", (2,))
    if np.any(res < 1) or np.any(res != np.round(res)):
        raise t.fail("resolution_px", "must be two whole numbers ≥ 1 [width, height]")
    fovy = t.number("fovy_deg", positive=True)
    if fovy >= 180:
        raise t.fail("fovy_deg", f"must be < 180, got {fovy}")
    return Camera(
        t.array("position_m", (3,)), t.quaternion("quat_wxyz"), (int(res[0]), int(res[1])), fovy
    )


def _tag(t: _Table) -> Tag:
    family, tag_id = t.string("family"), t.integer("id")
    if (family, tag_id) != ("tag36h11", 0):  # what the camera's detector looks for
        bad = "family" if family != "tag36h11" else "id"
        raise t.fail(
            bad,
            f"the twin detects tag36h11 id 0 only, got {family} id {tag_id}; "
            "use that tag (and its texture, make_tag_texture.py)",
        )
    return Tag(
        family=family,
        id=tag_id,
        size=t.number("size_m", positive=True),
        plate_half_size=t.number("plate_half_size_m", positive=True),
        plate_thickness=t.number("plate_thickness_m", positive=True),
        position=t.array("position_m", (3,)),
        quat_wxyz=t.quaternion("quat_wxyz"),
        texture=t.string("texture"),
    )


def _check_texture(path: Path, tag: Tag) -> None:
    """``[tag] texture``: a readable PNG file, relative to the description file ``path``."""
    file = path.parent / tag.texture
    try:
        with file.open("rb") as f:
            png = f.read(8) == b"\x89PNG\r\n\x1a\n"
    except OSError as exc:
        raise RobotError(f"{path}: tag.texture: {file}: cannot be read ({exc.strerror})") from None
    if not png:
        raise RobotError(f"{path}: tag.texture: {file}: not a PNG image (make_tag_texture.py)")


def _scene(scene: _Table, outer_min: np.ndarray, outer_max: np.ndarray) -> dict:
    """``[scene]`` (optional): the viewer's centre, extent and floor, from the frame by default."""
    size = outer_max - outer_min
    return {
        "view_center": scene.array("view_center_m", (3,), (0.5 * (outer_min + outer_max)).tolist()),
        "view_extent": scene.number("view_extent_m", float(np.linalg.norm(size)), positive=True),
        "floor_half_size": scene.number("floor_half_size_m", float(size[:2].max()), positive=True),
    }


def _read(path: Path) -> dict:
    return read_toml(path, "robot description", RobotError, in_directory="robot.toml")


def load_robot(path: str | Path) -> Robot:
    """Read and validate a robot description file.

    Args:
        path: a ``robot.toml``.

    Returns:
        The robot, in SI units.

    Raises:
        RobotError: one line naming the file, the field and the problem.
    """
    path = Path(path)
    data = _read(path)
    top = _Table(path, data, "")
    top.where = "robot"

    def optional(name: str, required: bool = False) -> _Table | None:
        v = top.get(name, ... if required else None)
        if v is None:
            return None
        if not isinstance(v, dict):
            raise RobotError(f"{path}: [{name}] must be a table")
        return _Table(path, v, name)

    def table(name: str) -> _Table:
        found = optional(name, required=True)
        # a required table: _Table.get raised for a missing one, and None is no table
        assert found is not None
        return found

    name = top.string("name")  # it names the MJCF files `model build` writes: a plain name
    if name.startswith(".") or not all(c.isalnum() or c in "_-." for c in name):
        raise top.fail("name", f"must be a plain file name (letters, digits, _ - .), got {name!r}")
    if name == "scene":  # `model build` writes <name>.xml beside scene.xml
        raise top.fail("name", "'scene' names the scene file model build writes; choose another")
    top.string("description", "-")
    sim = table("simulation")
    fields: dict[str, Any] = {"name": name, "source": path, **_simulation(sim)}
    tables = [sim]
    for key, reader in (("frame", _frame), ("platform", _platform), ("winches", _winches)):
        tables.append(table(key))
        fields.update(reader(tables[-1]))
    tables += [table("cables"), table("pulleys"), table("tension_sensors"), table("payload")]
    fields["tension_sensors"] = tension_sensors(tables[-2])
    fields["max_payload"] = payload(tables[-1])
    fields.update(_cables(tables[-4], tables[-3]))
    check_gravity(sim, fields["gravity"], fields["sag"])
    fields["drum_radius_scale"] = _drum_scale(tables[3], fields["exit_points"].shape[0])
    readers: tuple[tuple[str, Callable[[_Table], object]], ...] = (
        ("camera", _camera),
        ("tag", _tag),
    )
    for key, read in readers:
        t = optional(key)
        fields[key] = None if t is None else read(t)
        tables += [t] if t is not None else []
    mon = optional("monitor") or _Table(path, {}, "monitor")
    for field, key in (
        ("max_speed", "platform_max_speed_m_s"),
        ("max_angular_speed", "platform_max_angular_speed_rad_s"),
    ):
        fields[field] = mon.number(key, math.inf, positive=True, infinite=True)
    scene = optional("scene") or _Table(path, {}, "scene")
    fields.update(_scene(scene, fields["frame_outer_min"], fields["frame_outer_max"]))
    for t in [*tables, mon, scene, top]:
        t.done()
    if fields["tag"] is not None:  # once every field is known good
        _check_texture(path, fields["tag"])
    return Robot(**fields)
