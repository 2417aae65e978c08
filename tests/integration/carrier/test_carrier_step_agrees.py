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

from mission.config.schema import with_overrides
from mission.phases.phase import Phase
from mission.time.clock import ManualClock
from sim.batch.recovery import KinematicCarrier, configured
from sim.robots.carrier import CarrierMode, CarrierSim
from tests.integration.carrier.test_carrier_p3 import DT, RADIUS, _cfg
from tests.integration.carrier.test_carrier_sim import TARGET, Passenger, _seen, sessions
from tests.support.zenoh_util import wait_for

pytestmark = pytest.mark.timeout(60)

SCRIPT = [("RIDING", 120), ("NAVIGATING", 60), ("RETURNING", 10), ("APPROACH", 400), ("HOME", 90), ("RIDING", 30)]


@pytest.mark.parametrize("gnss", [False, True], ids=["its-state", "gnss-fixes"])
def test_the_controller_and_the_simulation_s_carrier_take_the_same_steps(gnss: bool) -> None:
    """gnss-fixes: ``world.carrier_gnss`` on (2 m of bias, 10 Hz fixes 0.2 s late): both steer on
    the same fixes (the simulation's carrier steered on its truth, metres from the flight's) and
    the guard keeps the fixes, not the truth, out of its circle."""
    towards = math.degrees(math.atan2(TARGET[1], TARGET[0]))
    cfg = _cfg(start_accel_m_s2=0.5, recovery_course=[[towards + 90.0, 1.0, 2.01]], recovery_heading_deg=towards,
               recovery_speed_m_s=1.5, acceleration_tau_s=0.1)
    if gnss:
        cfg = with_overrides(cfg, {"world.carrier_gnss.enabled": True, "world.carrier_gnss.bias_sigma_m": 1.4})
    carrier = KinematicCarrier(cfg, configured())
    carrier.step(None, None)  # at 0: the controller's first tick comes one period later
    clock = ManualClock()
    closest, k = math.inf, 0
    accelerations: list[float] = []
    with sessions(1) as (sa, sb), CarrierSim(cfg, clock, sa) as sim:
        passenger = Passenger(sb, "p3", clock, sim)
        try:
            wait_for(lambda: passenger.pub.matched)
            # with fixes 0.2 s late, both stand without an own state first (the controller then cannot
            # tell the passenger is on its dock point, which the simulation does not model): a wait
            for phase, steps in ([("ARMING", 12)] if gnss else []) + SCRIPT:
                for i in range(steps):
                    if i % 10 == 0:
                        seq = passenger.say(phase)
                        wait_for(lambda: _seen(sim, seq), what=f"{phase} seen")
                    k += 1
                    clock.advance_to(k * DT)
                    out = sim.step(DT)
                    carrier.step(Phase(phase), None)
                    assert carrier.mode is sim.mode, (k, phase)
                    if out is None:  # no own state yet (the first fix comes 0.2 s late): both stand
                        assert gnss and phase == "ARMING" and not np.any(carrier.velocity), (k, carrier.velocity)
                        continue
                    # the robots' true states (with gnss the published one is the fix, the same for both)
                    truth = sim.robot.state_at(k * DT)
                    np.testing.assert_allclose(carrier.velocity, truth.velocity_ned_m_s, atol=1e-9, err_msg=f"tick {k}")
                    np.testing.assert_allclose(carrier.position, truth.position_ned_m, atol=1e-9, err_msg=f"tick {k}")
                    seen = carrier.observed(k * DT)
                    assert seen is not None
                    np.testing.assert_allclose(seen.position_ned_m, out.position, atol=1e-9, err_msg=f"tick {k}")
                    sent = seen.acceleration_ned_m_s2  # what each sends of its acceleration
                    assert (sent is None) == (out.acceleration_ned_m_s2 is None), f"tick {k}"
                    if sent is not None:
                        np.testing.assert_allclose(sent, out.acceleration_ned_m_s2, atol=1e-9, err_msg=f"tick {k}")
                        accelerations.append(float(np.linalg.norm(sent)))
                    closest = min(closest, float(np.linalg.norm(TARGET - out.position)))  # where it steers (gnss: its fix)
        finally:
            passenger.pub.close()
        assert sim.mode is CarrierMode.APPROACHING and sim.summary()["guard_active_ticks"] > 0
    if not gnss:  # the steady course ran into the guard's circle (its fixes: 0.3 m of noise, 0.2 s late)
        assert RADIUS - 1e-9 <= closest < RADIUS + 0.1
    assert max(accelerations) > 0.5  # carrier.acceleration_tau_s: both sent the ramps' (1 m/s^2), not zeros
