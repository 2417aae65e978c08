"""The carrier's gentle start on a robot with stiction (carrier.start_accel_m_s2): while it stands
the command grows slowly, so it breaks free at a low speed; once it moves the law's acceleration
limit applies. Real Zenoh to a scripted passenger; the carrier steps on a manual clock."""
from __future__ import annotations

import numpy as np
import pytest

from mission.carrier.controller import CarrierController
from mission.carrier.backends.sim import SimRobot
from mission.carrier.tracking import Tracked
from mission.time.clock import ManualClock
from mission.config.schema import Config, from_dict
from tests.integration.carrier.test_carrier_sim import TARGET, Passenger, _seen, sessions
from tests.support.zenoh_util import wait_for

pytestmark = pytest.mark.timeout(60)

DT = 1.0 / 30.0
BREAKAWAY_M_S = 0.3  # the robot stands until it is asked this much (SIH's rover: ~0.3 m/s of PX4 speed loop)


class StickyRobot(SimRobot):
    """The built-in Ackermann robot with static friction: it stands until asked for at least
    ``BREAKAWAY_M_S``; free, it drives as asked. Records every speed asked [m/s]."""

    def __init__(self, cfg: Config, clock: ManualClock) -> None:
        super().__init__(cfg, clock)
        self.free = False
        self.asked: list[float] = []

    def command(self, cmd: Tracked) -> None:
        self.asked.append(cmd.speed_m_s)
        self.free = self.free or cmd.speed_m_s >= BREAKAWAY_M_S
        super().command(cmd if self.free else Tracked(0.0, 0.0, cmd.bearing_rad, np.zeros(2), np.zeros(2)))


def _asked_speeds(start_accel: float) -> tuple[list[float], int]:
    """Speeds asked over 3 s of riding, and the step the robot broke free at."""
    cfg = from_dict({
        "zenoh": {"pair": "start"},
        "scenario": {"carrier_start": [0.0, 0.0, 0.0], "target": TARGET.tolist()},
        "safety": {"carrier_max_accel_m_s2": 1.0},
        "carrier": {"rate_hz": 30.0, "max_speed_m_s": 1.0, "kinematics": "ackermann", "start_accel_m_s2": start_accel},
    })
    clock = ManualClock()
    with sessions(1) as (sa, sb):
        robot = StickyRobot(cfg, clock)
        with CarrierController(cfg, clock, sa, robot) as carrier:
            passenger = Passenger(sb, "start", clock, carrier)
            try:
                wait_for(lambda: passenger.pub.matched)
                seq = passenger.say("RIDING")
                wait_for(lambda: _seen(carrier, seq), what="RIDING seen")
                free_at = -1
                for k in range(90):
                    if k % 10 == 9:  # the passenger keeps saying it rides (a status is stale after 1 s)
                        seq = passenger.say("RIDING")
                        wait_for(lambda: _seen(carrier, seq), what="RIDING seen")
                    clock.advance(DT)
                    carrier.step(DT)
                    if robot.free and free_at < 0:
                        free_at = k
            finally:
                passenger.pub.close()
    return robot.asked, free_at


def test_a_standing_robot_is_asked_gently_so_it_breaks_free_at_a_low_speed_then_the_law_ramps_on() -> None:
    asked, free_at = _asked_speeds(0.25)
    steps = np.diff(asked[:free_at + 1])
    assert steps.max() <= 0.25 * DT + 1e-9  # standing: the command grows at the start acceleration
    assert asked[free_at] < BREAKAWAY_M_S + 0.25 * DT + 1e-9  # so it breaks free at the speed that frees it
    assert free_at * DT == pytest.approx(BREAKAWAY_M_S / 0.25, abs=3 * DT)
    moving = np.diff(asked[free_at + 2:])
    assert moving.max() == pytest.approx(1.0 * DT, rel=1e-6)  # moving: the law's 1 m/s^2
    assert max(asked) == pytest.approx(1.0)  # and on to its speed limit


def test_without_a_gentle_start_the_law_s_ramp_runs_on_while_the_robot_stands() -> None:
    asked, free_at = _asked_speeds(0.0)
    assert np.diff(asked[:free_at + 1]).max() == pytest.approx(1.0 * DT, rel=1e-6)
    assert free_at * DT == pytest.approx(BREAKAWAY_M_S / 1.0, abs=3 * DT)
