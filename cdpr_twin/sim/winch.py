"""Winch servos and drums: how the cable rate follows its command (numpy only).

Each winch's velocity loop makes its actual cable rate r follow the commanded rate u (constant
over a control period) as a first-order system with time constant τ = 1/(2π·bandwidth), its
acceleration bounded by a slew limit a:

    ṙ = clip((u − r)/τ, −a, a).

For a constant u the solution is closed-form: while |u − r| > a·τ the rate ramps at ±a
(slew-limited), then the error decays as exp(−t/τ). :class:`WinchServos` advances that solution
over each physics chunk and returns the chunk's *exact mean rate*, which MuJoCo's integrator
actuator (ctrl = rate, act = l0) turns into the exact paid-out length at the chunk's end.

The drum: the velocity loop runs on the motor, turning the drum at the commanded cable rate
divided by the *nominal* radius; the cable paid out is the *true* radius times the drum angle
(:class:`~cdpr_twin.sim.physics.Physics` scales the loop's rate by r'/r), while the encoder
reports the nominal radius times the angle it counts (:mod:`cdpr_twin.sim.encoders`): after a
command of L it reads L, and the cable has paid out L·r'/r. Each robot's true radii are drawn
once, by :func:`draw_drum_radii`.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.optimize import brentq

from cdpr_twin.robot.realism import WinchRealism


def robot_winch(model, winch: WinchRealism | None) -> WinchRealism:
    """The winches' realism with a ``nan`` drum radius taken from the robot (its ``<numeric>``).

    A model without ``winch_drum_radius`` (a hand-written one) keeps an ideal winch at radius
    1 m: an ideal winch pays out exactly its command whatever the radius.

    Raises:
        ModelError: the model has no drum radius and the winch needs one (encoder counts or a
            drum radius error).
    """
    from cdpr_twin.sim.model import ModelError, robot_sensing

    winch = WinchRealism() if winch is None else winch
    if not math.isnan(winch.drum_radius):
        return winch
    robot = robot_sensing(model)
    if robot is not None:
        return replace(winch, drum_radius=robot.drum_radius)
    if winch.encoder_counts == 0 and winch.drum_radius_error_std == 0.0:
        return replace(winch, drum_radius=1.0)
    raise ModelError("the model has no <numeric name='winch_drum_radius'>; set drum_radius_m")


def draw_drum_radii(winch: WinchRealism, rng: np.random.Generator, n: int) -> np.ndarray:
    """One robot's true drum radii, r·(1 + N(0, σ)) per winch.

    Args:
        winch: the nominal radius r [m] and the relative std σ.
        rng: the robot's winch generator (:func:`cdpr_twin.robot.realism.robot_rng`).
        n: number of winches.

    Returns:
        (n,) true drum radii [m].
    """
    return winch.drum_radius * (1.0 + rng.normal(0.0, winch.drum_radius_error_std, n))


def time_constant(bandwidth_hz: float) -> float:
    """The velocity loop's time constant τ = 1/(2π f) [s] (0 for an infinite bandwidth)."""
    return 0.0 if math.isinf(bandwidth_hz) else 1.0 / (2.0 * math.pi * bandwidth_hz)


