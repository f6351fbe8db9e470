"""Valid-looking but extreme inputs an independent probe ran: each is refused before a run, with
the field named, where it used to run wrong, fail mid-run or exhaust the machine."""

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import paper_pose

from cdpr_twin.campaign import CampaignError, load_campaign
from cdpr_twin.controllers.open_loop import MIN_PERIODS, OpenLoopController, OpenLoopOptions
from cdpr_twin.math import kinematics as kin
from cdpr_twin.math import se3
from cdpr_twin.plugins import OptionError, lookup
from cdpr_twin.scenario.loading import ScenarioError, load_scenario
from cdpr_twin.scenario.preflight import check_task
from cdpr_twin.sim import camera

ROOT = Path(__file__).resolve().parents[2]
OPEN_LOOP = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
PBVS = (ROOT / "scenarios" / "paper_pbvs.toml").read_text()


def _file(tmp_path, text, old=None, new="", extra=""):
    text = text.replace('"../models/', f'"{ROOT}/models/')
    if old is not None:
        assert old in text
        text = text.replace(old, new, 1)
    path = tmp_path / "s.toml"
    path.write_text(text + extra)
    return path


def _refused(path, match):
    with pytest.raises(ScenarioError, match=match):
        check_task(load_scenario(path))


def test_a_segment_of_few_periods_would_pay_its_motion_out_wrong_and_is_refused(tmp_path, twin):
    """The twist sampled at each period's midpoint, over n periods, against the lengths the
    segment must change: the midpoint rule on the quintic's speed predicts 1 + e(n), e = 87.5 %
    (1 period), 5.47 % (2), 0.14 % (5, the shortest allowed): the plan pays exactly that out."""
    geom, period = twin.nominal_geometry, 0.04
    p0 = paper_pose("p0")
    goal = p0 @ se3.se3_exp([0.002, 0.001, -0.004, 0.0, 0.0, 0.01])  # 4.6 mm, 0.6°
    need = kin.cable_lengths(geom, goal, "pulley") - kin.cable_lengths(geom, p0, "pulley")
    for n, expected in ((1, 0.875), (2, 0.0546875), (MIN_PERIODS, 0.0014)):
        options = OpenLoopOptions((goal,), (n * period,), jacobian_model="pulley")
        paid = OpenLoopController(geom, options).planned_rates(p0, period, n * period)
        ratio = paid.sum(axis=0) * period / need
        assert np.allclose(ratio, 1.0 + expected, rtol=1e-5, atol=0.0), ratio
    path = _file(tmp_path, OPEN_LOOP, "durations = [10.0, 5.0, 10.0]", "durations = [0.16, 5, 10]")
    _refused(path, r"controller.durations\[0\]: 0.16 s is shorter than 5 control periods")


def test_a_plan_faster_than_the_winches_is_refused_before_the_run(tmp_path):
    path = _file(tmp_path, OPEN_LOOP, "durations = [10.0, 5.0, 10.0]", "durations = [0.2, 5, 10]")
    _refused(path, r"controller.durations\[0\]: at t = .* beyond its winch's range \[-0.5, 0.5\]")
    fine = _file(tmp_path, OPEN_LOOP, "durations = [10.0, 5.0, 10.0]", "durations = [2, 5, 10]")
    check_task(load_scenario(fine))


def test_pbvs_speed_caps_beyond_the_winches_are_refused_and_the_bound_holds(tmp_path, twin):
    path = _file(tmp_path, PBVS, "max_linear_speed = 0.04", "max_linear_speed = 10.0")
    _refused(path, r"controller.max_linear_speed: .* up to 10 m/s .* beyond the winches' 0.5")
    # the bound is one: random camera twists at both caps, at random feasible poses
    s = load_scenario(_file(tmp_path, PBVS))
    geom = twin.nominal_geometry
    ctl = lookup("controller", "pbvs")(geom, s.controller.options)
    bound, rng, worst = ctl.peak_cable_rate(), np.random.default_rng(4), 0.0
    for _ in range(200):
        v, w = rng.normal(size=3), rng.normal(size=3)
        v_cam = np.concatenate(
            [
                v / np.linalg.norm(v) * ctl.max_linear_speed,
                w / np.linalg.norm(w) * ctl.max_angular_speed,
            ]
        )
        T = paper_pose("p1") @ se3.se3_exp(rng.uniform(-0.05, 0.05, 6))
        rates = kin.jacobian(geom, T, "platform", "pulley") @ (ctl._Ad @ v_cam)
        worst = max(worst, float(np.abs(rates).max()))
    assert worst <= bound and worst > 0.5 * bound  # a bound, and not a loose one


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        ("duration = 25.0", "duration = 0.02", r"duration: 0.02 s must span 1"),  # round(0.5) = 0
        ("control_rate = 25.0", "control_rate = 33.33333", r"model.control_rate: the control"),
    ],
)
def test_timing_that_would_run_no_tick_or_fail_mid_run_is_refused(tmp_path, old, new, match):
    with pytest.raises(ScenarioError, match=match):
        load_scenario(_file(tmp_path, OPEN_LOOP, old, new))


