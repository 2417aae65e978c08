"""A rogue ground station arms the passenger seated on the carrier's deck and takes off with it
(configs/cycle.toml, ``mission.ride = "deck"``): the fault matrix's harness (tests/faults/procs.py,
lockstep) with the mock vehicle standing on the carrier's deck and the rogue on its GCS link.

On main the mission ignored a seated passenger that was armed and airborne, the carrier kept
driving, and at the separation the mission switched the rogue's flight to OFFBOARD and "took
off" from wherever it was. Now: deck_disturbed (exit 5), nothing more sent, the carrier stops
told why, and no take-off is ever adopted. docs/security.md, "Attacks tried".
"""
from __future__ import annotations

from pathlib import Path

import pytest

from mission.mavlink import px4
from tests.conftest import CONFIGS
from tests.faults.procs import Router, flight, wait_for
from tests.faults.test_matrix import PACED, assert_exit

pytestmark = [pytest.mark.slow, pytest.mark.timeout(200)]

DECK = ("--start-ned", "0,0,-0.5", "--deck", "pair0", "--deck-height", "0.5")  # cycle.toml's deck, at carrier_start


def test_a_rogue_arms_and_takes_off_the_seated_passenger(tmp_path: Path) -> None:
    router = Router()
    try:
        with flight(tmp_path, "deck-rogue", router=router, config=CONFIGS / "cycle.toml", lockstep=True,
                    vehicle_args=(*DECK, "--zenoh-connect", router.endpoint, *PACED)) as f:
            f.wait_phase("RIDING")
            wait_for(lambda: "-> approaching" in f.text("carrier.err"), 20.0, "carrier approaching")
            assert f.gcs is not None
            ack = f.gcs.arm(True)  # the rogue arms the seated passenger ...
            assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED
            f.gcs.command(px4.MAV_CMD_NAV_TAKEOFF, (0.0, 0.0, 0.0, float("nan"), float("nan"), float("nan"), float("nan")))
            f.wait_mission(30.0)  # ... and takes off with it
            assert_exit(f, 5, "deck_disturbed")
            s = f.summary()
            assert (s["phase"], s["reason"]) == ("ABORT", "deck_disturbed"), s
            rows = f.record()
            phases = {r["phase"] for r in rows}
            assert not phases & {"SEPARATED", "NAVIGATING"}, phases  # never adopted as a take-off
            seated = next(float(r["t_s"]) for r in rows if r["phase"] == "RIDING")
            flown = [m for t, m in f.tlog() if t >= seated and m.get_srcComponent() == 191 and (
                m.get_type() == "SET_POSITION_TARGET_LOCAL_NED" or m.get_type() == "COMMAND_LONG"
                and m.command in (px4.MAV_CMD_COMPONENT_ARM_DISARM, px4.MAV_CMD_DO_SET_MODE))]
            assert not flown, flown[:3]  # no setpoint, arming or mode switch ever sent to the rogue's flight
            wait_for(lambda: "-> stopped (passenger aborted: deck_disturbed)" in f.text("carrier.err"), 10.0,
                     "carrier stopped")
    finally:
        router.close()
