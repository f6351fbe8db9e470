"""A 6-cable robot (inline MJCF, not ACROBOT) through the physics core and an open-loop run.

Nothing in the package knows this robot: the cable count and names are read from the model.
Its six cables form an inverted Stewart-Gough pattern (three exit pairs on a 0.5 m circle,
three anchor pairs on the platform's top face), so the tension distribution is unique and,
at the centre, equal in all six cables by symmetry.
"""

import json

import mujoco
import numpy as np
import pytest

from cdpr_twin.math import se3
from cdpr_twin.recording.timeseries import Timeseries
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import load_scenario
from cdpr_twin.sim import Twin, build_robot

MASS = 3.5
START = [0.0, 0.0, 0.4, 0.0, 0.0, 0.0]
AWAY = [0.05, -0.03, 0.35, 0.0, 0.0, 5.0]


def six_cable_mjcf() -> str:
    """A suspended 6-cable robot: entry site → swivelling sheave → anchor, integrating winches."""
    parts = {"bodies": "", "anchors": "", "tendons": "", "winches": ""}
    for i in range(6):
        k, s = divmod(i, 2)
        a, b = np.radians(120 * k + (20 if s else -20)), np.radians(120 * k + (45 if s else -45))
        ax, ay, bx, by = 0.5 * np.cos(a), 0.5 * np.sin(a), 0.08 * np.cos(b), 0.08 * np.sin(b)
        n = i + 1
        parts["bodies"] += f"""
    <body name="pulley{n}_swivel" pos="{ax:.6f} {ay:.6f} 1.165" mocap="true">
      <geom name="pulley{n}_sheave" type="cylinder" size="0.0045 0.002" pos="0.0045 0 0"
            euler="1.5707963267948966 0 0" contype="0" conaffinity="0" density="0"/>
      <site name="cable{n}_entry" pos="0 0 0.03"/>
      <site name="pulley{n}_side" pos="0.0045 0 -0.009"/>
    </body>"""
        parts["anchors"] += f'<site name="cable{n}_anchor" pos="{bx:.6f} {by:.6f} 0.035"/>'
        parts["tendons"] += f"""
    <spatial name="cable{n}_tendon">
      <site site="cable{n}_entry"/>
      <geom geom="pulley{n}_sheave" sidesite="pulley{n}_side"/>
      <site site="cable{n}_anchor"/>
    </spatial>"""
        parts["winches"] += (
            f'<general name="winch{n}_actuator" tendon="cable{n}_tendon" dyntype="integrator" '
            'gaintype="fixed" biastype="affine" ctrlrange="-0.5 0.5" forcerange="-100000 0" '
            'actrange="0.05 3"/>'
        )
    return f"""<mujoco model="six_cables">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.0005" integrator="implicitfast"/>
  <custom>
    <numeric name="cable_es" data="{" ".join(["348716.8"] * 6)}"/>
    <numeric name="cable_damping_time" data="0.0005"/>
    <numeric name="cable_entry_height" data="0.03"/>
    <numeric name="frame_min" data="-0.6 -0.6 0.0"/>
    <numeric name="frame_max" data="0.6 0.6 1.15"/>
  </custom>
  <worldbody>{parts["bodies"]}
    <body name="platform" pos="0 0 0.4">
      <freejoint/>
      <geom name="platform_box" type="box" size="0.09 0.09 0.035" mass="{MASS}"
            contype="0" conaffinity="0"/>
      {parts["anchors"]}
    </body>
  </worldbody>
  <tendon>{parts["tendons"]}
  </tendon>
  <actuator>{parts["winches"]}</actuator>
</mujoco>"""


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("six") / "six_cables.xml"
    path.write_text(six_cable_mjcf())
    return path