@pytest.mark.parametrize(
    ("table", "line", "match"),
    [
        ("realism.winch", "drum_radius_error_std = 3.0", "drum_radius_error_std: must be ≤ 0.1"),
        ("realism.camera", "focal_error_std = 5.0", "focal_error_std: must be ≤ 0.1"),
        ("realism.tension", "gain_error_std = 0.5", "gain_error_std: must be ≤ 0.1"),
        ("realism.camera", "full_well_e = 1e39", "full_well_e: must be ≤ 1e\\+30"),
        ("realism.camera", "latency_ticks = 10000000000", "latency_ticks: must be ≤ 100"),
        ("estimators.fused", "process_position_std = 1e155", "process_position_std: must be ≤"),
    ],
)
def test_magnitudes_that_break_the_physics_or_the_arithmetic_are_refused(
    tmp_path, table, line, match
):
    header = f"\n[{table}]\n"  # (a table, not a comment naming it)
    if header in PBVS:
        path = _file(tmp_path, PBVS, header, header + line + "\n")
    else:
        path = _file(tmp_path, PBVS, extra=f"\n{header}{line}\n")
    with pytest.raises(ScenarioError, match=f"{table}.{match}"):
        load_scenario(path)


def test_the_relative_std_bound_keeps_negative_draws_beyond_10_sigma():
    from cdpr_twin.robot.realism import WinchRealism
    from cdpr_twin.robot.realism_limits import MAX_RELATIVE_STD

    WinchRealism(drum_radius_error_std=MAX_RELATIVE_STD)
    with pytest.raises(OptionError, match=r"once in 20\.9 robots"):  # P(z < −1/0.6) = 0.0478
        WinchRealism(drum_radius_error_std=0.6)
    assert 0.5 * math.erfc(1 / MAX_RELATIVE_STD / math.sqrt(2)) < 1e-22


def test_frames_the_buffer_or_the_memory_cannot_hold_are_refused(monkeypatch):
    camera.check_frame_size(640, 480, 4)
    with pytest.raises(ValueError, match=r"17000×480 px: more than an offscreen buffer .* resolu"):
        camera.check_frame_size(17000, 480)
    with pytest.raises(ValueError, match=r"16000×12000 px.*supersample"):
        camera.check_frame_size(640, 480, 25)
    monkeypatch.setattr(camera, "_available_memory", lambda: 2_000_000_000)
    camera.check_frame_size(640, 480, 6)  # 1.8 GB of images
    with pytest.raises(ValueError, match=r"about 3\.1 GB of images .* than the 2\.0 GB"):
        camera.check_frame_size(640, 480, 8)


def test_a_campaign_refuses_what_its_runs_would_before_any_starts(tmp_path):
    scenario = ROOT / "scenarios" / "paper_open_loop.toml"
    base = f'scenario = "{scenario}"\n[overrides]\nduration = 0.2\n'
    for axis, match in (
        ('key = "realism.camera.exposure_s"\nvalues = [0.004, 0.05]', "exposure_s: 0.05 s"),
        ('key = "truth.exit_point_std"\nvalues = [0, 0.0]', "are identical"),
        ('key = "controller.durations"\nvalues = [[10, 5, 10], [10.0, 5.0, 10.0]]', "identical"),
    ):
        path = tmp_path / "c.toml"
        path.write_text(base + "\n[[axes]]\n" + axis + "\n")
        with pytest.raises(CampaignError, match=match):
            load_campaign(path)


