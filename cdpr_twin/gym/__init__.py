"""Gymnasium environments over the twin (``pip install 'cdpr-twin[gym]'``).

>>> from cdpr_twin.gym import CdprEnv
>>> env = CdprEnv(task="reach", action="twist")       # or gymnasium.make("cdpr_twin/Reach-v0")
>>> obs, info = env.reset(seed=0)
>>> obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

Importing this package registers ``cdpr_twin/Reach-v0`` and ``cdpr_twin/ServoToTag-v0`` with
Gymnasium (keyword arguments of :class:`CdprEnv` pass through ``gymnasium.make``).
"""

try:
    import gymnasium
except ModuleNotFoundError as exc:  # the optional extra
    raise ModuleNotFoundError(
        "cdpr_twin.gym needs gymnasium; install it with: pip install 'cdpr-twin[gym]'"
    ) from exc

from cdpr_twin.gym.env import CdprEnv, pose6
from cdpr_twin.gym.tasks import ReachPose, ServoToTag, Truth

ENV_IDS = {"cdpr_twin/Reach-v0": "reach", "cdpr_twin/ServoToTag-v0": "servo"}
"""The registered environment ids and their tasks."""

for _id, _task in ENV_IDS.items():
    if _id not in gymnasium.registry:
        gymnasium.register(_id, entry_point="cdpr_twin.gym.env:CdprEnv", kwargs={"task": _task})

__all__ = ["ENV_IDS", "CdprEnv", "ReachPose", "ServoToTag", "Truth", "pose6"]
