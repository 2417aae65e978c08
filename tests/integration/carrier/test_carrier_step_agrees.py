"""One carrier step in one place: ``marsupial carrier``'s controller on its built-in robot, hearing
a scripted passenger over real Zenoh, and the recovery simulation's carrier
(sim/batch/recovery.py's KinematicCarrier) told the same phases, command the same velocity,
stand at the same place and send the same measured acceleration every tick, through a deploy, a
recovery course with a turn, the guard's circle, parking and riding again. The carrier steps on a
manual clock."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.phases.phase import Phase
from mission.time.clock import ManualClock
from sim.batch.recovery import KinematicCarrier, configured
from sim.robots.carrier import CarrierMode, CarrierSim
from tests.integration.carrier.test_carrier_p3 import DT, RADIUS, _cfg
from tests.integration.carrier.test_carrier_sim import TARGET, Passenger, _seen, sessions
from tests.support.zenoh_util import wait_for

pytestmark = pytest.mark.timeout(60)

SCRIPT = [("RIDING", 120), ("NAVIGATING", 60), ("RETURNING", 10), ("APPROACH", 400), ("HOME", 90), ("RIDING", 30)]


def test_the_controller_and_the_simulation_s_carrier_take_the_same_steps() -> None:
    towards = math.degrees(math.atan2(TARGET[1], TARGET[0]))
    cfg = _cfg(start_accel_m_s2=0.5, recovery_course=[[towards + 90.0, 1.0, 2.01]], recovery_heading_deg=towards,
               recovery_speed_m_s=1.5, acceleration_tau_s=0.1)
    carrier = KinematicCarrier(cfg, configured())
    carrier.step(None, None)  # at 0: the controller's first tick comes one period later
    clock = ManualClock()
    closest, k = math.inf, 0
    accelerations: list[float] = []
    with sessions(1) as (sa, sb), CarrierSim(cfg, clock, sa) as sim:
        passenger = Passenger(sb, "p3", clock, sim)
        try:
            wait_for(lambda: passenger.pub.matched)
            for phase, steps in SCRIPT:
                for i in range(steps):
                    if i % 10 == 0:
                        seq = passenger.say(phase)
                        wait_for(lambda: _seen(sim, seq), what=f"{phase} seen")
                    k += 1
                    clock.advance_to(k * DT)
                    out = sim.step(DT)
                    carrier.step(Phase(phase), None)
                    assert out is not None and carrier.mode is sim.mode, (k, phase)
                    np.testing.assert_allclose(carrier.velocity, out.velocity_ned_m_s, atol=1e-9, err_msg=f"tick {k}")
                    np.testing.assert_allclose(carrier.position, out.position, atol=1e-9, err_msg=f"tick {k}")
                    sent = carrier.observed(k * DT).acceleration_ned_m_s2  # what each sends of its acceleration
                    assert (sent is None) == (out.acceleration_ned_m_s2 is None), f"tick {k}"
                    if sent is not None:
                        np.testing.assert_allclose(sent, out.acceleration_ned_m_s2, atol=1e-9, err_msg=f"tick {k}")
                        accelerations.append(float(np.linalg.norm(sent)))
                    closest = min(closest, float(np.linalg.norm(TARGET - out.position)))
        finally:
            passenger.pub.close()
        assert sim.mode is CarrierMode.APPROACHING and sim.summary()["guard_active_ticks"] > 0
    assert RADIUS - 1e-9 <= closest < RADIUS + 0.1  # the steady course ran into the guard's circle
    assert max(accelerations) > 0.5  # carrier.acceleration_tau_s: both sent the ramps' (1 m/s^2), not zeros
