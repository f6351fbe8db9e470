"""The compiled Newton solve (``estimators.newton``) equals the scalar reference bit for bit.

The reference, ``solvers._newton``, is itself held to SciPy's least squares and to the truth
in ``test_model_estimators.py``; here the two are compared on the same inputs with ``==`` on
every float: starts near the root (the estimators' case), far ones (step halving), the straight
and pulley kernels, and the systems where the compiled solve hands over to the reference.
"""

import numpy as np
import pytest
from conftest import random_workspace_poses

from cdpr_twin.estimators import newton
from cdpr_twin.estimators.solvers import _cable_tuples, _newton
from cdpr_twin.math import kinematics as kin
from cdpr_twin.math import se3
from cdpr_twin.plugins import make_estimator
from cdpr_twin.types import Measurement


def _cases(geom, n, seed, far):
    """(cables, goal, T0, T): six random cables, the pulley or straight lengths at a random
    workspace pose T with 0.2 mm of noise, a start ``far`` (m, rad per axis) from T."""
    rng = np.random.default_rng(seed)
    out = []
    for T in random_workspace_poses(n, seed=seed):
        idx = np.sort(rng.choice(geom.n_cables, 6, replace=False))
        pulley = bool(rng.integers(2))
        radii = geom.pulley_radius if pulley else None
        cables = _cable_tuples(geom.a_base, geom.b_platform, radii)
        model = "pulley" if pulley else "straight"
        goal = kin.cable_lengths(geom, T, model)[idx] + rng.normal(0.0, 2e-4, 6)
        T0 = T @ se3.se3_exp(rng.uniform(-far, far, 6))
        out.append(([cables[i] for i in idx], pulley, goal, T0))
    return out


@pytest.mark.parametrize("far", [0.005, 0.3])
def test_compiled_newton_equals_the_reference_bit_for_bit(twin, far):
    geom = twin.nominal_geometry
    halved = main = 0
    for cables, pulley, goal, T0 in _cases(geom, 150, seed=11, far=far):
        T, res, it, outcome = newton.newton(np.array(cables), goal, T0, 30, 1e-12)
        ref = _newton(cables, pulley, goal, T0)
        T_ref, res_ref, it_ref = ref.T, ref.residual, ref.iterations
        if outcome != newton.MAIN:
            continue
        main += 1
        assert it == it_ref and res == res_ref
        assert np.array_equal(T, T_ref)
        halved += res_ref > 1e-6  # far starts that did not reach a root
    assert main >= 140  # the main path is the one taken
    if far > 0.1:
        assert halved > 0  # the step halving and its give-up were exercised


def test_compiled_newton_hands_singular_and_infinite_systems_to_the_reference(twin):
    geom = twin.nominal_geometry
    cables, pulley, goal, T0 = _cases(geom, 1, seed=3, far=0.005)[0]
    point = np.array(cables)
    point[:, 3:6] = 0.0  # every anchor at the platform's origin: no moment arm, rank 3
    *_, outcome = newton.newton(point, goal, T0, 30, 1e-12)
    assert outcome == newton.FALLBACK
    infinite = goal.copy()
    infinite[2] = np.inf
    *_, outcome = newton.newton(np.array(cables), infinite, T0, 30, 1e-12)
    assert outcome == newton.FALLBACK
    # the estimator then solves with the reference (its least-squares step), same result
    est = make_estimator("model_pulley" if pulley else "model_simple", geom)
    est._cables, est._cable_array = [tuple(c) for c in point], point
    got = est.solve(goal, list(range(6)), T0)
    ref = _newton(est._cables, pulley, goal, T0)
    assert np.array_equal(got.T, ref.T)
    assert got.residual == ref.residual and got.iterations == ref.iterations > 0


@pytest.mark.parametrize("name", ["model_simple", "model_elastic_pulley"])
def test_estimators_give_the_same_pose_compiled_or_not(twin, name):
    geom = twin.nominal_geometry
    compiled, reference = (make_estimator(name, geom) for _ in range(2))
    reference._compiled = False
    assert compiled._compiled
    for T in random_workspace_poses(30, seed=5):
        lengths = kin.cable_lengths(geom, T, "pulley")
        m = Measurement(0.0, lengths, np.full(geom.n_cables, 10.0) + np.arange(8))
        T0 = T @ se3.se3_exp(np.full(6, 0.004))
        compiled.reset(T0)
        reference.reset(T0)
        a, b = compiled.update(m), reference.update(m)
        assert a.valid == b.valid and a.iterations == b.iterations
        assert np.array_equal(a.T_base_platform, b.T_base_platform)
