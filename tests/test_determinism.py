"""Same seed ⇒ bit-identical measurements; noise has the configured statistics."""

import numpy as np
from conftest import paper_pose

from cdpr_twin.math import kinematics as kin
from cdpr_twin.sim import DeviationSpec, Twin


def _run(noise_seed: int, camera: bool):
    spec = DeviationSpec(exit_point_std=0.003, es_scale_std=0.05, seed=3)
    out = []
    with Twin(deviations=spec, noise_seed=noise_seed, camera=camera) as t:
        T = paper_pose("p0")
        t.reset(T)
        rates = kin.jacobian(t.nominal_geometry, T, "base", "pulley") @ [0.01, 0, -0.01, 0, 0, 0]
        for _ in range(3):
            t.advance(0.04, rates)
            out.append((t.sense(), t.T_base_platform))
    return out


def _same(a, b) -> bool:
    (a, truth_a), (b, truth_b) = a, b
    fields = ("time", "cable_lengths", "tensions", "image")
    same = np.array_equal(truth_a, truth_b)
    same = same and all(np.array_equal(getattr(a, f), getattr(b, f)) for f in fields)
    if a.tag is None or b.tag is None:
        return same and a.tag is b.tag
    return (
        same
        and np.array_equal(a.tag.T_cam_tag, b.tag.T_cam_tag)
        and np.array_equal(a.tag.corners, b.tag.corners)
    )


def test_same_seed_bit_identical_measurements():
    a, b = _run(11, camera=True), _run(11, camera=True)
    assert all(_same(x, y) for x, y in zip(a, b, strict=True))
    assert a[-1][0].tag is not None


def test_other_noise_seed_other_tensions_same_motion():
    a, b = _run(11, camera=False), _run(12, camera=False)
    assert not np.array_equal(a[-1][0].tensions, b[-1][0].tensions)
    np.testing.assert_array_equal(a[-1][1], b[-1][1])


def test_tension_noise_statistics():
    with Twin(camera=False, tension_noise_std=0.24, noise_seed=1) as t:
        t.reset(paper_pose("p1"))
        errs = np.array([t.sense().tensions - t.tensions for _ in range(2000)]).ravel()
    assert abs(errs.mean()) < 0.02
    assert abs(errs.std() - 0.24) < 0.01
