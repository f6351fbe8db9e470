"""Self-calibration: exit and anchor points, length offsets, drum scales, camera mount.

``problem`` (the residuals: the cable lengths', with ``tag_views`` and ``wrench_balance``
holding the other kinds and their vectorised derivatives; ``parameter_layout`` places each
unknown in the parameter vector), ``jacobian`` (their sparse finite differences), ``solver``
(Levenberg–Marquardt on the normal equations, ``normal_equations`` and ``schur``; uncertainty,
rank; ``solve_weighted``: the noise re-estimated by ``variance``), ``excitation`` (which
poses), ``drive`` and ``acquire`` (recording them in the twin), ``pipeline`` (all of it for one
scenario), ``output`` (the calibrated robot description and the report).
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
