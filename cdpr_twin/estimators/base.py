"""The estimators' common interface: reset at a known pose, update from a Measurement.

:meth:`Estimator.update` is a template method: it checks the reset, holds the estimate on a
measurement whose time is not finite, runs the sensor watches the class declares in
:attr:`Estimator.watches`, then calls :meth:`Estimator._step`, where each estimator does only
its own work.

An estimator sees the nominal geometry, measurements and — when it declares them in
:attr:`Estimator.inputs` — the current estimates of other estimators (a fusing estimator);
never MuJoCo, never ground truth.
"""

from __future__ import annotations

import enum
import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.math.se3 import check_rigid
from cdpr_twin.options import NoOptions
from cdpr_twin.types import Measurement, PoseEstimate

TAG_LOST = "tag_lost"
"""No tag detection in this measurement: the estimate is held."""
NO_CAMERA = "no_camera"
"""The measurement carries no image: the image-based estimate is held."""
FEW_TAUT_CABLES = "fewer_than_six_taut_cables"
"""Fewer than six cables read a tension above the taut threshold: the estimate is held."""
NON_FINITE_INPUT = "non_finite_input"
"""A length, tension or twist in the measurement is NaN or infinite: the estimate is held."""
NO_TWIST = "no_twist"
"""Time advanced but no commanded twist was recorded: the control-based estimate is held."""
NOT_CONVERGED = "not_converged"
"""The least-squares solve did not converge: the estimate is held."""
ILL_CONDITIONED = "ill_conditioned"
"""The cables available form a nearly singular set (Jacobian condition number above the
estimator's ``max_condition``): the estimate is held rather than jump."""
REANCHORED = "reanchored"
"""Image-based: no successive detection pair; the reference restarts at the held estimate."""
ENCODER_MISMATCH = "encoder_mismatch"
"""Over the last second an encoder moved ≥ 5 mm more or less than its winch was commanded to
(a stalled winch, a glitching encoder): lengths or commanded motion are not to be trusted."""

TENSION_STUCK = "tension_stuck"
"""A tension sensor has read exactly the same value for a second: a real reading carries
noise, so the sensor has failed (the model-based estimators still rank it by that value)."""


class TensionWatch:
    """Counts, per sensor, how many readings in a row were bit-identical.

    Args:
        ticks: this many identical readings in a row (25: one second at 25 Hz) flag a sensor.
    """

    def __init__(self, ticks: int = 25) -> None:
        self.ticks = ticks
        self._last: list[float] | None = None
        self._same: list[int] = []

    def check(self, tensions: np.ndarray) -> tuple[int, ...]:
        """Add one reading (m,) [N]; the sensors (from 0) stuck for ``ticks`` readings."""
        # Python floats and ints: m comparisons cost less than NumPy's calls on an m-vector
        now = tensions.tolist()
        if self._last is None:
            self._last, self._same = now, [0] * len(now)
            return ()
        if len(now) != len(self._last):
            raise ValueError(
                f"tensions: {len(now)} readings after {len(self._last)}; feed one robot's "
                "measurements (reset the estimator for another)"
            )
        pairs = zip(self._same, now, self._last, strict=True)
        self._same = same = [n + 1 if a == b else 0 for n, a, b in pairs]
        self._last = now
        if max(same) < self.ticks:
            return ()
        return tuple(i for i, n in enumerate(same) if n >= self.ticks)


