"""Robot descriptions and MJCF generated from them through MjSpec.

The truth for ACROBOT is the hand-written model the generated one replaced, kept verbatim (but
for its texture path) in tests/fixtures/acrobot_handwritten/.
"""

import re
import shutil
import tomllib
from operator import attrgetter
from pathlib import Path

import mujoco
import numpy as np
import pytest
from conftest import A_BASE, B_PLATFORM, random_workspace_poses

from cdpr_twin import MODELS_DIR
from cdpr_twin.campaign.spec import set_dotted
from cdpr_twin.cli import main
from cdpr_twin.robot.description import RobotError, load_robot
from cdpr_twin.scenario.loading import ScenarioError, scenario_from_data
from cdpr_twin.sim import Physics
from cdpr_twin.sim.mjcf_from_robot import build_files, model_texts

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"
HANDWRITTEN = FIXTURES / "acrobot_handwritten" / "scene.xml"
ACROBOT = MODELS_DIR / "acrobot" / "robot.toml"


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """The generator's ACROBOT files, written to a fresh directory with the tag texture."""
    out = tmp_path_factory.mktemp("gen")
    robot_xml, scene_xml = model_texts(load_robot(ACROBOT))
    (out / "acrobot.xml").write_text(robot_xml)
    (out / "scene.xml").write_text(scene_xml)
    shutil.copytree(MODELS_DIR / "acrobot" / "assets", out / "assets")
    return out, robot_xml, scene_xml


def _state(physics: Physics) -> dict[str, np.ndarray]:
    """Everything the twin reads from MuJoCo at the current (placed) pose."""
    m, d = physics.model, physics.data
    n = physics.n_cables
    jac = []
    for i in range(n):
        site = m.site(f"cable{i + 1}_anchor").id
        jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        mujoco.mj_jacSite(m, d, jp, jr, site)
        jac.append(np.vstack([jp, jr]))
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    cam = m.camera("platform_cam").id
    return {
        "ten_length": d.ten_length.copy(),
        "ten_J": np.array(d.ten_J).reshape(m.ntendon, m.nv),
        "jac_sites": np.array(jac),
        "site_xpos": d.site_xpos.copy(),
        "cam": np.concatenate([d.cam_xpos[cam], d.cam_xmat[cam]]),
        "mass_matrix": M,
        "cable_lengths": physics.cable_lengths,
    }


def test_generated_acrobot_equals_the_handwritten_model_at_100_poses(generated):
    out, _, _ = generated
    ref = mujoco.MjModel.from_xml_path(str(HANDWRITTEN))
    gen = mujoco.MjModel.from_xml_path(str(out / "scene.xml"))
    # the constants: masses, inertia, camera, sites, tendons, actuators, keyframe
    for field in (
        "body_mass",
        "body_inertia",
        "body_ipos",
        "body_iquat",
        "body_pos",
        "body_quat",
        "site_pos",
        "site_quat",
        "site_bodyid",
        "geom_size",
        "geom_pos",
        "geom_quat",
        "cam_fovy",
        "cam_resolution",
        "cam_pos",
        "cam_quat",
        "tendon_num",
        "wrap_objid",
        "wrap_prm",
        "actuator_gainprm",
        "actuator_biasprm",
        "actuator_ctrlrange",
        "actuator_forcerange",
        "actuator_actrange",
        "actuator_dyntype",
        "key_qpos",
        "key_act",
        "key_mpos",
        "key_mquat",
        "opt.timestep",
        "opt.gravity",
        "tex_data",
    ):
        a, b = (np.asarray(attrgetter(field)(model)) for model in (ref, gen))
        assert a.shape == b.shape and np.array_equal(a, b), field
    for name in (
        "cable_es",
        "cable_damping_time",
        "cable_entry_height",
        "frame_min",
        "frame_max",
        "cable_breaking_load",
        "platform_max_speed",
        "platform_max_angular_speed",
        "tag_size",
        "floor_height",
    ):
        np.testing.assert_array_equal(gen.numeric(name).data, ref.numeric(name).data)
    # the kinematics at 100 poses, each model driven by the twin's own physics core
    p_ref, p_gen = Physics(ref), Physics(gen)
    worst = {}
    for T in random_workspace_poses(100, seed=10):
        p_ref.place(T)
        p_gen.place(T)
        for key, a in _state(p_ref).items():
            b = _state(p_gen)[key]
            worst[key] = max(worst.get(key, 0.0), float(np.max(np.abs(a - b))))
    assert max(worst.values()) <= 1e-12, worst  # measured: 0 (bit for bit)


