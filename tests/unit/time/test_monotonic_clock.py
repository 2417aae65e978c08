"""MonotonicClock: the injected clock at speed 1 that converts to and from CLOCK_MONOTONIC stamps."""
from __future__ import annotations

import threading
import time

from mission.time.monotonic import MonotonicClock


def test_times_and_monotonic_stamps_convert_both_ways():
    clock = MonotonicClock()
    before = time.monotonic_ns()
    t = clock.now()
    after = time.monotonic_ns()
    assert before <= clock.to_monotonic_ns(t) <= after + 1000  # 1 us of rounding
    assert clock.from_monotonic_ns(clock.to_monotonic_ns(12.345)) == 12.345
    assert clock.speed == 1.0 and t >= 0.0


def test_it_is_a_full_clock():
    clock, cond = MonotonicClock(), threading.Condition()
    t0 = clock.now()
    clock.sleep(0.01)
    with cond:
        clock.wait(cond, 0.01)
        clock.notify(cond)
    clock.close()
    assert clock.now() - t0 >= 0.01
