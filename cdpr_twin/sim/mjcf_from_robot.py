"""MJCF from a robot description, built through ``mujoco.MjSpec``.

:func:`robot_spec` builds the robot (frame, swivel pulleys, platform, tendons, winches, tension
sensors, camera, ``<numeric>`` constants) and :func:`scene_spec` the robot in its cell (floor,
light, tag). :func:`build_files` writes ``<name>.xml`` and ``scene.xml`` beside the description,
with a viewer keyframe settled at the description's home pose (MuJoCo's own viewer runs no
cdpr_twin code). The text is MuJoCo's own XML writer's, its numbers restored to full precision
(:mod:`cdpr_twin.sim.mjcf_writer`), so a file compiles to its spec's model bit for bit.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import mujoco
import numpy as np
import numpy.typing as npt

from cdpr_twin.math.se3 import pose_from_vector
from cdpr_twin.robot.description import Robot, Tag, load_robot
from cdpr_twin.sim import camera as cam_mod
from cdpr_twin.sim.mjcf_writer import to_xml
from cdpr_twin.sim.model import (
    PLATFORM_BODY,
    TAG_BODY,
    actuator_name,
    anchor_site,
    sheave_geom,
    side_site,
    swivel_body,
    tendon_name,
)

_SHEAVE_QUAT = [math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0]  # cylinder axis → y
_NO_CONTACT = {"contype": 0, "conaffinity": 0}
_GEOM = mujoco.mjtGeom
_COLOURS = {
    "frame": [0.6, 0.6, 0.65, 1],
    "sheave": [0.8, 0.5, 0.1, 1],
    "entry": [0.2, 0.2, 0.9, 1],
    "side": [0.9, 0.2, 0.2, 1],
    "anchor": [0.9, 0.9, 0.1, 1],
    "cable": [0.95, 0.95, 0.95, 1],
    "platform": [0.25, 0.3, 0.4, 1],
}


def _numerics(spec: mujoco.MjSpec, r: Robot) -> None:
    values: dict[str, npt.ArrayLike] = {
        "cable_es": r.es,
        "cable_damping_time": [r.damping_time],
        "cable_entry_height": [r.entry_height],
        "frame_min": r.frame_min,
        "frame_max": r.frame_max,
        "cable_breaking_load": [r.breaking_load],
        "platform_max_speed": [r.max_speed],
        "platform_max_angular_speed": [r.max_angular_speed],
        "cable_tension_range": r.tension_range,
        "cable_linear_density": [r.linear_density],
        "winch_drum_radius": [r.drum_radius],
        "tension_sensor_range": list(r.tension_sensors.range),
        "tension_sensor_accuracy": [r.tension_sensors.accuracy],
        "tension_sensor_repeatability": [r.tension_sensors.repeatability],
        "payload_max_mass": [r.max_payload],
    }
    if r.tension_sensors.location == "pulley":  # the sensors read the winch side's tension
        values["tension_sensor_at_pulley"] = [1.0]
    if r.sag:  # heavy cables: the twin builds SaggingPhysics (cdpr_twin/sim/sag.py)
        values["cable_sag"] = [1.0]
    for name, given in values.items():
        data = np.asarray(given, dtype=float)
        if np.all(np.isfinite(data)):
            spec.add_numeric(name=name, data=data.tolist(), size=data.size)


def _frame(world: mujoco.MjsBody, r: Robot) -> None:
    lo, hi, w = r.frame_outer_min, r.frame_outer_max, r.frame_member_half_width
    half = 0.5 * (hi - lo)
    mid = np.round(lo + half, 12)  # visual only: the decimal a person would write
    style = {"type": _GEOM.mjGEOM_BOX, "group": 1, "density": 0, "rgba": _COLOURS["frame"]}
    for k, (x, y) in enumerate([(lo[0], lo[1]), (lo[0], hi[1]), (hi[0], lo[1]), (hi[0], hi[1])]):
        pos = [x + w if x == lo[0] else x - w, y + w if y == lo[1] else y - w, mid[2]]
        world.add_geom(name=f"frame_post{k}", size=[w, w, half[2]], pos=pos, **style, **_NO_CONTACT)
    for axis, name in ((0, "x"), (1, "y")):
        other = 1 - axis
        for k, c in enumerate((lo[other], hi[other])):
            pos, size = [0.0, 0.0, hi[2] - w], [w, w, w]
            pos[axis], size[axis] = mid[axis], half[axis]
            pos[other] = c + w if k == 0 else c - w
            world.add_geom(name=f"frame_beam_{name}{k}", size=size, pos=pos, **style, **_NO_CONTACT)


def _pulleys(world: mujoco.MjsBody, r: Robot) -> None:
    for i in range(r.n_cables):
        rp, w = float(r.sheave_radius[i]), float(r.sheave_half_width[i])
        body = world.add_body(name=swivel_body(i), pos=r.exit_points[i], mocap=True)
        body.add_geom(
            name=sheave_geom(i),
            type=_GEOM.mjGEOM_CYLINDER,
            size=[rp, w, 0],
            pos=[rp, 0, 0],
            quat=_SHEAVE_QUAT,
            group=1,
            density=0,
            rgba=_COLOURS["sheave"],
            **_NO_CONTACT,
        )
        body.add_site(
            name=f"cable{i + 1}_entry",
            pos=[0, 0, r.entry_height],
            size=[0.002, 0.005, 0.005],
            group=3,
            rgba=_COLOURS["entry"],
        )
        body.add_site(
            name=side_site(i),
            pos=[rp, 0, -2 * rp],
            size=[0.001, 0.005, 0.005],
            group=4,
            rgba=_COLOURS["side"],
        )


def _platform(world: mujoco.MjsBody, r: Robot) -> None:
    body = world.add_body(name=PLATFORM_BODY, pos=r.home_pose[:3])
    body.add_freejoint(name="platform_joint")
    box = {"type": _GEOM.mjGEOM_BOX, "size": r.box_half_size, "rgba": _COLOURS["platform"]}
    if r.box_center.any():
        box["pos"] = r.box_center
    if r.inertia is None:
        body.add_geom(name="platform_box", mass=r.mass, **box)
    else:
        body.mass, body.explicitinertial = r.mass, True
        body.ipos = r.box_center if r.com is None else r.com
        if r.inertia.size == 6:
            body.fullinertia = r.inertia
        else:
            body.inertia = r.inertia
        body.add_geom(name="platform_box", density=0, **box)
    for i in range(r.n_cables):
        body.add_site(
            name=anchor_site(i),
            pos=r.anchor_points[i],
            size=[0.004, 0.005, 0.005],
            group=3,
            rgba=_COLOURS["anchor"],
        )
    if r.camera is not None:
        c = r.camera
        body.add_camera(
            name=cam_mod.CAMERA_NAME,
            pos=c.position,
            quat=c.quat_wxyz,
            fovy=c.fovy_deg,
            resolution=list(c.resolution),
        )


def _cables(spec: mujoco.MjSpec, r: Robot) -> None:
    for i in range(r.n_cables):
        t = spec.add_tendon(name=tendon_name(i), width=0.001, rgba=_COLOURS["cable"])
        t.wrap_site(f"cable{i + 1}_entry")
        t.wrap_geom(sheave_geom(i), side_site(i))
        t.wrap_site(anchor_site(i))
    for i in range(r.n_cables):  # gains E·S/l0 are set by cdpr_twin.sim (and the viewer key)
        spec.add_actuator(
            name=actuator_name(i),
            target=tendon_name(i),
            trntype=mujoco.mjtTrn.mjTRN_TENDON,
            dyntype=mujoco.mjtDyn.mjDYN_INTEGRATOR,
            gaintype=mujoco.mjtGain.mjGAIN_FIXED,
            biastype=mujoco.mjtBias.mjBIAS_AFFINE,
            ctrlrange=[-r.rate_limit, r.rate_limit],
            forcerange=[-r.force_limit, 0],
            actrange=r.length_range,
        )
    for i in range(r.n_cables):
        spec.add_sensor(
            name=f"cable{i + 1}_tension_sensor",
            type=mujoco.mjtSensor.mjSENS_ACTUATORFRC,
            objtype=mujoco.mjtObj.mjOBJ_ACTUATOR,
            objname=actuator_name(i),
        )


def robot_spec(r: Robot) -> mujoco.MjSpec:
    """The robot alone (no floor, light or tag) as an ``MjSpec``."""
    spec = mujoco.MjSpec()
    spec.modelname = r.name
    spec.comment = (
        f" {r.name}: generated from robot.toml by `cdpr-twin model build` (cdpr_twin/sim/"
        "mjcf_from_robot.py); do not edit, edit the description. Units: SI, radians. "
    )
    spec.compiler.degree = False
    spec.compiler.autolimits = True
    spec.option.timestep = r.timestep
    spec.option.gravity = r.gravity
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    _numerics(spec, r)
    world = spec.worldbody
    _frame(world, r)
    _pulleys(world, r)
    _platform(world, r)
    _cables(spec, r)
    return spec


def scene_spec(r: Robot, out_dir: str | Path | None = None) -> mujoco.MjSpec:
    """The robot in its cell: floor, light, viewer settings and (if described) the tag.

    Args:
        r: the robot.
        out_dir: where the file will be written (the tag texture's path is relative to it);
            default: beside the description.
    """
    spec = robot_spec(r)
    spec.modelname = f"{r.name} scene"
    spec.stat.center, spec.stat.extent = r.view_center, r.view_extent
    g = spec.visual.global_
    g.azimuth, g.elevation = 135, -25
    if r.camera is not None:
        g.offwidth, g.offheight = r.camera.resolution
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.4, 0.4, 0.4]
    spec.visual.headlight.specular = [0, 0, 0]
    spec.visual.quality.shadowsize, spec.visual.quality.offsamples = 0, 0
    spec.visual.map.znear = 0.005
    if r.tag is not None:
        spec.add_numeric(name="tag_size", data=[r.tag.size], size=1)
    spec.add_numeric(name="floor_height", data=[r.floor_height], size=1)
    tex = spec.add_texture(
        name="floor_grid",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        width=256,
        height=256,
        rgb1=[0.42, 0.42, 0.45],
        rgb2=[0.38, 0.38, 0.41],
    )
    spec.add_material(name="floor_grid", texrepeat=[8, 8], reflectance=0).textures[1] = tex.name
    world = spec.worldbody
    world.add_light(
        name="ceiling",
        pos=[0, 0, 2.5],
        dir=[0, 0, -1],
        castshadow=False,
        diffuse=[0.6, 0.6, 0.6],
        type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
    )
    half = r.floor_half_size
    world.add_geom(
        name="floor",
        type=_GEOM.mjGEOM_PLANE,
        size=[half, half, 0.05],
        pos=[0, 0, r.floor_height],
        material="floor_grid",
    )
    if r.tag is not None:
        _tag(spec, r, r.tag, Path(r.source).parent if out_dir is None else Path(out_dir))
    return spec


def _tag(spec: mujoco.MjSpec, r: Robot, t: Tag, out_dir: Path) -> None:
    texture = (Path(r.source).parent / t.texture).resolve()
    name = texture.stem
    spec.compiler.texturedir = os.path.relpath(texture.parent, out_dir.resolve())
    spec.modelfiledir = str(out_dir.resolve())  # where the compiler looks for the texture
    spec.add_texture(name=name, type=mujoco.mjtTexture.mjTEXTURE_2D, file=texture.name)
    spec.add_material(name=name, specular=0, shininess=0).textures[1] = name
    body = spec.worldbody.add_body(name=TAG_BODY, pos=t.position, quat=t.quat_wxyz)
    h = 0.5 * t.plate_thickness
    body.add_geom(
        name="tag_plate",
        type=_GEOM.mjGEOM_BOX,
        size=[t.plate_half_size] * 2 + [h],
        pos=[0, 0, h],
        quat=[0, 0, 1, 0],
        material=name,
        **_NO_CONTACT,
    )
    body.add_site(name="tag_center", size=[0.002, 0.005, 0.005], group=4)


def add_home_key(spec: mujoco.MjSpec, r: Robot, key_name: str) -> None:
    """Settle the robot at its home pose and store the state as a viewer keyframe.

    MuJoCo's viewer runs no cdpr_twin code: the key (platform pose, rest lengths, swivel yaws)
    and the winch gains E·S/l0 written into the actuators hang still by themselves. Numbers are
    rounded to 10 significant digits, so the files do not depend on the last bits of a solver.
    """
    from cdpr_twin.sim.physics import Physics  # (physics imports this package's model module)

    physics = Physics(spec.compile())
    try:  # inside the frame, with tensions within range
        physics.reset(pose_from_vector(r.home_pose), settle_time=0.5)
    except ValueError as exc:
        raise ValueError(f"{r.source}: platform.home_pose: {exc}") from None
    check_rest(physics, r)
    m, d = physics.model, physics.data

    def rounded(a: np.ndarray) -> list[float]:
        return [float(f"{v:.10g}") for v in np.ravel(a)]

    for i, a in enumerate(physics._actuator_ids):
        act = spec.actuator(actuator_name(i))
        act.gainprm = rounded(m.actuator_gainprm[a, :1]) + [0.0] * 9
        act.biasprm = rounded(m.actuator_biasprm[a, :3]) + [0.0] * 7
    spec.add_key(
        name=key_name,
        qpos=rounded(d.qpos),
        act=rounded(d.act),
        mpos=rounded(d.mocap_pos),
        mquat=rounded(d.mocap_quat),
    )


HOME_REST = (1e-4, 1e-3)
"""How far the settled home keyframe may lie from ``home_pose`` ([m], [rad]); a robot that
holds the pose settles within ~1e-15 of it (its rest lengths are its static equilibrium)."""


def check_rest(physics, r: Robot) -> None:
    """Refuse a home keyframe that is not a rest at ``home_pose`` (the description's error).

    Raises:
        ValueError: the platform settled away from it (cables at the winches' force limit,
            a typo in a point), naming the largest tension against the limits.
    """
    dt, dr = physics.settle_error
    if dt <= HOME_REST[0] and dr <= HOME_REST[1]:
        return
    i = int(np.argmax(physics.tensions))
    raise ValueError(
        f"{r.source}: platform.home_pose: the platform does not rest there, it settles "
        f"{dt * 1e3:.3g} mm / {np.degrees(dr):.3g}° away (cable {i + 1} pulls "
        f"{physics.tensions[i]:.4g} N; winches.force_limit_n {r.force_limit:g} N, "
        f"tension_range_n {r.tension_range.tolist()}); check the points, the limits and the pose"
    )


def build_files(description: str | Path, out_dir: str | Path | None = None) -> tuple[Path, Path]:
    """Write ``<name>.xml`` (robot) and ``scene.xml`` (robot, floor, light, tag).

    Args:
        description: a ``robot.toml``.
        out_dir: where to write (default: beside the description).

    Returns:
        The two paths written.

    Raises:
        RobotError: for a bad description.
        cdpr_twin.files.transaction.OutputError: a file cannot be written; no half-written file is
            left.
    """
    from cdpr_twin.files.transaction import write_whole

    r = load_robot(description)
    out = Path(description).parent if out_dir is None else Path(out_dir)
    texts = model_texts(r, out)
    out.mkdir(parents=True, exist_ok=True)
    paths = (out / f"{r.name}.xml", out / "scene.xml")
    write_whole(dict(zip(paths, texts, strict=True)))  # both whole, or neither renamed
    return paths


def model_texts(r: Robot, out_dir: str | Path | None = None) -> tuple[str, str]:
    """The texts of ``<name>.xml`` and ``scene.xml`` (what :func:`build_files` writes).

    Args:
        r: the robot.
        out_dir: where they will be written (default: beside the description).
    """
    robot, scene = robot_spec(r), scene_spec(r, out_dir)
    add_home_key(robot, r, r.home_key)
    for i in range(r.n_cables):
        src, dst = robot.actuator(actuator_name(i)), scene.actuator(actuator_name(i))
        dst.gainprm, dst.biasprm = src.gainprm, src.biasprm
    key = robot.key(r.home_key)
    scene.add_key(name=key.name, qpos=key.qpos, act=key.act, mpos=key.mpos, mquat=key.mquat)
    return to_xml(robot), to_xml(scene)
