"""Load the ACROBOT MJCF, apply the robot's truth deviations, read its geometry.

The nominal :class:`~cdpr_twin.math.geometry.CdprGeometry` (what estimators and controllers believe)
and the twin's true one come from the same model file: the true one is read after
:func:`build_model` has moved exit and anchor points, scaled E·S, changed pulley radii and
re-mounted the camera and tag as a seeded :class:`TruthDeviations` says (the calibration errors
of one physical robot).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from cdpr_twin.files.inputs import MAX_MODEL_BYTES, read_bytes
from cdpr_twin.files.paths import path_kind
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.se3 import matrix_from_quat_wxyz, quat_wxyz_from_matrix, so3_exp, transform
from cdpr_twin.robot.deviations import TruthDeviations
from cdpr_twin.robot.realism import RobotSensing
from cdpr_twin.sim import camera
from cdpr_twin.sim.occluder import add_occluder

PLATFORM_BODY = "platform"
TAG_BODY = "tag"


class ModelError(ValueError):
    """A model file is missing, malformed, or lacks an element the twin needs."""

    field = "model.file"
    """The scenario key that named the file at fault."""


class NominalError(ModelError):
    """The robot description given as the nominal model (``[model] nominal``) is unusable."""

    field = "model.nominal"


class SimulationError(RuntimeError):
    """The simulation diverged or was asked for something it cannot do."""


def as_slice(ids: np.ndarray | list) -> slice | np.ndarray:
    """A slice when ids are consecutive (assignments through it are views), else the ids."""
    ids = np.asarray(ids)
    if ids.size and np.all(np.diff(ids) == 1):
        return slice(int(ids[0]), int(ids[-1]) + 1)
    return ids


def swivel_body(i: int) -> str:
    """Name of cable i's pulley swivel body (i from 0)."""
    return f"pulley{i + 1}_swivel"


def sheave_geom(i: int) -> str:
    """Name of cable i's sheave geom (i from 0)."""
    return f"pulley{i + 1}_sheave"


def side_site(i: int) -> str:
    """Name of cable i's wrap side site (i from 0)."""
    return f"pulley{i + 1}_side"


def anchor_site(i: int) -> str:
    """Name of cable i's anchor site B_i (i from 0)."""
    return f"cable{i + 1}_anchor"


def tendon_name(i: int) -> str:
    """Name of cable i's tendon (i from 0)."""
    return f"cable{i + 1}_tendon"


def actuator_name(i: int) -> str:
    """Name of cable i's winch actuator (i from 0)."""
    return f"winch{i + 1}_actuator"


_CABLE_PARTS = (
    (mujoco.mjtObj.mjOBJ_BODY, swivel_body),
    (mujoco.mjtObj.mjOBJ_GEOM, sheave_geom),
    (mujoco.mjtObj.mjOBJ_SITE, anchor_site),
    (mujoco.mjtObj.mjOBJ_TENDON, tendon_name),
    (mujoco.mjtObj.mjOBJ_ACTUATOR, actuator_name),
)


def cable_count(model: mujoco.MjModel) -> int:
    """Number of cables: tendons named ``cable1_tendon``, ``cable2_tendon``… without a gap."""
    n = 0
    while mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TENDON, tendon_name(n)) >= 0:
        n += 1
    return n


def _spec_cable_count(spec: mujoco.MjSpec) -> int:
    n = 0
    while spec.tendon(tendon_name(n)) is not None:
        n += 1
    return n


