"""LockstepClock: a thread a participant starts takes part from its first instruction."""
from __future__ import annotations

import threading
import time

from mission.time.clock import LockstepClock, start_thread
from tests.support.stepper import Stepper


def test_a_thread_started_in_a_step_acts_in_that_step_whatever_its_start_up_takes() -> None:
    clock = LockstepClock(name="test", creator_runs=False)
    stepper = Stepper(clock)
    seen: list[float] = []

    def child() -> None:
        time.sleep(0.05)  # a slow start (wall): unseen, a plain thread would act after the step
        seen.append(clock.now())
        clock.sleep(1.0)

    def parent() -> None:
        clock.sleep(0.1)
        start_thread(clock, child, "child")
        clock.sleep(10.0)

    threading.Thread(target=parent, name="parent", daemon=True).start()
    try:
        stepper.step()  # t = 0: the parent parks until 0.1
        stepper.step()  # t = 0.1: the parent starts the child; the step ends when the child waits
        assert seen == [0.1]
        stepper.step()
        assert clock.now() == 1.1  # the child's wake was in the step's report
    finally:
        clock.close()
