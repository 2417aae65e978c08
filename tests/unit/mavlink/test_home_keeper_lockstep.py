"""The home keeper in lockstep: it wakes (and asks for a step) only when a home is due or it checks."""
from __future__ import annotations

import numpy as np


def test_in_lockstep_the_home_keeper_wakes_only_when_a_home_is_due_or_it_checks():
    """A threaded keeper on a lockstep clock: the home sent at the same ticks as a keeper that
    decides in ``offer`` (a manual clock), and no step asked for by the keeper in between (a
    keeper polling once its period is over asked for one every millisecond: half the steps of a flight)."""
    from mission.mavlink.commander import CHECK_PERIOD_S, HomeKeeper
    from mission.time.clock import LockstepClock, ManualClock, start_thread
    from tests.support.stepper import Stepper

    def course(t_s: float) -> np.ndarray:  # the carrier stands, then moves on at 1 m/s
        return np.array([0.0 if t_s < 2.5 else t_s - 2.5, 0.0, 0.0])

    class Vehicle:
        def __init__(self, clock):
            self.clock, self.sent = clock, []

        @property
        def state(self):
            from types import SimpleNamespace
            return SimpleNamespace(home_ned_m=self.sent[-1][1] if self.sent else None, home_rx_s=self.clock.now())

        def set_home(self, home):
            self.sent.append((round(self.clock.now(), 6), np.array(home)))
            return 0

    manual = ManualClock(0.0)
    reference = Vehicle(manual)
    keeper = HomeKeeper(reference, manual, threaded=False)
    for k in range(300):
        manual.advance_to(k * 0.02)
        keeper.offer(course(k * 0.02))

    clock = LockstepClock(creator_runs=False, name="test", watchdog_wall_s=120.0)  # a loaded machine is slow, not gone
    stepper = Stepper(clock)
    vehicle = Vehicle(clock)
    threaded = HomeKeeper(vehicle, clock)

    def loop() -> None:
        for k in range(300):
            threaded.offer(course(clock.now()))
            clock.sleep(0.02)

    start_thread(clock, loop, "MainThread")
    barriers = []
    while clock.now() < 299 * 0.02 - 1e-9:  # to the last offer
        stepper.step()
        barriers.append(round(clock.now(), 6))
    clock.close()  # first: the keeper's thread then ends at once on the wall clock
    threaded.close()
    assert [t for t, _ in vehicle.sent] == [t for t, _ in reference.sent] == [0.0, 3.0, 4.0, 5.0]
    off_tick = [t for t in barriers if abs(t / 0.02 - round(t / 0.02)) > 1e-6]
    assert all(abs(t / CHECK_PERIOD_S - round(t / CHECK_PERIOD_S)) < 1e-6 for t in off_tick), off_tick
