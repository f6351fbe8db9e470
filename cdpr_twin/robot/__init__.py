"""Robot descriptions, their calibration errors and how imperfect the simulated robot is.

No MuJoCo: the simulation layer (:mod:`cdpr_twin.sim`) builds its model from these values.
"""