def loop_response(
    r0: np.ndarray, u: np.ndarray, h: float, tau: float, accel: float
) -> tuple[np.ndarray, np.ndarray]:
    """The velocity loop's exact response to a constant command over h seconds.

    Args:
        r0: (m,) rates at the start [m/s].
        u: (m,) commanded rates [m/s].
        h: duration [s].
        tau: time constant [s] (0: no first-order lag).
        accel: acceleration limit [m/s²] (``inf``: none); τ = 0 needs a finite one.

    Returns:
        (rates at h [m/s], lengths paid out over [0, h] [m]), each (m,).
    """
    err = u - r0
    if tau > 0.0 and (math.isinf(accel) or np.abs(err).max() <= accel * tau):
        # no slew phase (the usual case after the first chunks): one exponential, scalar decay
        grow = -math.expm1(-h / tau)  # 1 − e^(−h/τ)
        return r0 + err * grow, u * h - err * (tau * grow)
    sign = np.sign(err)
    if math.isinf(accel):
        t1, slope = np.zeros_like(err), np.zeros_like(err)
    else:  # slew phase: |u − r| > a·τ, the rate ramps at ±a
        with np.errstate(over="ignore"):  # a tiny a (5e-324): ramps past h, inf, are held to h
            t1 = np.minimum(np.maximum(np.abs(err) - accel * tau, 0.0) / accel, h)
        slope = sign * accel
    r1 = r0 + slope * t1
    paid = (r0 + 0.5 * slope * t1) * t1
    t2 = h - t1
    if tau > 0.0:  # then the error decays exponentially
        decay = np.exp(-t2 / tau)
        err2 = u - r1
        return u - err2 * decay, paid + u * t2 + err2 * tau * np.expm1(-t2 / tau)
    return np.where(t2 > 0.0, u, r1), paid + u * t2


def friction_response(
    r0: np.ndarray, u: np.ndarray, h: float, tau: float, accel: float, lag: float
) -> tuple[np.ndarray, np.ndarray]:
    """The velocity loop's response over h seconds with Coulomb friction on the motor.

    A proportional velocity loop of time constant τ against a friction torque T_c:
    ṙ = clip((u − r)/τ, ±a) − (f/τ)·sign(r), f = T_c/K_v the rate lag (``lag``). While the rate
    keeps its sign this is the loop of :func:`loop_response` aimed at
    u − f·sign(r); a resting motor sticks while |u| ≤ f (the loop's torque does not break it
    loose); a rate that reaches 0 stops there and starts again the same way.

    Args:
        r0: (m,) rates at the start [m/s].
        u: (m,) commanded rates [m/s].
        h: duration [s].
        tau: time constant [s] (> 0).
        accel: acceleration limit [m/s²] (``inf``: none).
        lag: the friction's rate lag f [m/s].

    Returns:
        (rates at h [m/s], lengths paid out over [0, h] [m]), each (m,).
    """
    rate, paid = np.empty_like(r0), np.zeros_like(r0)
    for i in range(r0.size):
        r, left = float(r0[i]), h
        while True:
            if r != 0.0:
                s = math.copysign(1.0, r)
            elif abs(u[i]) > lag:  # the loop's torque breaks the motor loose
                s = math.copysign(1.0, u[i])
            else:  # at rest, stuck
                break
            target = np.array([u[i] - lag * s])
            end, length = loop_response(np.array([r]), target, left, tau, accel)
            if end[0] * s >= 0.0:  # kept its sign to the end
                r, paid[i] = float(end[0]), paid[i] + float(length[0])
                break
            # it reaches 0 inside: stop there, then go on from rest

            def rate_at(t, r=r, target=target):
                return float(loop_response(np.array([r]), target, t, tau, accel)[0][0])

            t0 = brentq(rate_at, 0.0, left, xtol=1e-12)
            paid[i] += float(loop_response(np.array([r]), target, t0, tau, accel)[1][0])
            r, left = 0.0, left - t0
            if left <= 0.0:
                break
        rate[i] = r
    return rate, paid


