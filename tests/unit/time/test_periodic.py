"""The loop's deadline keeper: a grid of ticks, re-anchored after an overrun, and a tick that
says the time it really is after a sleep that ended late (a stopped or starved process)."""
from __future__ import annotations

import pytest

from mission.time.clock import ManualClock, Periodic


class OversleepingClock(ManualClock):
    """A manual clock whose next sleep ends ``late_s`` [s] after it should (the process stopped in it)."""

    def __init__(self) -> None:
        super().__init__()
        self.late_s = 0.0

    def sleep(self, duration_s: float) -> None:
        super().sleep(duration_s + self.late_s)
        self.late_s = 0.0


def test_ticks_on_the_grid_and_an_overrun_reanchors_it() -> None:
    clock = OversleepingClock()
    periodic = Periodic(clock, 0.02)
    assert [round(periodic.wait(), 6) for _ in range(3)] == [0.02, 0.04, 0.06]
    clock.advance(0.5)  # the loop itself took 0.5 s
    assert periodic.wait() == pytest.approx(0.56) and periodic.overruns == 1
    assert periodic.wait() == pytest.approx(0.58)


def test_a_sleep_that_ends_a_second_late_gives_the_time_it_is_not_the_grid_time() -> None:
    clock = OversleepingClock()
    periodic = Periodic(clock, 0.02)
    periodic.wait()
    clock.late_s = 1.0  # stopped (SIGSTOP) while sleeping to the next tick
    t = periodic.wait()
    assert t == pytest.approx(clock.now()) and t == pytest.approx(1.04)  # not the 0.04 it slept for
    assert periodic.overruns == 1
    assert periodic.wait() == pytest.approx(1.06)


def test_a_sleep_late_by_less_than_a_period_stays_on_the_grid() -> None:
    clock = OversleepingClock()
    periodic = Periodic(clock, 0.02)
    periodic.wait()
    clock.late_s = 0.015
    assert periodic.wait() == pytest.approx(0.04) and periodic.overruns == 0
