"""Robots of 6 and 12 cables, generated from descriptions, end to end through the runner.

Nothing in the package knows these robots (tests/fixtures/robots/): their cable count comes from
the description, through the generated MJCF. Truths: MuJoCo's own force balance (the recorded
tensions along MuJoCo's tendon Jacobian hold the weight), the description's waypoints, and the
generated model's tendon lengths against the paper's pulley model (eq. 15-24) computed from the
description's numbers alone.
"""

import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

from cdpr_twin.math import kinematics, se3
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.recording.timeseries import Timeseries
from cdpr_twin.robot.description import load_robot
from cdpr_twin.run.runner import run
from cdpr_twin.scenario.loading import load_scenario
from cdpr_twin.sim import Twin
from cdpr_twin.sim.mjcf_from_robot import build_files

ROBOTS = Path(__file__).resolve().parents[1] / "fixtures" / "robots"
CASES = {
    # robot: (start, away, camera); 'away' keeps the tag in view for the 12-cable camera
    "six_cables": ([0.0, 0.0, 0.4, 0, 0, 0], [0.05, -0.03, 0.35, 0, 0, 5], False),
    "twelve_cables": ([0.15, -0.1, 0.3, 0, 0, 0], [0.2, -0.15, 0.25, 3, -2, 5], True),
}


@pytest.fixture(scope="module", params=sorted(CASES))
def robot(request, tmp_path_factory):
    name = request.param
    out = tmp_path_factory.mktemp(name)
    description = ROBOTS / name / "robot.toml"
    _, scene = build_files(description, out)
    return name, load_robot(description), scene


def test_generated_tendons_match_the_pulley_model_from_the_description(robot):
    name, r, scene = robot
    geom = CdprGeometry(r.exit_points, r.anchor_points, r.sheave_radius, r.es, r.mass, np.zeros(3))
    start, away, _ = CASES[name]
    with Twin(scene, camera=False, tension_noise_std=0.0) as twin:
        assert twin.physics.n_cables == r.n_cables
        for pose in (start, away):
            T = se3.pose_from_vector(pose)
            twin.place(T)
            np.testing.assert_allclose(
                twin.physics.cable_lengths, kinematics.cable_lengths(geom, T, "pulley"), atol=1e-12
            )


def test_open_loop_run_end_to_end(robot, tmp_path):
    name, r, scene = robot
    start, away, camera = CASES[name]
    m = r.n_cables
    passive = ["model_simple", "model_elastic_pulley"] + (["image"] if camera else [])
    scenario_file = tmp_path / "run.toml"
    scenario_file.write_text(
        f"""
name = "{name}"
duration = 6.0
[model]
file = "{scene}"
align_every = 10
[sensors]
tension_noise_std = 0.0
camera = {str(camera).lower()}
[start]
pose = {start}
[controller]
type = "open_loop"
waypoints = [{away}, {start}]
durations = [3.0, 3.0]
[estimators]
in_loop = "control"
passive = {json.dumps(passive)}
"""
    )
    out = tmp_path / "out"
    summary = run(load_scenario(scenario_file), out, record_rrd=camera).summary
    assert summary["status"] == "done"
    assert summary["segment_ends"][0]["truth_vs_waypoint"]["translation_m"] < 1e-3
    assert summary["final_error_vs_goal"]["translation_m"] < 1e-3
    assert len(summary["final_tensions_n"]) == m
    e = summary["estimators"]["model_elastic_pulley"]  # six most tensioned of m, exact model
    assert e["max_translation_m"] < 1e-4 and e["final_translation_m"] < 1e-5
    ts = Timeseries.load(out / "timeseries.csv")
    if camera:  # the camera sees the tag all along: the image estimate is millimetres off
        valid = ts.columns["image_valid"].astype(bool)
        err = [
            np.linalg.norm(a[:3, 3] - b[:3, 3])
            for a, b in zip(ts.poses("true"), ts.poses("image"), strict=True)
        ]
        assert valid.all() and np.median(err) < 5e-3  # measured: median 3.2 mm, max 8 mm
        assert (out / "recording.rrd").stat().st_size > 0
    assert (
        ts.n_cables == m and f"tension_{m}" in ts.columns and f"tension_{m + 1}" not in ts.columns
    )
    assert ts.matrix("rate").shape == (len(ts.t), m)
    # the recorded end state is a force balance in MuJoCo's own terms
    T_end = ts.poses("true")[-1]
    with Twin(scene, camera=False, tension_noise_std=0.0) as twin:
        twin.place(T_end)
        model, d = twin.model, twin.data
        ids = [
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TENDON, f"cable{i + 1}_tendon")
            for i in range(m)
        ]
        J = np.array(d.ten_J).reshape(model.ntendon, model.nv)[ids]
    weight = r.mass * 9.81
    np.testing.assert_allclose(
        -J[:, :3].T @ ts.matrix("tension")[-1], [0, 0, weight], atol=0.01 * weight
    )
