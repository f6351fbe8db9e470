"""Timed scenario events (faults) acting on the simulated robot through the physics hooks.

A scenario lists events in ``[[events]]`` tables::

    [[events]]
    type = "cable_break"     # a registered event type
    time = 1.0               # [s]
    cable = 3                # 1-based, as on the robot

Each event type is a frozen dataclass (its fields are its schema, parsed like plugin options)
with an ``apply(physics, sensors)`` method. An :class:`EventSchedule` is a
:class:`~cdpr_twin.sim.physics.StepHook`: the physics stops stepping at each event's time and
fires it between two steps; the runner also fires what is due before each control tick.
Events never read MuJoCo directly: they act through the physics' and sensors' public methods
(``disable_cable``…), so the swivel/stiffness refresh respects them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

from cdpr_twin.plugins import OptionError, option


class StepHook(Protocol):
    """Something that acts on the physics between steps, at times of its choosing."""

    def next_time(self) -> float:
        """Simulation time [s] of the next action (``inf`` when there is none)."""
        ...

    def fire(self, time: float) -> None:
        """Act now: everything due at or before ``time`` [s]."""
        ...


@dataclass(frozen=True)
class Event:
    """Base of timed events.

    Attributes:
        time: when it happens [s].
    """

    type: ClassVar[str] = ""
    time: float = option(minimum=0.0, unit="s")

    def __post_init__(self) -> None:
        if not (math.isfinite(self.time) and self.time >= 0):
            raise OptionError("time", f"must be a finite time ≥ 0 s, got {self.time}")

    def check(self, n_cables: int) -> None:
        """Check the event against the robot before the run starts.

        Raises:
            OptionError: naming the field at fault.
        """

    def apply(self, physics: Any, sensors: Any) -> None:
        """Act on the simulated robot."""
        raise NotImplementedError


@dataclass(frozen=True)
class CableBreak(Event):
    """A cable breaks: its force is zero from ``time`` on (the winch and encoder keep going).

    Attributes:
        cable: which cable, counted from 1.
    """

    type: ClassVar[str] = "cable_break"
    cable: int = option(minimum=1)

    def check(self, n_cables: int) -> None:
        """The cable must exist."""
        if not 1 <= self.cable <= n_cables:
            raise OptionError("cable", f"must be in 1…{n_cables}, got {self.cable}")

    def apply(self, physics: Any, sensors: Any) -> None:
        """Disable the cable in the physics."""
        physics.disable_cable(self.cable - 1)


EVENT_TYPES: dict[str, type[Event]] = {cls.type: cls for cls in (CableBreak,)}
"""Event classes by their ``type`` in scenario files."""


class EventSchedule:
    """Fires events in time order; a step hook of the physics.

    Args:
        events: the events (any order).
        physics: what they act on.
        sensors: what they act on.
    """

    def __init__(self, events: tuple[Event, ...], physics: Any, sensors: Any) -> None:
        self._pending = sorted(events, key=lambda e: e.time)
        self.physics, self.sensors = physics, sensors
        self.fired: list[tuple[float, Event]] = []
        """(simulation time it fired at [s], event), in order."""

    def next_time(self) -> float:
        """Time of the next pending event [s] (``inf`` when none is left)."""
        return self._pending[0].time if self._pending else math.inf

    def fire(self, time: float) -> None:
        """Apply every pending event whose time is ≤ ``time`` [s]."""
        while self._pending and self._pending[0].time <= time:
            event = self._pending.pop(0)
            event.apply(self.physics, self.sensors)
            self.fired.append((self.physics.time, event))
