"""Timed scenario events (faults) acting on the simulated robot through the physics hooks.

A scenario lists events in ``[[events]]`` tables::

    [[events]]
    kind = "cable_break"     # one of EVENT_KINDS
    at = 1.0                 # [s]
    cable = 3                # 1-based, as on the robot

- ``cable_break`` (``cable``): the cable's force is zero for good;
- ``winch_stall`` (``cable``, ``until``): the winch stops turning whatever it is commanded;
- ``encoder_glitch`` (``cable``, ``jump``): the encoder's reading jumps and stays off by it;
- ``tag_occlusion`` (``until``, ``coverage``): a sheet hides part of the tag in the rendered
  image (:mod:`cdpr_twin.sim.occluder`);
- ``tension_sensor_fail`` (``cable``, ``value``): the sensor reads a constant for good.

Each kind is a frozen dataclass (its fields are its schema, parsed like plugin options) with
``apply(physics, sensors)`` and, for one that lasts, ``end(physics, sensors)``. An
:class:`EventSchedule` is a :class:`StepHook`: the physics stops stepping at each event's start
and end and fires it between two steps; the runner also fires what is due before each tick.
Events never read MuJoCo directly: they act through the physics' and sensors' public methods
(``disable_cable``…), so the swivel/stiffness refresh respects them.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

from cdpr_twin.options import OptionError, option
from cdpr_twin.robot.realism import MAX_TENSION_READING


class StepHook(Protocol):
    """Something that acts on the physics between steps, at times of its choosing."""

    def next_time(self) -> float:
        """Simulation time [s] of the next action (``inf`` when there is none)."""
        ...

    def fire(self, time: float) -> None:
        """Act now: everything due at or before ``time`` [s]."""
        ...


def fire_due(hooks: list[StepHook], time: float, dt: float, chunk: int) -> int:
    """Fire the hooks due at ``time`` [s]; returns ``chunk`` shortened to the next hook time.

    Args:
        hooks: the physics' hooks.
        time: simulation time now [s].
        dt: the physics step [s].
        chunk: how many steps the physics means to take next.
    """
    for hook in hooks:
        next_time = hook.next_time()
        if next_time <= time + 0.5 * dt:
            hook.fire(time + 0.5 * dt)
            next_time = hook.next_time()
        ahead = (next_time - time) / dt - 0.5  # (inf, never due, for a time past 1e308 steps)
        if 0 < ahead <= chunk - 1:  # its step, rounded up, is due before the chunk ends
            chunk = math.ceil(ahead)
    return chunk


@dataclass(frozen=True)
class Event:
    """Base of timed events.

    Attributes:
        at: when it happens [s].
    """

    kind: ClassVar[str] = ""
    at: float = option(minimum=0.0, unit="s")

    def __post_init__(self) -> None:
        if not (math.isfinite(self.at) and self.at >= 0):
            raise OptionError("at", f"must be a finite time ≥ 0 s, got {self.at}")

    @property
    def end_time(self) -> float:
        """When it ends [s] (``inf``: never)."""
        return math.inf

    def check(self, n_cables: int) -> None:
        """Check the event against the robot before the run starts.

        Raises:
            OptionError: naming the field at fault.
        """

    def apply(self, physics: Any, sensors: Any) -> None:
        """Act on the simulated robot."""
        raise NotImplementedError

    def end(self, physics: Any, sensors: Any) -> None:
        """Undo :meth:`apply` at :attr:`end_time`."""

    def fields(self) -> dict[str, float | None]:
        """The event's fields but ``at`` (what it does); NaN and ``inf`` (never) as ``None``."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "at"}
        return {k: (v if math.isfinite(v) else None) for k, v in out.items()}

    def describe(self, phase: str = "start") -> str:
        """In words, for the timeseries and the recording (``cable_break cable 3``)."""
        words = [self.kind if phase == "start" else f"{self.kind} ends"]
        words += [f"{k} {v:g}" for k, v in self.fields().items() if v is not None]
        return " ".join(words)

    def as_dict(self, time: float, phase: str) -> dict:
        """For ``summary.json``: when it fired [s], what, and its fields."""
        return {"time_s": time, "kind": self.kind, "phase": phase, "at": self.at} | self.fields()


@dataclass(frozen=True)
class _OnCable(Event):
    """An event on one cable.

    Attributes:
        cable: which cable, counted from 1.
    """

    cable: int = option(minimum=1)

    def check(self, n_cables: int) -> None:
        """The cable must exist."""
        if not 1 <= self.cable <= n_cables:
            raise OptionError("cable", f"must be in 1…{n_cables}, got {self.cable}")


def _check_until(event: Event, until: float) -> None:
    if not (until > event.at):  # NaN fails too
        raise OptionError("until", f"must be after at = {event.at} s, got {until}")


@dataclass(frozen=True)
class CableBreak(_OnCable):
    """A cable breaks: its force is zero from ``at`` on (the winch and encoder keep going)."""

    kind: ClassVar[str] = "cable_break"

    def apply(self, physics: Any, sensors: Any) -> None:
        """Disable the cable in the physics."""
        physics.disable_cable(self.cable - 1)