def test_the_committed_files_are_what_the_generator_writes(generated):
    _, robot_xml, scene_xml = generated
    assert (MODELS_DIR / "acrobot" / "acrobot.xml").read_text() == robot_xml
    assert (MODELS_DIR / "acrobot" / "scene.xml").read_text() == scene_xml


def test_the_description_carries_acrobots_numbers():
    r = load_robot(ACROBOT)
    np.testing.assert_array_equal(r.exit_points, A_BASE)
    np.testing.assert_array_equal(r.anchor_points, B_PLATFORM)
    np.testing.assert_allclose(r.es, 111e9 * np.pi * 0.001**2, rtol=1e-6)
    assert r.mass == 3.5 and r.camera.resolution == (640, 480) and r.tag.size == 0.04
    np.testing.assert_array_equal(2 * r.box_half_size, [0.18, 0.17, 0.07])
    # the paper §IV-A: sensors near B_i, −25…75 N, accuracy 0.24 N, repeatability 0.01 N
    t = r.tension_sensors
    assert (t.range, t.accuracy, t.repeatability, t.location) == (
        (-25.0, 75.0),
        0.24,
        0.01,
        "anchor",
    )
    cogiro = load_robot(MODELS_DIR / "cogiro" / "robot.toml")
    assert (cogiro.drum_radius, cogiro.max_payload, cogiro.sag) == (0.0675, 500.0, True)
    assert tuple(cogiro.tension_range) == (100.0, 5000.0)


def test_model_build_command_writes_both_files(tmp_path, capsys):
    assert main(["model", "build", str(ACROBOT), "--out", str(tmp_path)]) == 0
    assert "acrobot.xml" in capsys.readouterr().out
    assert (tmp_path / "acrobot.xml").read_text() == (
        MODELS_DIR / "acrobot" / "acrobot.xml"
    ).read_text()
    # the robot file compiles alone (no tag, no texture) and hangs still from its key
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "acrobot.xml"))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("p0").id)
    q0 = data.qpos.copy()
    mujoco.mj_step(model, data, nstep=1000)
    assert np.max(np.abs(data.qpos[:3] - q0[:3])) < 1e-4