def _load_spec(path: Path) -> mujoco.MjSpec:
    path = Path(path)
    kind = path_kind(path, ModelError)
    if kind == "dir":
        raise ModelError(
            f"model file {path} is a directory; give an MJCF file in it, such as "
            "models/acrobot/scene.xml"
        )
    if kind is None:
        raise ModelError(
            f"model file {path} not found; pass the path of an MJCF file such as "
            "models/acrobot/scene.xml"
        )
    if path.suffix == ".toml":  # a robot description, not its model
        raise ModelError(
            f"model file {path} is a robot description, not an MJCF model: run "
            f"`cdpr-twin model build {path}` and give the scene.xml it writes"
        )
    read_bytes(  # before MuJoCo reads it: a FIFO would block it, /dev/zero fill the memory
        path, "model file", MAX_MODEL_BYTES, lambda why: ModelError(f"model file {why}"), False
    )
    warned: list[str] = []  # MuJoCo's parser warns on stderr before it fails: caught here
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(warned.append)
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:  # its error says what is wrong: its warnings are left out
        raise ModelError(f"model file {path} is malformed: {exc}".strip()) from exc
    finally:
        mujoco.set_mju_user_warning(previous)
    for text in warned:  # a model that loads: what MuJoCo warned of, one line each
        print(f"MuJoCo warning: {path}: {text}", file=sys.stderr)
    return spec


def _element(getter, name: str, kind: str, path: Path):
    element = getter(name)
    if element is None:
        raise ModelError(
            f"model file {path} has no {kind} named {name!r}, which the ACROBOT "
            "twin needs (see models/acrobot/acrobot.xml)"
        )
    return element


def build_model(
    path: str | Path, deviations: TruthDeviations | None = None, occluder: bool = False
) -> mujoco.MjModel:
    """Compile a model file, with the robot's truth deviations applied (through MjSpec).

    Args:
        path: MJCF file (``models/acrobot/scene.xml`` or a file that includes acrobot.xml).
        deviations: calibration errors of the simulated robot; ``None`` for the nominal robot.
        occluder: add the sheet that ``tag_occlusion`` events slide over the tag
            (:mod:`cdpr_twin.sim.occluder`).

    Returns:
        The compiled model.

    Raises:
        ModelError: when the file is missing, malformed or lacks a needed element, or when the
            deviations make it invalid (e.g. a negative pulley radius).
    """
    path = Path(path)
    spec = _load_spec(path)
    if deviations is not None:
        _apply(spec, deviations, path)
    if occluder:
        add_occluder(spec, float(_element(spec.geom, "tag_plate", "geom", path).size[0]))
    try:
        model = spec.compile()
    except ValueError as exc:
        raise ModelError(f"model file {path} does not compile: {exc}") from exc
    n = cable_count(model)
    if n < 1:
        raise ModelError(
            f"model file {path} has no cables: a cable robot needs, for cable 1, 2…, a tendon "
            f"{tendon_name(0)!r}, a winch {actuator_name(0)!r}, a mocap swivel body "
            f"{swivel_body(0)!r} with a sheave {sheave_geom(0)!r}, and an anchor site "
            f"{anchor_site(0)!r} (see models/acrobot/acrobot.xml)"
        )
    for i in range(n):  # fail early and clearly on a cable that misses a part
        for objtype, name in _CABLE_PARTS:
            if mujoco.mj_name2id(model, objtype, name(i)) < 0:
                raise ModelError(
                    f"model file {path} has no {objtype.name[6:].lower()} named "
                    f"{name(i)!r}, which cable {i + 1} needs"
                )
    return model