@pytest.mark.parametrize(
    ("old", "new", "problem"),
    [
        ("tension_range_n = [2.0, 75.0]", "tension_range_n = [2.0, 2.5]",
         "platform.home_pose: no tension distribution with 2.0 N ≤ τ ≤ 2.5 N"),
        # before: the frame's message without the file or the field
        ("home_pose = [0.112,", "home_pose = [5.0,", "platform.home_pose: reset pose at position"),
        # before: "quaternion [0. 0. 0. 0.] is zero or not finite", no file or field
        ("quat_wxyz = [0.0, 0.0, 0.0, 1.0]", "quat_wxyz = [0.0, 0.0, 0.0, 0.0]",
         "camera.quat_wxyz: must be a non-zero quaternion"),
    ],
)  # fmt: skip
def test_what_model_build_refuses_names_the_description_and_field(
    tmp_path, capsys, old, new, problem
):
    import shutil

    from cdpr_twin.cli import main

    shutil.copytree(ROOT / "models" / "acrobot", tmp_path / "robot")
    desc = tmp_path / "robot" / "robot.toml"
    text = desc.read_text()
    assert old in text
    desc.write_text(text.replace(old, new, 1))
    assert main(["model", "build", str(desc), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{desc}: {problem}" in err


def test_a_vanishing_workspace_spacing_is_an_error_without_warnings():
    import warnings

    from cdpr_twin.math.workspace import spacing_problem
    from cdpr_twin.sim import Twin

    geom = Twin(camera=False).nominal_geometry
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert "gives inf grid points" in spacing_problem(geom, 1e-300)


def _waypoints(tmp_path, n):
    """The open-loop scenario with its three waypoints repeated to ``n``."""
    start = OPEN_LOOP.index("waypoints = [")
    end = OPEN_LOOP.index("durations = [10.0, 5.0, 10.0]")
    three = [
        [0.284, -0.197, 0.08, 0, 0, 0],
        [0.284, -0.197, 0.25, 0, 0, 0],
        [0.112, -0.032, 0.301, -12, -10, 0],
    ]
    poses = (three * n)[:n]
    text = (
        OPEN_LOOP[:start]
        + f"waypoints = {poses}\ndurations = {[2.0] * n}"
        + OPEN_LOOP[end + len("durations = [10.0, 5.0, 10.0]") :]
    )
    return _file(tmp_path, text)


def test_more_waypoints_than_a_plan_may_stop_at_are_refused_before_any_is_read(
    tmp_path, capsys, monkeypatch
):
    """Before: 100 000 waypoints spent > 120 s in preflight for a 1 s run. Refused now by
    their count, one line naming the field, before a pose is parsed or a linear program runs
    (each is counted, not timed)."""
    from cdpr_twin.cli import main
    from cdpr_twin.controllers.open_loop import MAX_WAYPOINTS
    from cdpr_twin.math import workspace
    from cdpr_twin.scenario import toml_reading as options

    parsed, programs = [], []
    pose = options.pose_from_vector
    feasible = workspace.is_feasible
    monkeypatch.setattr(options, "pose_from_vector", lambda v: parsed.append(v) or pose(v))
    monkeypatch.setattr(
        workspace, "is_feasible", lambda *a, **k: programs.append(a) or feasible(*a, **k)
    )
    path = _waypoints(tmp_path, MAX_WAYPOINTS + 1)
    out = tmp_path / "out"
    argv = ["run", str(path), "--duration", "0.2", "--no-camera", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and not out.exists()
    assert f"{path}: controller.waypoints: must list at most {MAX_WAYPOINTS} poses" in err
    assert f"got {MAX_WAYPOINTS + 1}" in err
    assert len(parsed) == 1 and programs == []  # the start pose only: no waypoint was read


def test_preflight_checks_each_waypoint_once(tmp_path, monkeypatch):
    """The checks before a run grow linearly with the waypoints: one inside-the-frame check and
    one linear program (wrench feasibility) per waypoint, whatever their number."""
    from cdpr_twin.controllers import open_loop
    from cdpr_twin.math import geometry

    counts = {}
    feasible = open_loop.is_feasible
    inside = geometry.CdprGeometry.check_pose_inside

    def counted_feasible(*a, **k):
        counts["feasible"] = counts.get("feasible", 0) + 1
        return feasible(*a, **k)

    def counted_inside(self, *a, **k):
        counts["inside"] = counts.get("inside", 0) + 1
        return inside(self, *a, **k)

    monkeypatch.setattr(open_loop, "is_feasible", counted_feasible)
    monkeypatch.setattr(geometry.CdprGeometry, "check_pose_inside", counted_inside)
    for n in (3, 30, 300):
        counts.clear()
        scenario = load_scenario(_waypoints(tmp_path, n)).with_overrides(duration=0.2)
        check_task(scenario)
        assert counts == {"feasible": n, "inside": n + 2}, (n, counts)  # + start and goal