class EncoderWatch:
    """Compares each encoder's motion with its winch's commanded motion over a sliding window.

    Each tick adds, per cable, ``Δl_measured − l̇_commanded·Δt``; a cable whose sum over the
    last ``window`` ticks exceeds ``threshold`` is reported. A healthy winch's velocity loop
    lags by its time constant (8 ms on ACROBOT: 0.5 mm at the paper's peak 0.067 m/s) and a
    drum radius error scales the motion by ~0.5 %: both stay far below 5 mm; a winch stalled
    for a second at 0.05 m/s, or an encoder jumping by a centimetre, do not.

    Args:
        window: ticks summed (25: one second at 25 Hz).
        threshold: the largest healthy sum [m].
    """

    def __init__(self, window: int = 25, threshold: float = 0.005) -> None:
        self.window, self.threshold = window, threshold
        self._last: tuple[float, np.ndarray] | None = None
        self._diffs: np.ndarray | None = None  # (window, m): the last ones, oldest first
        self._n = 0

    def check(self, m: Measurement) -> tuple[int, ...]:
        """Add one measurement; the cables (from 0) whose encoders disagree with the commands."""
        last, self._last = self._last, (m.time, m.cable_lengths)
        if last is None or m.command is None:
            return ()
        dt = m.time - last[0]
        diff = m.cable_lengths - last[1] - m.command.cable_rates * dt
        if self._diffs is None:
            self._diffs = np.empty((self.window, diff.size))
        if self._n < self.window:
            self._n += 1
        else:  # the oldest drops out; the rows stay in time order (the same sum, bit for bit)
            self._diffs[:-1] = self._diffs[1:]
        self._diffs[self._n - 1] = diff
        total = np.add.reduce(self._diffs[: self._n], axis=0).tolist()
        # Python floats: the m sums scanned without NumPy's calls on an m-vector
        return tuple(i for i, v in enumerate(total) if abs(v) > self.threshold)


class SensorWatch(enum.Flag):
    """The sensor watches an estimator declares in :attr:`Estimator.watches`.

    :meth:`Estimator.update` runs the declared ones on every measurement with a finite time,
    before :meth:`Estimator._step`, and passes their flags to it.
    """

    NONE = 0
    """No watch: the estimator reads neither encoders nor tensions, or judges them itself."""
    ENCODERS = enum.auto()
    """:class:`EncoderWatch`: ``ENCODER_MISMATCH`` while an encoder disagrees with its commands."""
    TENSIONS = enum.auto()
    """:class:`TensionWatch`: ``TENSION_STUCK`` while a tension sensor reads a constant."""


_WATCH_FLAGS: dict[tuple[bool, bool], frozenset[str]] = {
    (False, False): frozenset(),
    (True, False): frozenset({ENCODER_MISMATCH}),
    (False, True): frozenset({TENSION_STUCK}),
    (True, True): frozenset({ENCODER_MISMATCH, TENSION_STUCK}),
}
"""What :meth:`SensorWatches.flags` returns, by (encoder mismatch, tension stuck): built once."""


class SensorWatches:
    """An :class:`EncoderWatch` and a :class:`TensionWatch`, each fed a measurement once.

    Estimators reset together and updated with the same measurements can share one (see
    :meth:`Estimator.share_watches`): a measurement asked about again, the same object, gets
    the flags it got the first time, so each watch counts every reading once.
    """

    def __init__(self) -> None:
        self.encoders, self.tensions = EncoderWatch(), TensionWatch()
        self._encoders_seen: Measurement | None = None
        self._encoder_flags: tuple[int, ...] = ()
        self._tensions_seen: Measurement | None = None
        self._tension_flags: tuple[int, ...] = ()

    def flags(self, m: Measurement, encoders: bool, tensions: bool) -> frozenset[str]:
        """The flags the asked-for watches raise on ``m`` (each watch ingests it once)."""
        mismatch = stuck = False
        if encoders:
            if m is not self._encoders_seen:
                self._encoders_seen, self._encoder_flags = m, self.encoders.check(m)
            mismatch = bool(self._encoder_flags)
        if tensions:
            if m is not self._tensions_seen:
                self._tensions_seen, self._tension_flags = m, self.tensions.check(m.tensions)
            stuck = bool(self._tension_flags)
        return _WATCH_FLAGS[mismatch, stuck]


NO_INPUTS: Mapping[str, PoseEstimate] = MappingProxyType({})
_NO_FLAGS: frozenset[str] = frozenset()


