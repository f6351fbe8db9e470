"""What a run checks of its scenario before it starts (:mod:`cdpr_twin.scenario.preflight`): a
goal the robot cannot reach or see whole, a plan it cannot follow, a nominal description of
another robot — each refused in one line naming the field. So are valid-looking but extreme
values (timing that runs no tick, magnitudes that break the physics, more waypoints than a plan
may stop at), which used to run wrong, fail mid-run or exhaust the machine."""

import tomllib
from pathlib import Path

import numpy as np
import pytest
from conftest import paper_pose

from cdpr_twin.campaign.spec import set_dotted
from cdpr_twin.controllers.open_loop import MIN_PERIODS, OpenLoopController, OpenLoopOptions
from cdpr_twin.math import kinematics as kin
from cdpr_twin.math import se3
from cdpr_twin.plugins import lookup
from cdpr_twin.run.runner import prepare
from cdpr_twin.scenario.loading import ScenarioError, load_scenario, scenario_from_data
from cdpr_twin.scenario.preflight import check_task

ROOT = Path(__file__).resolve().parents[2]
OPEN_LOOP = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
PBVS = (ROOT / "scenarios" / "paper_pbvs.toml").read_text()


def _pbvs(**changes):
    source = ROOT / "scenarios" / "paper_pbvs.toml"
    data = tomllib.loads(source.read_text())
    for key, value in changes.items():
        set_dotted(data, key, value)
    return scenario_from_data(data, source)


def test_a_pbvs_goal_the_nominal_robot_cannot_reach_is_refused():
    # the tag seen 5 m away: the platform would be 5 m above it (z = 4.99 m), out of the frame
    s = _pbvs(**{"controller.goal_tag_pose_visp": [0.0, 0.0, 5.0, 180, 0, 180]})
    with pytest.raises(ScenarioError, match=r"its goal .* puts the platform .* outside the frame"):
        prepare(s)


def test_the_papers_goal_is_accepted():
    prepare(_pbvs()).close()


def test_a_pbvs_goal_view_that_cuts_the_tag_is_refused_by_runs_and_campaigns(tmp_path):
    # truth: the pinhole projection of the tag's corners, by hand: at 9 cm, 4.5 cm off the
    # optical axis, the 4 cm tag's far edge sits at y = 0.065 m, v = cy + fy·0.065/0.09 > 480
    from cdpr_twin.scenario.preflight import check_task
    from cdpr_twin.sim import nominal_robot

    K = nominal_robot("acrobot").intrinsics
    assert K.cy + K.fy * (0.045 + 0.02) / 0.09 > K.height  # the far edge below the image
    assert K.cy + K.fy * (0.01 + 0.02) / 0.09 < K.height - 1  # 1 cm off: inside
    s = _pbvs(**{"controller.goal_tag_pose_visp": [0.0, 0.045, 0.09, 180, 0, 180]})
    with pytest.raises(ScenarioError, match=r"goal_tag_pose_visp: .* would not see the whole tag"):
        prepare(s)
    with pytest.raises(ScenarioError, match=r"would not see the whole tag"):
        check_task(s)  # what a campaign checks of every run before the first starts
    s = _pbvs(**{"controller.goal_tag_pose_visp": [0.0, 0.01, 0.09, 180, 0, 180]})
    prepare(s).close()  # 1 cm off: the whole tag in the image


def test_an_open_loop_segment_shorter_than_a_control_tick_is_refused():
    source = ROOT / "scenarios" / "paper_open_loop.toml"
    data = tomllib.loads(source.read_text())
    set_dotted(data, "controller.durations", [0.001, 5.0, 10.0])  # was skipped: 326 mm off p1
    with pytest.raises(ScenarioError, match=r"durations\[0\]: 0.001 s is shorter than 5 control"):
        prepare(scenario_from_data(data, source).with_overrides(camera=False))


def test_a_platform_above_its_exit_points_is_said_so():
    source = ROOT / "scenarios" / "paper_open_loop.toml"
    data = tomllib.loads(source.read_text())
    set_dotted(data, "truth.exit_point_std", 1.0)  # exit points a metre off: some below p0
    s = scenario_from_data(data, source).with_overrides(camera=False)
    with pytest.raises(ScenarioError, match="is not below the lowest exit point") as error:
        prepare(s)
    assert "anchor points []" not in str(error.value)  # was: "puts anchor points [] outside"


@pytest.mark.parametrize(("shift_m", "refused"), [(0.05, False), (0.2, True)])
def test_a_nominal_description_of_another_robot_is_refused_as_such(tmp_path, shift_m, refused):
    # before: COGIRO's description as ACROBOT's nominal model was refused as "start.pose is
    # outside the wrench-feasible workspace" (COGIRO's 100-5000 N tension range at ACROBOT's
    # start pose); an exit point moved 5 cm (4x ACROBOT's 12 mm tolerance) is a belief about
    # the same robot, 20 cm (beyond 10 % of its 1.05 m span of exit points) another robot
    from cdpr_twin import resources

    cogiro = resources.models_dir() / "cogiro" / "robot.toml"
    with pytest.raises(ScenarioError, match=r": model\.nominal: .*cogiro.*another robot"):
        prepare(_pbvs(**{"model.nominal": str(cogiro)}))
    source = resources.models_dir() / "acrobot" / "robot.toml"
    text = source.read_text().replace('"assets/', f'"{source.parent}/assets/')
    moved = text.replace("[-0.4725, -0.5275, 1.165]", f"[-0.4725, -0.5275, {1.165 + shift_m}]")
    assert moved != text
    (tmp_path / "robot.toml").write_text(moved)
    s = _pbvs(**{"model.nominal": str(tmp_path / "robot.toml")})
    if refused:
        with pytest.raises(ScenarioError, match=r"exit point 1 is 0\.2 m from the model's"):
            prepare(s)
    else:
        prepare(s).close()


def test_a_bad_nominal_description_is_named_by_its_own_key_and_a_directory_as_one(tmp_path):
    # before: both said model.file, and a directory was "not found"
    bad = tmp_path / "robot.toml"
    bad.write_text('name = "acrobot"\n')  # a description without its tables
    s = _pbvs(**{"model.nominal": str(bad)})
    with pytest.raises(ScenarioError, match=r": model\.nominal: .*robot\.toml"):
        prepare(s)
    data = tomllib.loads((ROOT / "scenarios" / "paper_open_loop.toml").read_text())
    data["model"] = {"file": str(tmp_path)}
    with pytest.raises(ScenarioError, match=r": model\.file: model file .* is a directory"):
        prepare(scenario_from_data(data, ROOT / "scenarios" / "paper_open_loop.toml"))


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
