"""Self-calibration (issue 11): exit and anchor points, length offsets, drum scales, camera mount.

``problem`` (the residuals), ``jacobian`` (their sparse finite differences), ``solver``
(Levenberg–Marquardt on the normal equations, uncertainty, rank; ``solve_weighted``: the noise
re-estimated by ``variance``), ``excitation`` (which poses), ``acquire`` (recording them in the
twin), ``session`` (all of it for one scenario), ``output`` (the calibrated robot description
and the report).
"""

from cdpr_twin.calibrate.problem import BLOCKS, NoiseModel, Observations, Priors, Problem
from cdpr_twin.calibrate.solver import Calibration, CalibrationError, solve, solve_weighted

__all__ = [
    "BLOCKS",
    "Calibration",
    "CalibrationError",
    "NoiseModel",
    "Observations",
    "Priors",
    "Problem",
    "solve",
    "solve_weighted",
]
