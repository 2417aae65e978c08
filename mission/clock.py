"""Injected clocks.

Every timeout, watchdog, stream period and integration step reads a :class:`Clock`, never
``time.time()``. A :class:`ScaledClock` runs ``speed`` times faster than the wall clock, like
PX4's SIH speed factor, so processes that share a speed factor agree on rates and timeouts
while a test flies a minute in seconds. A :class:`ManualClock` is driven by hand in unit tests.
"""
from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    """A monotonic time source in seconds [s] of simulated time."""

    speed: float

    def now(self) -> float: ...

    def sleep(self, duration_s: float) -> None: ...


class ScaledClock:
    """Monotonic clock that advances ``speed`` simulated seconds per wall second.

    ``now()`` starts at 0 when the clock is made. ``sleep(d)`` blocks ``d / speed`` wall seconds.
    """

    def __init__(self, speed: float = 1.0) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed!r}")
        self.speed = float(speed)
        self._t0 = time.monotonic()

    def now(self) -> float:
        return (time.monotonic() - self._t0) * self.speed

    def sleep(self, duration_s: float) -> None:
        if duration_s > 0:
            time.sleep(duration_s / self.speed)

    def wall(self, duration_s: float) -> float:
        """Wall-clock seconds that ``duration_s`` simulated seconds take."""
        return duration_s / self.speed


class ManualClock:
    """A clock advanced explicitly (unit tests); ``sleep`` advances it instantly."""

    def __init__(self, start_s: float = 0.0) -> None:
        self.speed = 1.0
        self._t = float(start_s)
        self._lock = threading.Lock()

    def now(self) -> float:
        with self._lock:
            return self._t

    def advance(self, duration_s: float) -> None:
        with self._lock:
            self._t += duration_s

    def sleep(self, duration_s: float) -> None:
        if duration_s > 0:
            self.advance(duration_s)


class Periodic:
    """Deadline keeper for a fixed-rate loop: ``wait()`` sleeps until the next tick.

    Ticks are scheduled on an absolute grid (no drift); if the loop falls behind by more
    than one period the grid is re-anchored and the overrun counted.
    """

    def __init__(self, clock: Clock, period_s: float) -> None:
        if not period_s > 0:
            raise ValueError(f"period must be > 0, got {period_s!r}")
        self.clock, self.period_s = clock, float(period_s)
        self._next = clock.now() + self.period_s
        self.overruns = 0

    def wait(self) -> float:
        """Sleep until the next tick; return the clock time of the tick."""
        now = self.clock.now()
        if now > self._next + self.period_s:
            self.overruns += 1
            self._next = now
        else:
            self.clock.sleep(self._next - now)
        tick = self._next
        self._next += self.period_s
        return tick