class Estimator(ABC):
    """A moving-platform pose estimator (paper §III). All start from a known pose.

    Subclasses set ``name`` and ``Options`` (a frozen dataclass whose fields are the
    estimator's scenario options, see :mod:`cdpr_twin.plugins`), declare the sensor
    ``watches`` they want, implement :meth:`_step` and are registered with
    :func:`cdpr_twin.plugins.register`. :meth:`update` does what every estimator needs before
    its step: it refuses an estimator never reset, holds the estimate (flag
    ``non_finite_input``) on a measurement whose time is NaN or infinite, and runs the declared
    watches.

    An estimator written against the older interface, which overrides :meth:`update` whole and
    has no :meth:`_step`, still works: it does its own checks, as before. To port one, move the
    body of its ``update`` after those checks into ``_step`` and declare its ``watches``.

    Args:
        geometry: the *nominal* robot geometry the estimator believes in.
        options: an instance of the class's ``Options`` (defaults when ``None``).
    """

    kind: ClassVar[str] = "estimator"
    name: ClassVar[str] = ""
    Options: ClassVar[type] = NoOptions
    needs_camera: ClassVar[bool] = False
    """Whether it reads tag detections (dropped from the passive set when the camera is off)."""
    reports_covariance: ClassVar[bool] = False
    """Whether its estimates carry a covariance (recorded in ``timeseries.csv`` and Rerun)."""
    watches: ClassVar[SensorWatch] = SensorWatch.NONE
    """The sensor watches :meth:`update` runs before :meth:`_step` (their flags reach it)."""
    _watch_encoders: ClassVar[bool] = False
    _watch_tensions: ClassVar[bool] = False
    """``watches``' two members as booleans, set with the class (read every tick)."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Refuse a ``watches`` that is no :class:`SensorWatch`; excuse ``update()`` overriders.

        Raises:
            TypeError: ``watches`` is not a :class:`SensorWatch`.
        """
        super().__init_subclass__(**kwargs)
        if not isinstance(cls.watches, SensorWatch):
            raise TypeError(
                f"{cls.__name__}: watches must be a SensorWatch (e.g. SensorWatch.ENCODERS | "
                f"SensorWatch.TENSIONS, or SensorWatch.NONE), got {cls.watches!r}"
            )
        cls._watch_encoders = SensorWatch.ENCODERS in cls.watches
        cls._watch_tensions = SensorWatch.TENSIONS in cls.watches
        if cls.update is not Estimator.update and getattr(cls._step, "__isabstractmethod__", False):
            # Written against the older interface: its update() does the whole job, so it
            # needs no _step. Set here, before ABCMeta lists the abstract methods left.
            # (assigning the abstract method away is the point here)
            cls._step = _no_step  # type: ignore[method-assign]

    def __init__(self, geometry: CdprGeometry, options: Any = None) -> None:
        self.geometry = geometry
        self.options = self.Options() if options is None else options
        self._T = np.full((4, 4), np.nan)
        self._time = np.nan
        self._ready = False

    def reset(self, T_base_platform0: np.ndarray, time: float = 0.0) -> None:
        """Start from a known platform pose ᵇp_p0 at a given time.

        Args:
            T_base_platform0: (4, 4) initial pose.
            time: time of that pose [s].
        """
        T = check_rigid(T_base_platform0, f"{self.name}: initial pose")
        self._T = T.copy()
        self._time = float(time)
        self._ready = True
        self._watches = SensorWatches()

    def _watch_flags(self, m: Measurement, watches: SensorWatch) -> frozenset[str]:
        """What the ``watches`` see in one measurement (each watch ingests it).

        ``ENCODER_MISMATCH`` while an encoder disagrees with its commands; ``TENSION_STUCK``
        while a tension sensor reads a constant.
        """
        encoders, tensions = SensorWatch.ENCODERS in watches, SensorWatch.TENSIONS in watches
        return self._watches.flags(m, encoders, tensions)

    def share_watches(self, watches: SensorWatches) -> None:
        """Read the sensor watches through ``watches``, shared with the run's other estimators.

        Right after the estimators of a run are reset together, they would each keep watches
        fed the same measurements in the same order: one shared set, which looks at each
        measurement once, gives every one of them the same flags. A later :meth:`reset` gives
        this estimator watches of its own again.

        Args:
            watches: fresh watches (:class:`SensorWatches`), shared by estimators reset at the
                same time and updated with the same measurements.
        """
        self._watches = watches

    def _encoder_flags(self, m: Measurement, tensions: bool = False) -> frozenset[str]:
        """The encoder watch's flags (and the tension watch's, with ``tensions``).

        For estimators that override :meth:`update` whole; the others declare ``watches``.
        """
        watches = SensorWatch.ENCODERS | (SensorWatch.TENSIONS if tensions else SensorWatch.NONE)
        return self._watch_flags(m, watches)

    @property
    def inputs(self) -> tuple[str, ...]:
        """Names of the estimators whose current estimates :meth:`update` needs (none here)."""
        return ()

    @property
    def T_base_platform(self) -> np.ndarray:
        """The current estimate (4, 4)."""
        return self._T.copy()

    def _check_reset(self) -> None:
        if not self._ready:
            raise RuntimeError(f"{self.name}: call reset(T_base_platform0) before update()")

    def _bad_time(self, m: Measurement) -> PoseEstimate | None:
        """The held, flagged estimate when the measurement's time is NaN or infinite."""
        if np.isfinite(m.time):
            return None
        return PoseEstimate(self._time, self._T, valid=False, flags=frozenset({NON_FINITE_INPUT}))

    def _held(self, m: Measurement, *flags: str, **extra) -> PoseEstimate:
        """The last pose at the measurement's time, not valid, with ``flags`` and ``extra``."""
        self._time = m.time
        return PoseEstimate(m.time, self._T, valid=False, flags=frozenset(flags), **extra)

    def update(
        self, measurement: Measurement, inputs: Mapping[str, PoseEstimate] = NO_INPUTS
    ) -> PoseEstimate:
        """Update from one measurement and return the new estimate.

        Checks the reset; holds the last estimate, flagged ``non_finite_input``, when the
        measurement's time is NaN or infinite (no watch runs, :meth:`_step` is not called);
        runs the declared :attr:`watches`; then returns :meth:`_step`'s estimate.

        Args:
            measurement: the sensors' reading.
            inputs: this tick's estimates of the estimators named by :attr:`inputs`.

        Raises:
            RuntimeError: :meth:`reset` was never called.
        """
        # the checks inline, their methods called only when they fail: every tick, every
        # estimator
        if not self._ready:
            self._check_reset()
        if not math.isfinite(measurement.time):
            held = self._bad_time(measurement)
            # (None only for a finite time)
            assert held is not None
            return held
        encoders, tensions = self._watch_encoders, self._watch_tensions
        flags = _NO_FLAGS
        if encoders or tensions:
            flags = self._watches.flags(measurement, encoders, tensions)
        return self._step(measurement, inputs, flags)

    @abstractmethod
    def _step(
        self,
        measurement: Measurement,
        inputs: Mapping[str, PoseEstimate],
        watch_flags: frozenset[str],
    ) -> PoseEstimate:
        """The estimator's own update, once :meth:`update` has checked reset, time and watches.

        Args:
            measurement: the sensors' reading; its time is finite.
            inputs: this tick's estimates of the estimators named by :attr:`inputs`.
            watch_flags: the flags the declared :attr:`watches` raised on this measurement
                (empty without watches); the step decides which of its estimates carry them.

        Returns:
            The new estimate (a held one: see :meth:`_held`).
        """


