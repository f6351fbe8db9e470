"""The MJCF files themselves: numbers from their sources, and the viewer keyframe."""

import mujoco
import numpy as np
from conftest import A_BASE, B_PLATFORM, paper_pose

from cdpr_twin import DEFAULT_SCENE
from cdpr_twin.math import se3
from cdpr_twin.sim import build_model, read_geometry


def test_model_numbers_match_their_sources():
    model = build_model(DEFAULT_SCENE)
    g = read_geometry(model)
    np.testing.assert_array_equal(g.a_base, A_BASE)
    np.testing.assert_array_equal(g.b_platform, B_PLATFORM)
    np.testing.assert_allclose(g.es, 111e9 * np.pi * 0.001**2, rtol=1e-6)
    np.testing.assert_array_equal(g.pulley_radius, 0.0045)
    assert g.mass == 3.5
    box = model.geom_size[model.geom("platform_box").id]
    np.testing.assert_allclose(2 * box, [0.18, 0.17, 0.07])
    assert model.opt.timestep == 0.0005
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    cam = model.camera("platform_cam")
    assert float(cam.fovy[0]) == 60.0
    assert tuple(model.cam_resolution[cam.id]) == (640, 480)


def test_viewer_keyframe_hangs_still_in_plain_mujoco():
    """MuJoCo's viewer runs no cdpr_twin code: the p0 key and the file's winch gains must be a
    static equilibrium by themselves (`cdpr-twin model build` settles and writes them)."""
    model = mujoco.MjModel.from_xml_path(str(DEFAULT_SCENE))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("p0").id)
    mujoco.mj_step(model, data, nstep=2000)  # 1 s
    q = data.qpos[:7]
    T = se3.transform(se3.matrix_from_quat_wxyz(q[3:]), q[:3])
    dt, dr = se3.pose_distance(T, paper_pose("p0"))
    assert dt < 1e-4 and np.rad2deg(dr) < 0.01
    assert np.all(-data.actuator_force > 1.0)
    assert all(w.number == 0 for w in data.warning)
