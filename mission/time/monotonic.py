"""A wall clock for benches and tools that stamp events with ``time.monotonic_ns()``."""
from __future__ import annotations

import time

from mission.time.clock import ScaledClock


class MonotonicClock(ScaledClock):
    """A :class:`ScaledClock` at speed 1 whose times convert to and from CLOCK_MONOTONIC [ns], for
    benches and tools that stamp events with ``time.monotonic_ns()`` (as the controller's
    ``on_tick`` reports do). ``now()`` starts at 0 when the clock is made."""

    def __init__(self) -> None:
        super().__init__(1.0)
        self._t0_ns = time.monotonic_ns()

    def now(self) -> float:
        return (time.monotonic_ns() - self._t0_ns) * 1e-9

    def to_monotonic_ns(self, t_s: float) -> int:
        """CLOCK_MONOTONIC [ns] of clock time ``t_s`` [s]."""
        return self._t0_ns + round(t_s * 1e9)

    def from_monotonic_ns(self, monotonic_ns: int) -> float:
        """Clock time [s] of a CLOCK_MONOTONIC stamp [ns]."""
        return (monotonic_ns - self._t0_ns) * 1e-9