@dataclass(frozen=True)
class WinchStall(_OnCable):
    """A winch stalls: its drum stops whatever it is commanded (its encoder reads no motion).

    Attributes:
        until: when it follows its command again [s] (``inf``: never).
    """

    kind: ClassVar[str] = "winch_stall"
    until: float = option(math.inf, unit="s")

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_until(self, self.until)

    @property
    def end_time(self) -> float:
        """When the winch follows again [s]."""
        return self.until

    def apply(self, physics: Any, sensors: Any) -> None:
        """Stop the drum."""
        physics.stall_winch(self.cable - 1, True)

    def end(self, physics: Any, sensors: Any) -> None:
        """Let it turn again."""
        physics.stall_winch(self.cable - 1, False)


@dataclass(frozen=True)
class EncoderGlitch(_OnCable):
    """An encoder miscounts once: its reading jumps by ``jump`` and stays off by it.

    Attributes:
        jump: the jump of the reading [m] (non-zero, at most 1 m either way).
    """

    kind: ClassVar[str] = "encoder_glitch"
    jump: float = option(unit="m")

    def __post_init__(self) -> None:
        super().__post_init__()
        if not (math.isfinite(self.jump) and 0 < abs(self.jump) <= 1.0):
            raise OptionError("jump", f"must be non-zero and within ±1 m, got {self.jump}")

    def apply(self, physics: Any, sensors: Any) -> None:
        """Offset the encoder."""
        sensors.encoders.glitch(self.cable - 1, self.jump)


@dataclass(frozen=True)
class TensionSensorFail(_OnCable):
    """A tension sensor fails: it reads a constant from ``at`` on.

    Attributes:
        value: what it reads [N]; NaN (the default): its last reading, frozen.
    """

    kind: ClassVar[str] = "tension_sensor_fail"
    value: float = option(math.nan, unit="N")

    def __post_init__(self) -> None:
        super().__post_init__()
        if math.isinf(self.value) or abs(self.value) > MAX_TENSION_READING:
            raise OptionError(
                "value",
                f"must be nan or a force within ±{MAX_TENSION_READING:g} N (no cable robot's "
                f"sensor reads more), got {self.value:g}",
            )

    def apply(self, physics: Any, sensors: Any) -> None:
        """Freeze the sensor."""
        sensors.tension.fail(self.cable - 1, self.value)


@dataclass(frozen=True)
class TagOcclusion(Event):
    """Something hides the tag: a sheet between tag and camera, in the rendered image.

    Attributes:
        until: when the tag is uncovered [s] (``inf``: never).
        coverage: the fraction of the tag's code width hidden, from its −x edge (0 < c ≤ 1).
    """

    kind: ClassVar[str] = "tag_occlusion"
    until: float = option(math.inf, unit="s")
    coverage: float = option(1.0, minimum=0.0, exclusive=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_until(self, self.until)
        if not 0.0 < self.coverage <= 1.0:
            raise OptionError("coverage", f"must be in (0, 1], got {self.coverage}")

    @property
    def end_time(self) -> float:
        """When the tag is uncovered [s]."""
        return self.until

    def apply(self, physics: Any, sensors: Any) -> None:
        """Slide the sheet over the tag."""
        physics.occlude_tag(self.coverage)

    def end(self, physics: Any, sensors: Any) -> None:
        """Park the sheet."""
        physics.occlude_tag(0.0)


EVENT_KINDS: dict[str, type[Event]] = {
    cls.kind: cls
    for cls in (CableBreak, WinchStall, EncoderGlitch, TagOcclusion, TensionSensorFail)
}
"""Event classes by their ``kind`` in scenario files."""


class EventSchedule:
    """Fires events' starts and ends in time order; a step hook of the physics.

    Args:
        events: the events (any order).
        physics: what they act on.
        sensors: what they act on.
    """

    def __init__(self, events: tuple[Event, ...], physics: Any, sensors: Any) -> None:
        actions = [(e.at, 0, i, e) for i, e in enumerate(events)]
        actions += [(e.end_time, 1, i, e) for i, e in enumerate(events) if e.end_time < math.inf]
        self._pending = sorted(actions, key=lambda a: a[:3])
        self.physics, self.sensors = physics, sensors
        self.fired: list[tuple[float, Event, str]] = []
        """(simulation time it fired at [s], event, ``"start"`` or ``"end"``), in order."""
        self._taken = 0

    def next_time(self) -> float:
        """Time of the next pending start or end [s] (``inf`` when none is left)."""
        return self._pending[0][0] if self._pending else math.inf

    def fire(self, time: float) -> None:
        """Apply every pending start or end whose time is ≤ ``time`` [s]."""
        while self._pending and self._pending[0][0] <= time:
            _, ending, _, event = self._pending.pop(0)
            if ending:
                event.end(self.physics, self.sensors)
            else:
                event.apply(self.physics, self.sensors)
            self.fired.append((self.physics.time, event, "end" if ending else "start"))

    @property
    def pending(self) -> list[dict]:
        """What has not fired (yet): each start or end still due, as ``summary.json`` says it.

        A run that ends before an event's time (e.g. ``--duration`` shortened it) never fires
        it; the summary lists it under ``events_not_reached`` instead of saying nothing.
        """
        return [
            {"due_s": t, "kind": e.kind, "phase": "end" if ending else "start", "at": e.at}
            | e.fields()
            for t, ending, _, e in self._pending
        ]

    def take(self) -> list[tuple[float, Event, str]]:
        """What fired since the last call."""
        new = self.fired[self._taken :]
        self._taken = len(self.fired)
        return new
