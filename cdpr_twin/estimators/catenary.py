"""Est. 7, ``model_catenary``: eq. 25 with the sagging cable's length–tension relation.

For robots with heavy cables: like ``model_elastic_pulley`` (encoder lengths plus
the elastic stretch of eq. 14, matched to pulley lengths of eq. 15-24), except that a cable of
weight w per metre hanging between its pulley and its anchor is longer than the chord the pulley
model measures. For a taut span the elastic catenary's arc exceeds its chord c by

    δ = w² h² c / (24 τ²)     (Irvine, *Cable Structures*, 1981, eq. 2.18, shallow span),

h the horizontal span and τ the measured tension; the target lengths are the lengths stretched
by the span's mean tension τ + w·v/2 (a sensor at B_i reads the lowest; v the span's rise;
a sensor at the exit pulley reads the highest, τ − w·v/2 then) less δ at the lower end's τ,
with h, v and c from the last estimate (they change by micrometres between ticks). The cables'
mass per metre comes from the nominal geometry (``cable_linear_density`` in the model);
without it (0 kg/m) the estimator is ``model_elastic_pulley`` exactly.
"""

from __future__ import annotations

import numpy as np

from cdpr_twin.estimators.model_based import ElasticPulleyModelEstimator


def weight_above(geom, T_base_platform: np.ndarray) -> np.ndarray:
    """w·v/2: how much the mean tension of each span exceeds the tension at B_i. (m,) [N]."""
    w = geom.linear_density * float(np.linalg.norm(geom.gravity))
    b = geom.b_platform @ T_base_platform[:3, :3].T + T_base_platform[:3, 3]
    return 0.5 * w * (geom.a_base[:, 2] - b[:, 2])


def sag_excess(geom, T_base_platform: np.ndarray, tensions: np.ndarray) -> np.ndarray:
    """Arc − chord of each cable's sagging span (shallow elastic catenary). (m,) [m].

    Args:
        geom: the nominal :class:`~cdpr_twin.math.geometry.CdprGeometry` (its linear_density).
        T_base_platform: (4, 4) platform pose.
        tensions: (m,) measured tensions [N] (non-positive ones count as no sag).
    """
    w = geom.linear_density * float(np.linalg.norm(geom.gravity))
    if w <= 0:
        return np.zeros(geom.n_cables)
    span = geom.a_base - (geom.b_platform @ T_base_platform[:3, :3].T + T_base_platform[:3, 3])
    h2 = span[:, 0] ** 2 + span[:, 1] ** 2
    c = np.linalg.norm(span, axis=1)
    tau = np.asarray(tensions, dtype=float)
    safe = np.where(tau > 0, tau, 1.0)
    return np.where(tau > 0, w * w * h2 * c / (24.0 * safe * safe), 0.0)


class CatenaryModelEstimator(ElasticPulleyModelEstimator):
    """Est. 7: pulleys, stretch and the sag of heavy cables (eq. 25 with a catenary)."""

    name = "model_catenary"

    def corrected_lengths(self, lengths: np.ndarray, tensions: np.ndarray) -> np.ndarray:
        """Encoder lengths stretched by the span's mean tension, less its sag excess (m,) [m].

        A tension sensor at B_i reads the span's lowest tension; the cable above carries its
        weight too, so the mean tension that stretches it is τ + w·v/2 (v the span's rise). A
        sensor at the exit pulley reads the highest, τ_top = τ_B + w·v (dT/dz = w along a
        hanging cable), so the mean is τ_top − w·v/2.
        """
        if not np.all(np.isfinite(self._T)):
            return super().corrected_lengths(lengths, tensions)
        taut = tensions > 0
        half = weight_above(self.geometry, self._T)
        if self.geometry.sensors_at_pulleys:
            tensions = np.where(taut, tensions - 2.0 * half, tensions)  # the tension at B_i
        mean = np.where(taut, tensions + half, tensions)
        stretched = super().corrected_lengths(lengths, mean)
        return stretched - sag_excess(self.geometry, self._T, tensions)