def _no_step(
    self: Estimator,
    measurement: Measurement,
    inputs: Mapping[str, PoseEstimate],
    watch_flags: frozenset[str],
) -> PoseEstimate:
    """The ``_step`` of an estimator that overrides ``update`` whole: never called by it."""
    raise NotImplementedError(
        f"{type(self).__name__} overrides update() whole and has no _step(); call its update()"
    )


def update_order(
    estimators: Mapping[str, Estimator], dropped: frozenset[str] = frozenset()
) -> tuple[str, ...]:
    """Names ordered so that each estimator's inputs update before it (Kahn's algorithm).

    Args:
        estimators: the estimators by name.
        dropped: names left out of the run because the camera is off (for the message).

    Raises:
        ValueError: an input that does not run, or inputs that read each other in a cycle.
    """
    order: list[str] = []
    pending = dict(estimators)
    while pending:
        ready = [n for n, e in pending.items() if all(i in order for i in e.inputs)]
        if not ready:
            for name, e in pending.items():
                missing = [i for i in e.inputs if i not in estimators]
                if missing and dropped & set(missing):
                    raise ValueError(
                        f"{name!r} reads {missing}, dropped because the camera is off; keep "
                        "the camera on or read other estimators"
                    )
                if missing:
                    raise ValueError(
                        f"{name!r} reads {missing}, which do not run; add them to "
                        "estimators.passive"
                    )
            raise ValueError(f"{sorted(pending)} read each other in a cycle")
        order += ready
        for name in ready:
            del pending[name]
    return tuple(order)
