"""Self-calibration (issue 11): exit and anchor points, length offsets, drum scales, camera mount.

``problem`` (the residuals, numpy only), ``solver`` (scipy's sparse least squares, uncertainty,
rank), ``excitation`` (which poses), ``acquire`` (recording them in the twin), ``output`` (the
calibrated robot description and the report).
"""

from cdpr_twin.calibrate.problem import BLOCKS, NoiseModel, Observations, Priors, Problem
from cdpr_twin.calibrate.solver import Calibration, CalibrationError, solve

__all__ = [
    "BLOCKS",
    "Calibration",
    "CalibrationError",
    "NoiseModel",
    "Observations",
    "Priors",
    "Problem",
    "solve",
]
