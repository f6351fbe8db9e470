"""The swivel and stiffness refresh, against MuJoCo's own sites and tendons and the cable law."""

import mujoco
import numpy as np
from conftest import paper_pose

from cdpr_twin.sim import build_robot
from cdpr_twin.sim.model import actuator_name, anchor_site, numeric, swivel_body


def test_refresh_turns_each_swivel_to_its_anchor_and_pulls_by_the_cable_law():
    physics = build_robot().physics
    m, d = physics.model, physics.data
    physics.reset(paper_pose("p1"), settle_time=0.0)  # every cable taut, at rest
    physics.disable_cable(2)  # a cut cable: no stiffness, no pull
    d.mocap_quat[:] = [1.0, 0.0, 0.0, 0.0]  # every swivel turned away from its cable
    physics.refresh()
    mujoco.mj_forward(m, d)
    entry = float(numeric(m, "cable_entry_height")[0])
    for i in range(physics.n_cables):
        # the swivel's x axis, from MuJoCo's quaternion, lies along B_i − A_i seen from above
        body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, swivel_body(i))
        x_axis = np.zeros(3)
        mujoco.mju_rotVecQuat(x_axis, np.array([1.0, 0.0, 0.0]), d.mocap_quat[m.body_mocapid[body]])
        site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, anchor_site(i))
        toward = d.site_xpos[site] - physics.geometry.a_base[i]
        toward[2] = 0.0
        # (unit quaternions of cos/sin of one angle: a few ulp)
        np.testing.assert_allclose(x_axis, toward / np.linalg.norm(toward), atol=1e-12)
        # the pull: τ = (E·S/l0)(L − l0), L MuJoCo's tendon less its entry segment (at rest)
        act = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, actuator_name(i))
        l0 = d.act[act]
        length = d.ten_length[m.actuator_trnid[act, 0]] - entry
        pull = -d.actuator_force[act]
        if i == 2:
            assert m.actuator_gainprm[act, 0] == 0.0 and pull == 0.0
        else:
            es = physics.geometry.es[i]
            assert m.actuator_gainprm[act, 0] == es / l0
            # (the bias is k·[h, −1, −η]: the force rounds a few products of ~1e5 N/m)
            np.testing.assert_allclose(pull, es / l0 * (length - l0), rtol=1e-9)
            assert pull > 0.0