def _apply(spec: mujoco.MjSpec, dev: TruthDeviations, path: Path) -> None:
    n = _spec_cable_count(spec)
    if len(dev.es_scale) != n:
        raise ModelError(
            f"model file {path} has {n} cables but the truth deviations were drawn for "
            f"{len(dev.es_scale)}; draw them with DeviationSpec.draw({n})"
        )
    es = _element(spec.numeric, "cable_es", "numeric", path)
    es.data = list(np.asarray(es.data) * dev.es_scale)
    for i in range(n):
        body = _element(spec.body, swivel_body(i), "body", path)
        body.pos = np.asarray(body.pos) + dev.exit_offsets[i]
        site = _element(spec.site, anchor_site(i), "site", path)
        site.pos = np.asarray(site.pos) + dev.anchor_offsets[i]
        sheave = _element(spec.geom, sheave_geom(i), "geom", path)
        r = float(sheave.size[0]) + float(dev.pulley_radius_offsets[i])
        if r <= 0:
            raise ModelError(
                f"pulley radius deviation makes sheave {i + 1}'s radius {r} m ≤ 0; "
                "lower pulley_radius_std"
            )
        sheave.size = [r, sheave.size[1], sheave.size[2]]
        sheave.pos = [r, 0.0, 0.0]
        side = _element(spec.site, side_site(i), "site", path)
        side.pos = [r, 0.0, -2.0 * r]
    cam = spec.camera(camera.CAMERA_NAME)
    if cam is not None:
        cam.pos = np.asarray(cam.pos) + dev.camera_offset[:3]
        # the rotation error is expressed in the platform frame: R ← exp(δθ) R
        R = matrix_from_quat_wxyz(np.asarray(cam.quat))
        cam.quat = quat_wxyz_from_matrix(so3_exp(dev.camera_offset[3:]) @ R)
    tag = spec.body(TAG_BODY)
    if tag is not None:
        tag.pos = np.asarray(tag.pos) + dev.tag_offset[:3]
        R = matrix_from_quat_wxyz(np.asarray(tag.quat))
        tag.quat = quat_wxyz_from_matrix(so3_exp(dev.tag_offset[3:]) @ R)


def add_payload(model: mujoco.MjModel, mass: float, com: np.ndarray, source: str = "model") -> None:
    """Fix a payload to the platform of a compiled model: a point mass at ``com`` in F_p.

    The platform's mass, centre of mass and inertia become the rigid sum's (parallel-axis
    theorem; the payload's own inertia about its centre is neglected [eng]: a compact load).

    Args:
        model: the compiled model, changed in place (``mj_setConst`` refreshes what depends).
        mass: the payload's mass [kg] (0: nothing changes).
        com: (3,) its centre of mass in F_p [m].
        source: the model's file, for the error message.

    Raises:
        ValueError: the payload exceeds the robot's rated ``payload_max_mass``.
    """
    if mass == 0:
        return
    rated = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, "payload_max_mass")
    if rated >= 0 and mass > model.numeric_data[model.numeric_adr[rated]]:
        limit = model.numeric_data[model.numeric_adr[rated]]
        raise ValueError(f"payload_kg = {mass:g} exceeds the rated {limit:g} kg of {source}")
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, PLATFORM_BODY)
    m0, c0, p = float(model.body_mass[body]), model.body_ipos[body].copy(), np.asarray(com)
    R = matrix_from_quat_wxyz(model.body_iquat[body])
    total = m0 + mass
    c = (m0 * c0 + mass * p) / total

    def shift(m: float, d: np.ndarray) -> np.ndarray:  # a point mass m at d from c
        return m * (float(d @ d) * np.eye(3) - np.outer(d, d))

    inertia = R @ np.diag(model.body_inertia[body]) @ R.T + shift(m0, c0 - c) + shift(mass, p - c)
    moments, axes = np.linalg.eigh(inertia)
    axes[:, 2] *= np.sign(np.linalg.det(axes))  # a rotation
    model.body_mass[body], model.body_ipos[body] = total, c
    model.body_inertia[body], model.body_iquat[body] = moments, quat_wxyz_from_matrix(axes)
    mujoco.mj_setConst(model, mujoco.MjData(model))


def has_numeric(model: mujoco.MjModel, name: str) -> bool:
    """Whether the model has a ``<custom><numeric>`` element of that name."""
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, name) >= 0


def robot_sensing(model: mujoco.MjModel) -> RobotSensing | None:
    """The winch and tension-sensor data of a model's description, or ``None`` without them."""
    names = ("winch_drum_radius", "tension_sensor_range", "tension_sensor_accuracy")
    if not all(has_numeric(model, n) for n in (*names, "tension_sensor_repeatability")):
        return None
    lo, hi = numeric(model, "tension_sensor_range")
    return RobotSensing(
        drum_radius=float(numeric(model, "winch_drum_radius")[0]),
        tension_range=(float(lo), float(hi)),
        accuracy=float(numeric(model, "tension_sensor_accuracy")[0]),
        repeatability=float(numeric(model, "tension_sensor_repeatability")[0]),
    )


