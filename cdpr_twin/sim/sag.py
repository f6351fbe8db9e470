"""Cables with mass: each free span's force on the platform follows Irvine's elastic catenary.

MuJoCo's tendons are massless and straight. :class:`SaggingPhysics` keeps them (they carry the
elastic law, its damping and the implicit integration) and adds, at every refresh of the swivels
and stiffnesses (every ``align_every`` steps), the difference between the sagging and the
straight cable's force on the platform as an applied force at each anchor point B_i. The span
is MuJoCo's last tendon segment, from the sheave's tangent point to B_i, and its unstretched
length the cable's l0 in proportion of that segment in the tendon path (stretch uniform along
the cable). The catenary (:mod:`cdpr_twin.math.catenary`) is solved for that unstretched length and
span; the platform then also carries its share of the cable's weight. The span's upper end pulls
on the sheave with the catenary's upper-end force (:attr:`SaggingPhysics.pulley_force`): its
tension exceeds the one at B_i by about the weight of the cable's rise, w·Δz. The tension
sensors read B_i's tension, or the pulley's on a robot whose sensors sit at the exit pulleys
(``<numeric name="tension_sensor_at_pulley">``, robot.toml ``[tension_sensors] location``).

The swivels need no change: their axes are vertical, and a catenary hangs in the vertical plane
through its chord, so the upper-end tangent has the chord's azimuth, which the swivels already
follow (:meth:`Physics.refresh`). What sag does change at the sheave is the wrap angle (the
tangent dips below the chord by ≈ w·h/(2H) rad); the tendon's wrap keeps the chord's, a length
error of r·Δθ (≈ 3 mm on CoGiRo at 100 N, 0.3 mm at 1 kN), left in the MuJoCo path.
"""

from __future__ import annotations

import mujoco
import numpy as np

from cdpr_twin.math.catenary import CatenaryError, end_forces, hangs_vertically, solve_catenary
from cdpr_twin.sim.physics import Physics


class SaggingPhysics(Physics):
    """:class:`Physics` with heavy cables (Irvine's elastic catenary on every free span).

    Args:
        model: as :class:`Physics`.
        linear_density: the cables' mass per unstretched metre [kg/m].
        **kwargs: as :class:`Physics`.
    """

    def __init__(self, model: mujoco.MjModel, *args, linear_density: float, **kwargs) -> None:
        super().__init__(model, *args, **kwargs)
        if not linear_density > 0:
            raise ValueError(f"linear_density must be > 0 kg/m, got {linear_density}")
        self.linear_density = float(linear_density)
        g = model.opt.gravity
        if not hangs_vertically(g):
            raise ValueError(
                f"cables with mass need gravity along -z (the catenary hangs vertically), got "
                f"{g.tolist()} m/s²; set sag = false or point gravity down"
            )
        self.weight = self.linear_density * float(-g[2])  # w = ρ|g| [N/m] (0: no sag)
        self.sag_force = np.zeros((self.n_cables, 3))  # the catenary − straight force on B_i [N]
        self.pulley_force = np.zeros((self.n_cables, 3))  # catenary − straight force on the sheave
        self.sensor_at_pulley = (
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, "tension_sensor_at_pulley") >= 0
        )
        self._unit = np.zeros((self.n_cables, 3))  # B_i → tangent point, at the last refresh

    @property
    def tensions(self) -> np.ndarray:
        """True tensions at B_i (m,) [N]: the sagging span's, |τ_straight û + Δ|.

        MuJoCo's tendon carries the straight elastic tension τ_straight (current); the span's
        catenary differs by the force Δ of the last refresh. A tension sensor at B_i reads this.
        """
        straight = super().tensions
        pulled = straight[:, None] * self._unit + self.sag_force
        return np.where(self._hangs(straight), np.linalg.norm(pulled, axis=1), straight)

    @property
    def pulley_tensions(self) -> np.ndarray:
        """True tensions where the cables leave their sheaves (m,) [N]: |−τ_straight û + Δ_top|.

        The catenary's upper-end tension (the winch side), the current straight tension
        corrected by the upper-end force difference of the last refresh.
        """
        straight = super().tensions
        pulled = -straight[:, None] * self._unit + self.pulley_force
        return np.where(self._hangs(straight), np.linalg.norm(pulled, axis=1), straight)

    def _hangs(self, straight: np.ndarray) -> np.ndarray:
        """(m,) whether each cable pulls: taut in MuJoCo, or hanging beyond its chord.

        A heavy cable longer than its chord still holds the catenary's tension: it has no
        slack boundary.
        """
        return (straight > 0) | np.any(self.sag_force != 0.0, axis=1)

    @property
    def sensed_tensions(self) -> np.ndarray:
        """What the tension sensors measure (m,) [N]: at the pulleys or at B_i (robot data)."""
        return self.pulley_tensions if self.sensor_at_pulley else self.tensions

    def refresh(self) -> None:
        """Swivels and stiffnesses (:meth:`Physics.refresh`), then the sagging spans' forces."""
        super().refresh()
        d, m = self.data, self.model
        if not self.was_reset and not np.any(d.act):
            return  # no cable paid out yet
        mujoco.mj_tendon(m, d)  # the paths at the last step's positions (place(): the new ones)
        b = d.site_xpos[self._anchors]
        total = np.zeros(3)
        torque = np.zeros(3)
        com = d.xipos[self._platform]
        l0 = d.act[self._actuators]
        self.pulley_force[:] = 0.0
        for i in range(self.n_cables):
            force = self._span_force(i, b[i], l0[i]) if self.cable_enabled[i] else np.zeros(3)
            self.sag_force[i] = force
            total += force
            torque += np.cross(b[i] - com, force)
        d.xfrc_applied[self._platform] = np.concatenate([total, torque])

    def _span_force(self, i: int, b: np.ndarray, l0: float) -> np.ndarray:
        """Catenary − straight elastic force of cable i's free span on B_i [N] (3,).

        Also sets ``pulley_force[i]``, the same difference on the sheave's tangent point.
        """
        d = self.data
        tendon = self._tendons[i]
        points = d.wrap_xpos.reshape(-1, 3)  # the tendon paths' points, B_i last
        start = points[d.ten_wrapadr[tendon] + d.ten_wrapnum[tendon] - 2]  # tangent point
        span = start - b
        chord = float(np.linalg.norm(span))
        total = float(d.ten_length[tendon]) - self._entry
        if total <= 0 or l0 <= 0:
            return np.zeros(3)
        ls = l0 * chord / total  # unstretched length of the free span
        es = self._es[i]
        self._unit[i] = span / chord
        if self.weight == 0.0:
            return np.zeros(3)
        # longer than its chord, MuJoCo's straight cable pulls nothing, a hanging one still does
        # (its tension continuous across the chord's length): only the straight part goes
        straight = es * max(chord - ls, 0.0) / ls * span / chord
        try:
            cat = solve_catenary(ls, es, self.weight, np.hypot(*span[:2]), span[2])
        except CatenaryError:  # no hanging shape found (a vertical span, or far too long)
            return np.zeros(3)
        on_b, on_a = end_forces(cat, start, b)
        self.pulley_force[i] = on_a + straight
        return on_b - straight