def _edited(tmp_path: Path, old: str, new: str) -> Path:
    text = ACROBOT.read_text()
    assert old in text
    path = tmp_path / "robot.toml"
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(
    ("old", "new", "field"),
    [
        ("mass_kg = 3.5", "mass_kg = -3.5", "platform.mass_kg"),
        ("mass_kg = 3.5", "mass_g = 3500", "platform.mass_g"),  # unknown key (and mass missing)
        ("fovy_deg = 60.0", 'fovy_deg = "60"', "camera.fovy_deg"),
        ("    [0.4675, -0.5225, 1.165],\n]", "]", "cables.anchor_points_m"),  # 7 exits, 8 anchors
        ("axial_stiffness_n = 348716.8", "axial_stiffness_n = 3.5e5", "cables.axial_stiffness_n"),
        ("swivel_axis = [0.0, 0.0, 1.0]", "swivel_axis = [1.0, 0.0, 0.0]", "pulleys.swivel_axis"),
        (
            "tension_range_n = [2.0, 75.0]",
            "tension_range_n = [75.0, 2.0]",
            "winches.tension_range_n",
        ),
        ("[simulation]", "[simulation]\nsubsteps = 2", "simulation.substeps"),
        ("drum_radius_m = 0.02", "drum_radius_m = 0.0", "winches.drum_radius_m"),
        ('location = "anchor"', 'location = "winch"', "tension_sensors.location"),
        ("accuracy_n = 0.24\n", "", "tension_sensors.accuracy_n"),  # missing
        ("range_n = [-25.0, 75.0]", "range_n = [75.0, -25.0]", "tension_sensors.range_n"),
        ("range_n = [-25.0, 75.0]", "range_n = [5.0, 75.0]", "tension_sensors.range_n"),  # no 0 N
        ("max_mass_kg = 0.0", "max_mass_kg = -1.0", "payload.max_mass_kg"),
        # before: MuJoCo's "Error opening file" with a path relative to --out, at build time
        ('texture = "assets/tag36h11_00000.png"', 'texture = "nope.png"', "tag.texture"),
        ('texture = "assets/tag36h11_00000.png"', 'texture = "robot.toml"', "tag.texture"),
        ('texture = "assets/tag36h11_00000.png"', 'texture = "a\\u0000.png"', "tag.texture"),
        # each below once built, or failed with a trace or MuJoCo's nameless error
        ("timestep_s = 0.0005", "timestep_s = 1.0", "simulation.timestep_s"),  # diverged
        (
            "gravity_m_s2 = [0.0, 0.0, -9.81]",
            "gravity_m_s2 = [true, 0.0, -9.81]",
            "simulation.gravity_m_s2",
        ),  # read as [1, 0, -9.81]
        (
            "box_half_size_m = [0.09, 0.085, 0.035]",
            "box_half_size_m = [true, true, true]",
            "platform.box_half_size_m",
        ),  # read as a 1 m box
        ("mass_kg = 3.5", "mass_kg = 1" + "0" * 400, "platform.mass_kg"),  # OverflowError
        (
            "gravity_m_s2 = [0.0, 0.0, -9.81]",
            "gravity_m_s2 = [0.0, 0.0, -1" + "0" * 400 + "]",
            "simulation.gravity_m_s2",
        ),
        ("floor_height_m = -0.0505", "floor_height_m = 5.0", "frame.floor_height_m"),
        (
            "outer_min_m = [-0.6, -0.6, -0.05]",
            "outer_min_m = [-0.6, -0.6, 1.15]",
            "frame.outer_min_m",
        ),  # MuJoCo's "size 2 must be positive in geom"
        (
            "mass_kg = 3.5",
            "mass_kg = 3.5\ninertia_kg_m2 = [1.0, 1.0, 25.0]",
            "platform.inertia_kg_m2",
        ),  # A + B < C: no rigid body
        (
            "mass_kg = 3.5",
            "mass_kg = 3.5\ninertia_kg_m2 = [1.0, 1.0, 1.0, -40.0, 0.0, 0.0]",
            "platform.inertia_kg_m2",
        ),  # not positive definite
    ],
)
def test_a_bad_description_is_a_one_line_error_naming_file_and_field(
    tmp_path, capsys, old, new, field
):
    path = _edited(tmp_path, old, new)
    with pytest.raises(RobotError) as err:
        load_robot(path)
    message = str(err.value)
    assert message.startswith(f"{path}: ") and "\n" not in message
    assert field.split(".")[0] in message and (field.split(".")[1] in message or "mass" in message)
    assert main(["model", "build", str(path)]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert not (tmp_path / "acrobot.xml").exists()


def test_fewer_than_six_cables_is_refused(tmp_path):
    text = ACROBOT.read_text()
    start = text.index("exit_points_m = [") + len("exit_points_m = [")
    end = text.index("]\n", text.index("[0.4675, -0.5225, 1.165]")) + 1
    path = tmp_path / "robot.toml"
    path.write_text(
        text[:start] + "[0, 0, 1], [1, 0, 1], [0, 1, 1], [1, 1, 1], [0, 2, 1]]" + text[end:]
    )
    with pytest.raises(RobotError, match=r"cables\.exit_points_m: .*m ≥ 6 cables, got 5"):
        load_robot(path)


def _same_text(want: str, got: str, atol: float = 1e-12) -> bool:
    """Two generated files are the same: token by token, numbers to ``atol``."""
    a, b = re.split(r'([\s"=<>/]+)', want), re.split(r'([\s"=<>/]+)', got)
    if len(a) != len(b):
        return False
    for x, y in zip(a, b, strict=True):
        if x == y:
            continue
        try:
            if abs(float(x) - float(y)) > atol:
                return False
        except ValueError:
            return False
    return True


def test_cogiro_files_are_generated_and_carry_casprs_platform():
    cogiro = MODELS_DIR / "cogiro" / "robot.toml"
    r = load_robot(cogiro)
    robot_xml, scene_xml = model_texts(r)
    # the home key's qpos is the settled pose, whose residue (≤ 2e-15 m on a 2 m high platform)
    # depends on the machine's last bits: numbers within 1e-12, everything else exact
    assert _same_text((MODELS_DIR / "cogiro" / "cogiro.xml").read_text(), robot_xml)
    assert _same_text((MODELS_DIR / "cogiro" / "scene.xml").read_text(), scene_xml)
    model = mujoco.MjModel.from_xml_path(str(MODELS_DIR / "cogiro" / "scene.xml"))
    body = model.body("platform").id
    assert model.body_mass[body] == 91.058
    np.testing.assert_allclose(model.body_ipos[body], [-0.034, -0.013, 0.264], atol=1e-15)
    # MuJoCo's principal inertia = the eigenvalues of CASPR's full tensor (Ixy… products)
    ixx, iyy, izz, ixy, ixz, iyz = r.inertia
    tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    np.testing.assert_allclose(
        np.sort(model.body_inertia[body]), np.linalg.eigvalsh(tensor), rtol=1e-12
    )
    np.testing.assert_allclose(r.es, 68.5e9 * np.pi * 0.002**2, rtol=1e-8)


@pytest.mark.parametrize(
    "name", ["../../evil", "sub/x", "..", ".hidden", "a b", "c:\\\\x", "scene"]
)
def test_a_robot_name_that_is_not_a_plain_file_name_is_refused(tmp_path, name):
    # the name makes `<name>.xml`: "../../evil" wrote outside --out before; "scene" made both
    # files scene.xml, and the robot's was silently not written
    path = tmp_path / "d" / "robot.toml"
    path.parent.mkdir()
    path.write_text(ACROBOT.read_text().replace('name = "acrobot"', f'name = "{name}"', 1))
    with pytest.raises(RobotError, match=r"name: (must be a plain file name|'scene' names)"):
        build_files(path, tmp_path / "d" / "out")
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["d", "robot.toml"]


@pytest.mark.parametrize(
    ("old", "new", "key"),
    [('family = "tag36h11"', 'family = "tag25h9"', "family"), ("\nid = 0", "\nid = 3", "id")],
)
def test_a_tag_the_camera_would_never_detect_is_refused(tmp_path, old, new, key):
    # the detector looks for tag36h11 id 0: another tag would be rendered, then never found
    path = tmp_path / "robot.toml"
    path.write_text(ACROBOT.read_text().replace(old, new, 1))
    with pytest.raises(RobotError, match=rf"tag\.{key}: the twin detects tag36h11 id 0 only"):
        load_robot(path)


def test_a_description_that_is_not_utf8_names_its_file(tmp_path):
    path = tmp_path / "robot.toml"
    path.write_bytes(ACROBOT.read_bytes().replace(b"# ", b"# \x81", 1))
    with pytest.raises(RobotError, match=rf"^{re.escape(str(path))}: not UTF-8 text"):
        load_robot(path)


def test_cables_with_mass_need_gravity_down_the_z_axis(tmp_path):
    # before: sag's cable weight was 9.81 N/kg down z whatever the description's gravity
    path = _edited(tmp_path, "sag = false", "sag = true")
    text = path.read_text().replace(
        "gravity_m_s2 = [0.0, 0.0, -9.81]", "gravity_m_s2 = [1.0, 0, -9.8]"
    )
    path.write_text(text)
    with pytest.raises(RobotError, match=r"simulation\.gravity_m_s2: must point along -z"):
        load_robot(path)


def _buildable(tmp_path: Path, old: str, new: str) -> Path:
    """:func:`_edited`, its tag texture by absolute path (the description leaves its folder)."""
    path = _edited(tmp_path, old, new)
    texture = ACROBOT.parent / "assets" / "tag36h11_00000.png"
    path.write_text(path.read_text().replace('"assets/tag36h11_00000.png"', f'"{texture}"'))
    return path


def test_the_monitor_section_may_be_left_out_or_say_inf(tmp_path):
    # before: "monitor.platform_max_speed_m_s: must be a finite number, got inf", for a key
    # the user never wrote (the section is optional, inf its documented "unchecked")
    text = ACROBOT.read_text()
    section = text[text.index("[monitor]") : text.index("[scene]")]
    robot = load_robot(_buildable(tmp_path, section, ""))
    assert robot.max_speed == robot.max_angular_speed == float("inf")
    speed = "platform_max_speed_m_s = 1.5"
    path = _buildable(tmp_path, speed, "platform_max_speed_m_s = inf")
    robot = load_robot(path)
    assert robot.max_speed == float("inf") and robot.max_angular_speed == 12.0
    assert main(["model", "build", str(path), "--out", str(tmp_path / "out")]) == 0  # and builds


def test_a_home_pose_the_robot_cannot_hold_is_refused_not_written(tmp_path, capsys):
    # before: force_limit_n = 1 N (7.06 N needed) built a home keyframe 1 m below the pose,
    # under the floor, without a word. Truth: the settle of MuJoCo's own physics
    path = _buildable(tmp_path, "force_limit_n = 100000.0", "force_limit_n = 1.0")
    assert main(["model", "build", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "platform.home_pose: the platform does not rest there" in err
    assert "force_limit_n 1 N" in err
    assert not (tmp_path / "out" / "scene.xml").exists()
    assert (
        main(["model", "build", str(_buildable(tmp_path, "", "")), "--out", str(tmp_path / "ok")])
        == 0
    )


def test_a_robot_description_given_as_the_model_says_to_build_it(capsys):
    # before: "is malformed: could not find decoder for resource '…robot.toml'"
    assert main(["demo", "--model", str(ACROBOT)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"cdpr-twin model build {ACROBOT}" in err


def test_a_directory_given_for_a_description_is_called_a_directory(tmp_path):
    # before: "not found" for a directory that is there (model.nominal, a robot description)
    from cdpr_twin.robot.description import RobotError, load_robot

    with pytest.raises(ScenarioError, match=r": model\.nominal: .* is a directory; give a robot"):
        _pbvs(**{"model.nominal": str(tmp_path)})
    with pytest.raises(ScenarioError, match=r": model\.nominal: .*nothing\.toml not found"):
        _pbvs(**{"model.nominal": str(tmp_path / "nothing.toml")})
    with pytest.raises(RobotError, match=r": a directory, not a robot description; give its"):
        load_robot(tmp_path)
    with pytest.raises(RobotError, match=r"nothing\.toml: robot description not found"):
        load_robot(tmp_path / "nothing.toml")


def _pbvs(**changes):
    source = ROOT / "scenarios" / "paper_pbvs.toml"
    data = tomllib.loads(source.read_text())
    for key, value in changes.items():
        set_dotted(data, key, value)
    return scenario_from_data(data, source)
