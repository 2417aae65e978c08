"""The link's LOCAL_POSITION_NED rate: counted from the newest stamps, what a search of them all gives."""
from __future__ import annotations

import random

from mission.mavlink.session import LinkSession
from mission.time.clock import ManualClock


def _searched(stamps: list[float], now: float, window_s: float) -> float:
    kept = [t for t in stamps if now - t <= window_s]
    return 0.0 if len(kept) < 2 else (len(kept) - 1) / max(kept[-1] - kept[0], 1e-9)


def test_the_rate_is_that_of_a_search_of_every_stamp_in_order_and_after_a_clock_stepped_back():
    rng = random.Random(5)
    for back in (False, True):
        clock = ManualClock(0.0)
        session = LinkSession("test", clock, position_timeout_s=1.0)
        kept: list[float] = []
        t = 0.0
        for i in range(1500):
            t += -0.5 if back and i == 700 else rng.choice([0.0, 0.004, 0.02, 0.02, 0.3])
            with session.lock:
                session.note_position(t)
            kept = (kept + [t])[-256:]
            clock.advance_to(max(clock.now(), t + rng.choice([0.0, 0.01, 0.6])))
            for window_s in (0.5, 1.0):
                assert session.position_rate_hz(window_s) == _searched(kept, clock.now(), window_s), (i, window_s)
        assert session.position_stamps_rise is not back
