"""Tension sensors at the anchor points B_i.

Sensor i reads ``(1 + g_i)·τ_i + b_i + n``: a gain error g_i and an offset b_i that belong to
the sensor (drawn once per robot, from the truth seed: the datasheet's *accuracy*, a systematic
error), plus white noise n of ``noise_std`` drawn at every reading from the run's generator (the
datasheet's *repeatability*); with ``clip`` the reading saturates at the sensor's range, and
the measurement says which readings did (see :class:`~cdpr_twin.robot.realism.TensionRealism`).

Ideal (``TensionRealism()``): the true tension plus Gaussian noise of ``noise_std`` per reading,
drawn from the run's generator (the twin's behaviour before realism, bit for bit).
"""

from __future__ import annotations

import math

import numpy as np

from cdpr_twin.robot.realism import TensionRealism


class TensionSensors:
    """The tension sensors of one robot.

    The per-robot errors are drawn at construction, in this order: the m offsets b, uniform on
    ±√3·``bias_std`` [N] (a datasheet's accuracy ±a is a bound: rectangular, std a/√3), then
    the m gain errors g ~ N(0, ``gain_error_std``²). Each reading
    draws ``normal(0, noise_std, m)`` once from the run's generator (nothing when
    ``noise_std`` is 0), as the twin did before realism.

    Args:
        n_cables: cable count m.
        noise_std: per-reading noise std [N] (``[sensors] tension_noise_std``).
        realism: bias, gain and range of the sensors.
        run_rng: the run's generator of reading noise.
        robot_rng: the per-robot generator (bias and gain errors).

    Attributes:
        bias: (m,) each sensor's offset b_i [N].
        gain_error: (m,) each sensor's relative gain error g_i.
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
        half = math.sqrt(3.0) * realism.bias_std  # rectangular ±a with std a/√3 (GUM 4.3.7)
        self.bias = robot_rng.uniform(-half, half, n_cables)
        self.gain_error = robot_rng.normal(0.0, realism.gain_error_std, n_cables)
        self._calibration_error = realism.bias_std > 0 or realism.gain_error_std > 0
        self._failed = np.zeros(n_cables, dtype=bool)
        self._any_failed = False  # (a bool: each reading asks)
        self._stuck = np.zeros(n_cables)  # what a failed sensor reads [N]
        self._last = np.full(n_cables, np.nan)

    def fail(self, i: int, value: float = math.nan) -> None:
        """Sensor i (from 0) fails: it reads ``value`` [N] from now on (NaN: its last reading)."""
        self._failed[i] = self._any_failed = True
        self._stuck[i] = self._last[i] if math.isnan(value) else value

    def read(self, true_tensions: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The sensors' readings of the true tensions.

        Args:
            true_tensions: (m,) true cable tensions at B_i [N].

        Returns:
            The readings (m,) [N], and (m,) bool: which readings sit at a limit of the range
            (the true value may lie beyond it); ``None`` when the sensors do not clip.
        """
        tensions = true_tensions
        if self._calibration_error:
            tensions = (1.0 + self.gain_error) * tensions + self.bias
        if self.noise_std > 0:
            tensions = tensions + self._rng.normal(0.0, self.noise_std, self.n_cables)
        clipped = None
        if self.realism.clip:
            lo, hi = self.realism.range_min, self.realism.range_max
            clipped = (tensions <= lo) | (tensions >= hi)
            tensions = np.clip(tensions, lo, hi)
        if self._any_failed:  # (a copy: the caller's array is never written)
            tensions = np.where(self._failed, self._stuck, tensions)
        self._last = tensions
        return tensions, clipped