def numeric(model: mujoco.MjModel, name: str) -> np.ndarray:
    """Data of a ``<custom><numeric>`` element, with an error naming a missing one."""
    nid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, name)
    if nid < 0:
        raise ModelError(
            f"the model has no <numeric name={name!r}> in <custom>; see models/acrobot/acrobot.xml"
        )
    adr, size = model.numeric_adr[nid], model.numeric_size[nid]
    return np.array(model.numeric_data[adr : adr + size])


def static_site_pose(model: mujoco.MjModel, site: int, source: str = "model") -> np.ndarray:
    """The (4, 4) world pose of a site on a static child body of the world.

    Raises:
        ModelError: when the site's body is not a static child of the world.
    """
    body = model.site_bodyid[site]
    if model.body_parentid[body] != 0 or model.body_mocapid[body] >= 0:
        raise ModelError(f"{source}: the tag must be on a static child of the world")
    T_body = transform(matrix_from_quat_wxyz(model.body_quat[body]), model.body_pos[body])
    return T_body @ transform(matrix_from_quat_wxyz(model.site_quat[site]), model.site_pos[site])


def read_geometry(model: mujoco.MjModel) -> CdprGeometry:
    """The CDPR geometry a compiled model describes.

    Args:
        model: a model from :func:`build_model` (nominal or deviated).

    Returns:
        The :class:`CdprGeometry`: exit points from the swivel bodies, anchor points from the
        anchor sites, radii from the sheaves, E·S from ``<numeric name="cable_es">``, mass and
        centre of mass from the platform body, the OpenCV camera mounting from
        ``platform_cam`` (identity when the model has no camera), the workspace from
        ``frame_min``/``frame_max``, the tension limits from ``cable_tension_range`` (when the
        model has it; else the geometry's defaults).
    """
    n = cable_count(model)

    def ids(objtype: mujoco.mjtObj, names: list[str]) -> np.ndarray:
        return np.array([mujoco.mj_name2id(model, objtype, n) for n in names])

    bodies = ids(mujoco.mjtObj.mjOBJ_BODY, [swivel_body(i) for i in range(n)])
    sites = ids(mujoco.mjtObj.mjOBJ_SITE, [anchor_site(i) for i in range(n)])
    sheaves = ids(mujoco.mjtObj.mjOBJ_GEOM, [sheave_geom(i) for i in range(n)])
    platform = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, PLATFORM_BODY)
    if platform < 0 or np.any(model.site_bodyid[sites] != platform):
        raise ModelError("the model's anchor sites must sit on a body named 'platform'")
    es = numeric(model, "cable_es")
    limits: dict[str, Any] = {}
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, "cable_tension_range") >= 0:
        lo, hi = numeric(model, "cable_tension_range")
        limits = {"tension_min": float(lo), "tension_max": float(hi)}
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, "cable_linear_density") >= 0:
        limits["linear_density"] = float(numeric(model, "cable_linear_density")[0])
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, "tension_sensor_at_pulley") >= 0:
        limits["sensors_at_pulleys"] = True
    return CdprGeometry(
        a_base=model.body_pos[bodies],
        b_platform=model.site_pos[sites],
        pulley_radius=model.geom_size[sheaves, 0],
        es=np.broadcast_to(es, (n,)),
        mass=float(model.body_mass[platform]),
        com_platform=model.body_ipos[platform],
        gravity=model.opt.gravity,
        T_platform_cam=camera.T_body_cam(model) if camera.has_camera(model) else np.eye(4),
        frame_min=numeric(model, "frame_min"),
        frame_max=numeric(model, "frame_max"),
        **limits,
    )
