"""Truth deviations: seeded, applied to the twin only, never to the nominal geometry."""

import numpy as np
from conftest import paper_pose

from cdpr_twin import DEFAULT_SCENE
from cdpr_twin.math import se3
from cdpr_twin.sim import DeviationSpec, Twin, build_model, read_geometry

SPEC = DeviationSpec(
    exit_point_std=0.005,
    anchor_point_std=0.002,
    es_scale_std=0.1,
    pulley_radius_std=0.0005,
    camera_position_std=0.002,
    camera_rotation_std=0.01,
    tag_position_std=0.003,
    tag_rotation_std=0.01,
    seed=42,
)


def _model_arrays(model):
    return [
        np.array(a)
        for a in (
            model.body_pos,
            model.body_quat,
            model.site_pos,
            model.geom_size,
            model.geom_pos,
            model.numeric_data,
            model.cam_pos,
            model.cam_quat,
        )
    ]


def test_same_seed_same_model_other_seed_other_model():
    a = _model_arrays(build_model(DEFAULT_SCENE, SPEC.draw(8)))
    b = _model_arrays(build_model(DEFAULT_SCENE, SPEC.draw(8)))
    c = _model_arrays(
        build_model(DEFAULT_SCENE, DeviationSpec(**{**vars(SPEC), "seed": 43}).draw(8))
    )
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not all(np.array_equal(x, y) for x, y in zip(a, c, strict=True))


def test_deviations_change_the_twin_only():
    nominal = read_geometry(build_model(DEFAULT_SCENE))
    with Twin(deviations=SPEC, camera=False, tension_noise_std=0.0) as t:
        dev = t.deviations
        for field in ("a_base", "b_platform", "pulley_radius", "es", "T_platform_cam"):
            np.testing.assert_array_equal(
                getattr(t.nominal_geometry, field), getattr(nominal, field)
            )
        g = t.true_geometry
        np.testing.assert_allclose(g.a_base - nominal.a_base, dev.exit_offsets, atol=1e-15)
        np.testing.assert_allclose(
            g.b_platform - nominal.b_platform, dev.anchor_offsets, atol=1e-15
        )
        np.testing.assert_allclose(g.es / nominal.es, dev.es_scale, rtol=1e-12)
        np.testing.assert_allclose(
            g.pulley_radius - nominal.pulley_radius, dev.pulley_radius_offsets, atol=1e-15
        )
        dt, dr = se3.pose_distance(g.T_platform_cam, nominal.T_platform_cam)
        assert np.isclose(dt, np.linalg.norm(dev.camera_offset[:3]))
        assert np.isclose(dr, np.linalg.norm(dev.camera_offset[3:]))
        # the deviated robot is still physically consistent: it settles where it is reset
        t.reset(paper_pose("p1"))
        assert t.settle_error[0] < 1e-6
        # and its true cable lengths differ from what the nominal model predicts
        from cdpr_twin.math.kinematics import cable_lengths

        nominal_l = cable_lengths(t.nominal_geometry, paper_pose("p1"), "pulley")
        assert np.max(np.abs(nominal_l - t.cable_lengths)) > 1e-3


def test_mounting_errors_are_applied_in_the_frames_they_are_stated_in():
    """camera_offset is [δp, δθ] in F_p, tag_offset in F_b: a concrete value, not only its norm."""
    from cdpr_twin.robot.deviations import TruthDeviations

    dev = TruthDeviations.zero(8)
    dev = TruthDeviations(
        dev.exit_offsets,
        dev.anchor_offsets,
        dev.es_scale,
        dev.pulley_radius_offsets,
        camera_offset=np.array([0.001, -0.002, 0.0005, 0.01, -0.02, 0.03]),
        tag_offset=np.array([0.002, 0.001, 0.0, -0.01, 0.02, 0.005]),
    )
    nominal = read_geometry(build_model(DEFAULT_SCENE))
    with Twin(deviations=dev, camera=False) as t:
        T_pc = t.true_geometry.T_platform_cam
        np.testing.assert_allclose(
            T_pc[:3, 3] - nominal.T_platform_cam[:3, 3], dev.camera_offset[:3], atol=1e-15
        )
        np.testing.assert_allclose(
            T_pc[:3, :3],
            se3.so3_exp(dev.camera_offset[3:]) @ nominal.T_platform_cam[:3, :3],
            atol=1e-12,
        )
        T_bt = t.physics.T_base_tag
        np.testing.assert_allclose(
            T_bt[:3, 3] - t.nominal.T_base_tag[:3, 3], dev.tag_offset[:3], atol=1e-12
        )
        np.testing.assert_allclose(
            T_bt[:3, :3], se3.so3_exp(dev.tag_offset[3:]) @ t.nominal.T_base_tag[:3, :3], atol=1e-12
        )


def test_zero_spec_is_the_nominal_robot():
    with Twin(deviations=DeviationSpec(seed=5), camera=False) as t:
        for field in ("a_base", "b_platform", "pulley_radius", "es"):
            np.testing.assert_array_equal(
                getattr(t.nominal_geometry, field), getattr(t.true_geometry, field)
            )
