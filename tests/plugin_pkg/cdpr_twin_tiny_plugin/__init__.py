"""A tiny cdpr-twin plugin package: one estimator, exposed by entry point only.

``StartPoseEstimator`` believes the platform never leaves its start pose: its deviation from
ground truth is the platform's displacement. It is not decorated with ``register``; the entry
point ``start_pose`` in ``pyproject.toml`` is its registration. The second entry point names a
class that does not exist (a broken plugin the twin must skip and explain).
"""

from cdpr_twin.estimators.base import NO_INPUTS, Estimator
from cdpr_twin.types import PoseEstimate


class StartPoseEstimator(Estimator):
    """The start pose, at every tick."""

    name = "start_pose"

    def update(self, measurement, inputs=NO_INPUTS):
        self._check_reset()
        return PoseEstimate(measurement.time, self._T)
