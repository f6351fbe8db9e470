"""Print the settled-at-p0 keyframe and winch gains for acrobot.xml.

MuJoCo's own viewer (``python -m mujoco.viewer --mjcf models/acrobot/scene.xml``) does not run
cdpr_twin's swivel alignment or stiffness updates, so acrobot.xml carries a keyframe ``p0``
(platform pose, rest lengths, swivel yaws) and winch gains E·S/l0 matching it: load the key and
the robot hangs still. Rerun this after changing the model's geometry and paste its output;
tests/test_model_files.py fails while the file is stale.
"""

import numpy as np

from cdpr_twin.se3 import pose_from_vector
from cdpr_twin.sim import Twin

P0 = [0.112, -0.032, 0.301, -12.0, -10.0, 0.0]


def main() -> None:
    with Twin(camera=False, tension_noise_std=0.0) as t:
        t.reset(pose_from_vector(P0), settle_time=0.5)
        d, m = t.data, t.model

        def fmt(a: np.ndarray) -> str:
            return " ".join(f"{v:.10g}" for v in np.ravel(a))

        for i, a in enumerate(t._actuators, 1):
            print(
                f'    <general name="winch{i}_actuator" class="winch" tendon="cable{i}_tendon"'
                f' gainprm="{fmt(m.actuator_gainprm[a, :1])}"'
                f' biasprm="{fmt(m.actuator_biasprm[a, :3])}"/>'
            )
        print(
            f'    <key name="p0" qpos="{fmt(d.qpos)}"\n         act="{fmt(d.act)}"\n'
            f'         mpos="{fmt(d.mocap_pos)}"\n         mquat="{fmt(d.mocap_quat)}"/>'
        )


if __name__ == "__main__":
    main()
