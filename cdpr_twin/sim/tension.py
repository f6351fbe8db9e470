"""Tension sensors at the anchor points B_i.

Ideal (``TensionRealism()``): the true tension plus Gaussian noise of ``noise_std`` per reading,
drawn from the run's generator (the twin's behaviour before realism, bit for bit).
"""

from __future__ import annotations

import numpy as np

from cdpr_twin.realism import TensionRealism


class TensionSensors:
    """The tension sensors of one robot.

    Args:
        n_cables: cable count m.
        noise_std: per-reading noise std [N] (``[sensors] tension_noise_std``).
        realism: bias, gain and range of the sensors.
        run_rng: the run's generator of reading noise.
        robot_rng: the per-robot generator (bias and gain errors).
    """

    def __init__(
        self,
        n_cables: int,
        noise_std: float,
        realism: TensionRealism,
        run_rng: np.random.Generator,
        robot_rng: np.random.Generator,
    ) -> None:
        if not (np.isfinite(noise_std) and noise_std >= 0):
            raise ValueError(f"tension_noise_std must be ≥ 0 N, got {noise_std}")
        self.n_cables, self.noise_std, self.realism = n_cables, float(noise_std), realism
        self._rng = run_rng

    def read(self, true_tensions: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Readings (m,) [N], and which of them clipped at the range (``None``: no clipping)."""
        tensions = true_tensions
        if self.noise_std > 0:
            tensions = tensions + self._rng.normal(0.0, self.noise_std, self.n_cables)
        return tensions, None
