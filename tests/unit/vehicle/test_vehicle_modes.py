"""The mock vehicle's commander and physics, stepped by hand (sim/vehicle/modes.py): what a forced
disarm in the air does."""
from __future__ import annotations

import pytest

from mission.mavlink import px4
from sim.vehicle.modes import Commander, TrajectorySetpoint
from sim.vehicle.params import ParamTable, vehicle_limits
from sim.vehicle.physics.multicopter import KinState, step

DT = 0.005  # the mock's physics step [s]


def test_a_forced_disarm_in_the_air_stops_the_motors_and_pxs_land_detector_says_landed_while_it_falls():
    """PX4 (Commander.cpp): a disarm in the air needs param2 = 21196; then the motors stop. Its land
    detector counts a disarmed vehicle as landed through a hysteresis of LNDMC_TRIG_TIME / 3
    (MulticopterLandDetector.cpp), so EXTENDED_SYS_STATE says ON_GROUND 0.33 s later, while the
    vehicle is still falling from 3 m; it hits the ground in OFFBOARD, disarmed."""
    params = ParamTable()
    limits = vehicle_limits(params)
    kin = KinState(0.0, 0.0, -3.0, on_ground=False)
    c = Commander(params, kin)
    t = 0.0
    assert c.arm(t) == px4.MAV_RESULT_ACCEPTED
    c.accept_setpoint(t, TrajectorySetpoint(velocity=(0.0, 0.0, 0.0)))
    assert c.set_mode(t, "OFFBOARD") == px4.MAV_RESULT_ACCEPTED
    for _ in range(200):  # hover 1 s
        t += DT
        c.accept_setpoint(t, TrajectorySetpoint(velocity=(0.0, 0.0, 0.0)))
        kin = step(kin, c.step(t, kin), limits, (0.0, 0.0, 0.0), DT)
    assert c.landed_state(kin) == px4.LANDED_IN_AIR
    assert c.disarm(t) == px4.MAV_RESULT_TEMPORARILY_REJECTED and c.armed  # not landed: needs force
    assert c.disarm(t, force=True) == px4.MAV_RESULT_ACCEPTED and not c.armed
    t_disarmed, landed_at = t, None
    while kin.d_m < 0.0 and t < t_disarmed + 5.0:
        t += DT
        c.accept_setpoint(t, TrajectorySetpoint(velocity=(0.0, 0.0, 0.0)))  # the stream goes on: no matter
        command = c.step(t, kin)
        assert not command.powered
        kin = step(kin, command, limits, (0.0, 0.0, 0.0), DT)
        if landed_at is None and c.landed_state(kin) == px4.LANDED_ON_GROUND:
            landed_at, height = t, -kin.d_m
    assert landed_at is not None and landed_at - t_disarmed == pytest.approx(1.0 / 3.0, abs=DT)
    assert height > 2.0  # said while still in the air
    assert kin.on_ground and c.mode == "OFFBOARD" and not c.armed and t - t_disarmed < 1.5
