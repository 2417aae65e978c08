"""The test as the upstream of a process's lockstep clock (:class:`mission.time.clock.LockstepClock`):
what the mission's clock relay is to the carrier in a flight, for tests that drive one
component in simulated time."""
from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from mission.time.clock import LockstepClock


class Stepper:
    """The test as the upstream of the carrier's lockstep clock: it moves the clock to each step
    the carrier's threads need and waits for the step's report. Conditions are checked between
    steps, with timeouts in simulated seconds. ``settle`` (optional) runs before each step and
    blocks until what the step must see has arrived (e.g. the last status a scripted passenger
    published: what the carrier's clock relay waits for in a flight)."""

    def __init__(self, clock: LockstepClock, settle: Callable[[], None] | None = None) -> None:
        self.clock, self.settle = clock, settle
        clock.upstream = self
        self._cv = threading.Condition()
        self._done_ns, self._wake_ns = -1, 0
        self.reports: list[tuple[int, int]] = []  # every (t, wake) reported [ns], in order

    def report(self, t_ns: int, wake_ns: int) -> None:
        with self._cv:
            self._done_ns, self._wake_ns = t_ns, wake_ns
            self.reports.append((t_ns, wake_ns))
            self._cv.notify_all()

    def step(self) -> None:
        if self.settle is not None:
            self.settle()
        with self._cv:
            t_ns = max(self._wake_ns, self._done_ns + 1)
        self.clock.barrier(t_ns)
        with self._cv:
            if not self._cv.wait_for(lambda: self._done_ns >= t_ns, timeout=10.0):
                raise AssertionError(f"the carrier did not finish its step at t = {t_ns / 1e9:.3f} s")

    def until(self, predicate: Any, timeout_s: float, what: str) -> Any:
        """Step until ``predicate()`` is truthy (returned); at most ``timeout_s`` simulated seconds."""
        end_s = self.clock.now() + timeout_s
        while not (value := predicate()):
            if self.clock.now() > end_s:
                raise AssertionError(f"not within {timeout_s} s (simulated): {what}")
            self.step()
        return value

    def run_for(self, duration_s: float) -> None:
        end_s = self.clock.now() + duration_s
        while self.clock.now() < end_s:
            self.step()