def test_physics_core_holds_a_six_cable_robot_in_force_balance(model_file):
    built = build_robot(model_file)
    physics, nominal = built.physics, built.nominal
    assert physics.n_cables == 6 and physics.cable_names[-1] == "cable6"
    assert nominal.intrinsics is None and nominal.T_base_tag is None  # no camera, no tag
    for pose in (START, AWAY):
        T = se3.pose_from_vector(pose)
        physics.reset(T)
        physics.advance(1.0, np.zeros(6))  # one second at rest
        dt, dr = se3.pose_distance(physics.T_base_platform, T)
        assert dt < 1e-6 and dr < 1e-5  # a static equilibrium (measured ≈ 1e-9 m)
        d = physics.data
        # MuJoCo's own balance: the cables' generalised force cancels gravity (qfrc_bias at rest)
        np.testing.assert_allclose(d.qfrc_actuator, d.qfrc_bias, atol=1e-6 * MASS * 9.81)
        np.testing.assert_allclose(d.qfrc_bias[:3], [0.0, 0.0, MASS * 9.81], rtol=1e-9, atol=1e-12)
        assert np.all(physics.tensions > 1.0)
    physics.reset(se3.pose_from_vector(START))
    # by symmetry, at the centre every cable carries the same share of the weight
    tau = physics.tensions
    np.testing.assert_allclose(tau, tau.mean(), rtol=1e-4)  # measured 2e-5 after the settle
    # paying cable 1 out slackens it and moves the platform: the core drives any cable count
    physics.advance(0.2, np.array([0.01, 0, 0, 0, 0, 0]))
    assert physics.tensions[0] < tau[0] - 1.0


def test_twin_without_camera_on_a_six_cable_robot(model_file):
    with Twin(model_file, camera=False, tension_noise_std=0.0) as twin:
        twin.reset(se3.pose_from_vector(AWAY))
        m = twin.sense()
        assert m.n_cables == 6 and m.image is None and m.tag is None
        # the encoders read rest lengths that, through the elastic law, give MuJoCo's tensions
        # at MuJoCo's tendon lengths (independent of the sensors' code): τ = E·S/l0 (L − l0)
        es = 348716.8
        np.testing.assert_allclose(
            m.tensions, es / m.cable_lengths * (twin.cable_lengths - m.cable_lengths), rtol=1e-6
        )
    with pytest.raises(Exception, match="no camera"):
        Twin(model_file, camera=True)


def test_open_loop_run_on_a_six_cable_robot(model_file, tmp_path):
    scenario_file = tmp_path / "six.toml"
    scenario_file.write_text(
        f"""
name = "six_cables"
duration = 6.0
[model]
file = "{model_file}"
align_every = 10
[sensors]
tension_noise_std = 0.0
camera = false
[start]
pose = {START}
[controller]
type = "open_loop"
waypoints = [{AWAY}, {START}]
durations = [3.0, 3.0]
[estimators]
in_loop = "control"
passive = ["model_simple", "model_elastic_pulley"]
"""
    )
    out = tmp_path / "out"
    summary = run(load_scenario(scenario_file), out, record_rrd=False).summary
    assert summary["status"] == "done"
    assert summary["final_error_vs_goal"]["translation_m"] < 1e-3
    at_away = summary["segment_ends"][0]
    assert abs(at_away["time_s"] - 3.0) < 1e-6
    assert at_away["truth_vs_waypoint"]["translation_m"] < 1e-3  # the nominal robot follows
    # with the matching model and exact sensors the six-cable solve is exact at rest; in motion
    # the damping part of the tension (c·L̇) is read as stretch (measured max ≈ 24 µm)
    e = summary["estimators"]["model_elastic_pulley"]
    assert e["max_translation_m"] < 1e-4 and e["final_translation_m"] < 1e-5
    assert len(summary["final_tensions_n"]) == 6
    ts = Timeseries.load(out / "timeseries.csv")
    assert ts.n_cables == 6 and "tension_7" not in ts.columns
    assert ts.estimator_names == ("control", "model_simple", "model_elastic_pulley")
    assert json.loads((out / "summary.json").read_text())["ticks_recorded"] == len(ts.t)
    # the recorded end state is a force balance: the recorded tensions along MuJoCo's own cable
    # directions at the recorded final pose hold the platform's weight
    T_end = ts.poses("true")[-1]
    with Twin(model_file, camera=False, tension_noise_std=0.0) as twin:
        twin.place(T_end)
        d = twin.data
        tendons = [
            mujoco.mj_name2id(twin.model, mujoco.mjtObj.mjOBJ_TENDON, f"cable{i + 1}_tendon")
            for i in range(6)
        ]
        J = np.array(d.ten_J).reshape(twin.model.ntendon, twin.model.nv)[tendons]
        tau_end = ts.matrix("tension")[-1]
        # measured: 0.14 N sideways of 34.3 N (the platform still sways 0.1 s after the stop)
        np.testing.assert_allclose(-J[:, :3].T @ tau_end, [0, 0, MASS * 9.81], atol=0.3)
