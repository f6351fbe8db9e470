"""Bad input gets a clear error naming the problem."""

import math

import numpy as np
import pytest
from conftest import paper_pose

from cdpr_twin.math import se3
from cdpr_twin.math.statics import InfeasibleTensionError
from cdpr_twin.sim import ModelError, SimulationError, Twin


def test_missing_model_file(tmp_path):
    with pytest.raises(ModelError, match="not found"):
        Twin(model_path=tmp_path / "nope.xml", camera=False)


def test_malformed_model_file(tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><bodyy/></worldbody></mujoco>")
    with pytest.raises(ModelError, match=r"bad\.xml is malformed"):
        Twin(model_path=bad, camera=False)


def test_model_that_is_not_acrobot(tmp_path):
    other = tmp_path / "other.xml"
    other.write_text(
        "<mujoco><worldbody><body><freejoint/><geom size='0.1'/></body></worldbody></mujoco>"
    )
    with pytest.raises(ModelError, match="pulley1_swivel"):
        Twin(model_path=other, camera=False)


def test_pose_outside_the_frame(twin):
    with pytest.raises(ValueError, match="outside the frame"):
        twin.reset(se3.pose_from_vector([0.7, 0.0, 0.3, 0, 0, 0]))


def test_pose_without_feasible_tension_distribution(twin):
    with pytest.raises(InfeasibleTensionError, match="no tension distribution"):
        twin.reset(se3.pose_from_vector([0.45, 0.45, 0.1, 0, 0, 0]))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_cable_rate(twin, bad):
    twin.reset(paper_pose("p1"))
    rates = np.zeros(8)
    rates[3] = bad
    with pytest.raises(ValueError, match="finite"):
        twin.advance(0.04, rates)


def test_duration_not_a_whole_number_of_steps(twin):
    twin.reset(paper_pose("p1"))
    with pytest.raises(ValueError, match="whole number of physics steps"):
        twin.advance(0.04 + 1e-5, np.zeros(8))


def test_advance_before_reset():
    with Twin(camera=False) as t, pytest.raises(SimulationError, match="reset"):
        t.advance(0.04, np.zeros(8))


def test_non_rigid_pose_is_refused(twin):
    T = paper_pose("p1").copy()
    T[:3, :3] *= 1.5
    with pytest.raises(ValueError, match="not a rigid transform"):
        twin.reset(T)
    from cdpr_twin.plugins import make_estimator

    with pytest.raises(ValueError, match="not a rigid transform"):
        make_estimator("control", twin.nominal_geometry).reset(T)


@pytest.mark.parametrize("duration", [np.inf, np.nan, -0.04])
def test_non_finite_or_negative_duration(twin, duration):
    twin.reset(paper_pose("p1"))
    with pytest.raises(ValueError, match="duration"):
        twin.advance(duration, np.zeros(8))


@pytest.mark.parametrize(
    ("option", "value"), [("taut_threshold", np.nan), ("max_residual", -1.0), ("tension0", np.inf)]
)
def test_model_estimator_options_are_validated(twin, option, value):
    from cdpr_twin.plugins import make_estimator

    with pytest.raises(ValueError, match=option):
        make_estimator("model_simple", twin.nominal_geometry, **{option: value})


@pytest.mark.parametrize("selection", ["most_tensioned", "all_taut"])
def test_huge_finite_tensions_are_rejected_updates_not_a_crash(selection):
    """Tensions of 1e300 N (a broken sensor, an absurd noise): the elastic correction makes the
    targets infinite, and the solver used to step to an infinite pose (``math domain error``
    ending the run); it stops instead, and the update is flagged, the last pose held."""
    from dataclasses import replace

    from cdpr_twin.plugins import make_estimator
    from cdpr_twin.sim import Twin
    from cdpr_twin.types import Command

    tw = Twin(camera=False)
    try:
        T = paper_pose("p0")
        tw.reset(T)
        m = tw.sense(Command(np.zeros(8), np.zeros(6)))
        est = make_estimator("model_elastic_pulley", tw.nominal_geometry, selection=selection)
        est.reset(T, m.time)
        good = est.update(m)
        assert not good.flags and np.allclose(good.T_base_platform, T, atol=1e-3)
        bad = replace(m, time=m.time + 0.04, tensions=np.full(8, 1e300))
        held = est.update(bad)
        assert held.flags  # rejected, and why
        np.testing.assert_array_equal(held.T_base_platform, good.T_base_platform)
    finally:
        tw.close()


@pytest.mark.parametrize(("scale", "size"), [(64, "40960×30720"), (100_000, "64000000×48000000")])
def test_a_supersampled_buffer_too_large_for_the_gl_names_supersample(
    tmp_path, capsys, monkeypatch, scale, size
):
    """64× was blamed on a missing EGL: the buffer (40960 px) exceeds what Mesa can hold. At
    100 000× the lens's margins, sought along the supersampled frame's border before the size
    was checked, took every byte of memory (the kernel killed the run): the frame alone is
    refused first, the margins never sought."""
    from pathlib import Path

    from cdpr_twin.cli import main
    from cdpr_twin.sim import imaging

    margins = imaging.lens_margins
    monkeypatch.setattr(
        imaging, "lens_margins", lambda K, *a: margins(K, *a) if K.width < 16384 else 1 / 0
    )

    root = Path(__file__).resolve().parents[2]
    text = (root / "scenarios" / "paper_open_loop.toml").read_text()
    path = tmp_path / "s.toml"
    path.write_text(
        text.replace('"../models/', f'"{root}/models/')
        + f"\n[realism.camera]\nsupersample = {scale}\n"
    )
    assert main(["run", str(path), "--duration", "0.2", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{size} px" in err and "lower realism.camera.supersample" in err
    assert "EGL" not in err


@pytest.mark.parametrize("pulley", [False, True])
@pytest.mark.parametrize("goal", [1e152, 1e153, math.inf])
def test_the_solvers_stop_on_targets_no_pose_can_reach(pulley, goal):
    """Huge, inconsistent targets with small weights keep the cost finite while the step is not
    (``math domain error`` from the pose update, at 1e153 with weights 1e-2); both solvers
    say "not converged" instead."""
    from cdpr_twin.estimators.solvers import _cable_tuples, gauss_newton, solve_fast
    from cdpr_twin.sim import Twin

    with Twin(camera=False) as tw:
        g, T = tw.nominal_geometry, paper_pose("p0")
    radii = g.pulley_radius if pulley else None
    cables = _cable_tuples(g.a_base, g.b_platform, radii)
    targets = goal * np.arange(1.0, len(cables) + 1.0)  # no pose has these lengths
    for weight in (1.0, 1e-2):
        fit = gauss_newton(cables, pulley, targets, np.full(len(cables), weight), T)
        assert not fit.converged
    solution = solve_fast(
        g.a_base[:6], g.b_platform[:6], None if radii is None else radii[:6], targets[:6], T
    )
    assert not solution.residual <= 1e-6
