"""A carrier dropped from the lockstep for being late rejoins at the next step it answers, on the
controller's clock: it never runs on by a clock of its own (docs/lockstep.md, "Silent is gone,
slow is not").

The real processes of a pair (tests/faults/procs.py) fly in lockstep, paced (the vehicle at most
:data:`~tests.faults.procs.SPEED` x the wall clock, so the flight goes on at a bounded pace while
the carrier is away). Just after separation (the carrier's state no longer flies the passenger)
the carrier process is stopped (SIGSTOP) until the controller drops it (the wait for a carrier
whose liveliness token is present, ``ALIVE_CARRIER_WATCHDOG_WALL_S``, 6 s of wall time), then
continued. The stop is longer than the carrier's own watchdog on the controller's clock
(``CONTROLLER_WATCHDOG_WALL_S``, 5 s): before the fix its clock took its own stop for the
controller's silence, fell back to the wall clock and ran on by it; the controller's relay never
took it back, and its states' ages went negative (the CI run's -132 s).
"""
from __future__ import annotations

import json
import math
import signal
from pathlib import Path

import pytest

from mission.bus.feeds import FUTURE_SLACK_S
from mission.time.clock import ALIVE_CARRIER_WATCHDOG_WALL_S, CONTROLLER_WATCHDOG_WALL_S
from tests.faults.procs import flight, wait_for
from tests.faults.test_matrix import PACED, assert_completed

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]

#: [s] a carrier state's age once the carrier is back: its period (30 Hz) and the mission's tick
#: (50 Hz), with a step's slack; a carrier on a clock of its own is off by seconds
BACK_AGE_S = 0.1


def test_a_carrier_stopped_past_its_drop_rejoins_on_the_controllers_clock(tmp_path: Path) -> None:
    assert ALIVE_CARRIER_WATCHDOG_WALL_S > CONTROLLER_WATCHDOG_WALL_S  # the stop outlasts the carrier's watchdog
    with flight(tmp_path, "rejoin", lockstep=True, vehicle_args=PACED) as f:
        f.wait_phase("SEPARATED", timeout_s=60.0)
        carrier = f.procs["carrier"]
        carrier.send_signal(signal.SIGSTOP)
        try:
            wait_for(lambda: "lockstep: the carrier dropped" in f.text("mission.err"), 30.0, "the carrier dropped")
        finally:
            carrier.send_signal(signal.SIGCONT)
        wait_for(lambda: "lockstep: the carrier is back" in f.text("mission.err"), 30.0, "the carrier back")
        s = assert_completed(f)
    assert s["p1"] and s["p2"] and s["p3"], s
    lock = s["lockstep"]
    assert lock["fallback"] is None and lock["downstream_dropped"] == 1 and lock["downstream_rejoined"] == 1, lock
    assert lock["held"] is False, lock  # the run says it was not lockstep throughout
    c = json.loads((f.dir / "carrier.json").read_text())
    assert c["lockstep"]["fallback"] is None, c["lockstep"]  # the carrier stepped on the controller's clock
    assert s["carrier_feed"]["future_stamps"] == 0, s["carrier_feed"]
    rows = f.record()
    ages = [(float(r["t_s"]), float(r["carrier_age_s"])) for r in rows if not math.isnan(float(r["carrier_age_s"]))]
    assert min(a for _, a in ages) >= -FUTURE_SLACK_S, min(ages, key=lambda ta: ta[1])
    # once the carrier's states come fresh again after the stop, they stay fresh to the end
    oldest = max(range(len(ages)), key=lambda i: ages[i][1])
    back = next(i for i in range(oldest, len(ages)) if ages[i][1] <= BACK_AGE_S)
    assert all(a <= BACK_AGE_S for _, a in ages[back:]), max(ages[back:], key=lambda ta: ta[1])