class WinchServos:
    """The velocity loops of a robot's winches: their actual rates, persistent across ticks.

    Ideal winches (infinite bandwidth and acceleration) have no loop: their rate is the
    command, which the physics applies directly (bit for bit as before servo models).

    Args:
        winch: bandwidth and acceleration limit.
        n: number of winches.
        friction_rate: the motors' Coulomb friction as a rate lag [m/s]
            (:func:`friction_response`; 0: none).

    Attributes:
        ideal: whether the winches follow commands instantly.
        tau: time constant [s].
        accel: acceleration limit [m/s²].
        rate: (n,) actual cable rates now [m/s].
        command: (n,) commanded rates [m/s], constant until the next command.
    """

    def __init__(self, winch: WinchRealism, n: int, friction_rate: float = 0.0) -> None:
        self.ideal = math.isinf(winch.bandwidth_hz) and math.isinf(winch.max_accel)
        self.tau, self.accel = time_constant(winch.bandwidth_hz), float(winch.max_accel)
        self.rate, self.command = np.zeros(n), np.zeros(n)
        self.friction_rate = float(friction_rate)

    def _response(self, rates: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        if self.friction_rate > 0.0:
            return friction_response(self.rate, rates, h, self.tau, self.accel, self.friction_rate)
        return loop_response(self.rate, rates, h, self.tau, self.accel)

    def reset(self) -> None:
        """Winches at rest, no command."""
        self.rate = np.zeros_like(self.rate)
        self.command = np.zeros_like(self.command)

    def set_command(self, rates: np.ndarray) -> None:
        """Command rates (m,) [m/s] (ideal winches run at them at once)."""
        self.command = rates
        if self.ideal:
            self.rate = rates

    def paid_out(self, rates: np.ndarray, steps: int, dt: float) -> np.ndarray:
        """Length each winch would pay out under a command (m,) [m].

        Args:
            rates: (m,) commanded rates [m/s].
            steps: for how many physics steps.
            dt: physics step [s].
        """
        if self.ideal:
            return rates * steps * dt
        return self._response(rates, steps * dt)[1]

    def run(self, duration: float) -> np.ndarray:
        """Advance the loops by ``duration`` s under the current command (not for ideal ones).

        Returns:
            (n,) the mean rate over that time [m/s]: an integrator fed it for ``duration``
            ends at the exact paid-out length.
        """
        self.rate, paid = self._response(self.command, duration)
        return paid / duration


class WinchLimitError(ValueError):
    """A command beyond the winches' limits: a rate out of range, or a length run past its end."""


def checked_rates(rates: np.ndarray, n: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Commanded winch rates as a float array, checked for shape, finiteness and range.

    Args:
        rates: the commanded rates [m/s].
        n: number of winches.
        lo: (n,) lowest rates [m/s].
        hi: (n,) highest rates [m/s].

    Raises:
        ValueError: for a wrong shape, a NaN or inf; :class:`WinchLimitError` for a rate out of
            range.
    """
    rates = np.array(rates, dtype=float)
    if rates.shape != (n,):
        raise ValueError(f"cable_rates must have shape ({n},), got {rates.shape}")
    if not math.isfinite(np.add.reduce(rates)):
        raise ValueError(
            f"cable_rates must be finite, got {rates.tolist()} (NaN or inf from the controller?)"
        )
    if np.logical_or.reduce((rates < lo) | (rates > hi)):
        out = [f"{r:.3g}" for r in rates]  # (significant digits: a tiny range stays legible)
        raise WinchLimitError(
            f"cable rates [{', '.join(out)}] m/s exceed the winches' range "
            f"[{lo.min():.3g}, {hi.max():.3g}] m/s"
        )
    return rates


def check_lengths(l0_end: np.ndarray, act_range: np.ndarray) -> None:
    """Check the winch lengths a command would reach against the winches' range.

    Args:
        l0_end: (n,) lengths at the end of the command [m].
        act_range: (n, 2) lowest and highest lengths [m].

    Raises:
        WinchLimitError: when a length leaves the range.
    """
    if np.logical_or.reduce((l0_end < act_range[:, 0]) | (l0_end > act_range[:, 1])):
        raise WinchLimitError(
            f"these rates would run winch lengths to {np.round(l0_end, 4)} m, "
            f"outside the winch range {act_range[0].tolist()} m"
        )


def whole_steps(duration: float, timestep: float) -> int:
    """The whole number of physics steps of ``timestep`` [s] in ``duration`` [s].

    Raises:
        ValueError: when ``duration`` is negative, not finite, or not a whole number of steps.
    """
    if not (math.isfinite(duration) and duration >= 0):
        raise ValueError(f"duration must be a finite number of seconds ≥ 0, got {duration}")
    n = round(duration / timestep)
    if not math.isclose(n * timestep, duration, rel_tol=1e-9, abs_tol=1e-12):
        raise ValueError(
            f"duration {duration} s is not a whole number of physics steps of {timestep} s"
        )
    return n
