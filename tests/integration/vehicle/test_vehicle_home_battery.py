"""The mock vehicle's battery and home over real UDP, as a PX4 SITL showed them (docs/flying-px4.md):
the battery simulator in SYS_STATUS and BATTERY_STATUS and PX4's low-battery failsafe;
DO_SET_HOME (COMMAND_LONG and COMMAND_INT) armed and in flight, HOME_POSITION, a home set by
command surviving the next arming, RTL fixing its destination and return altitude when it starts,
and the offboard-loss failsafe returning to the home last set."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.core import geodesy
from mission.mavlink import px4
from mission.mavlink.env import mavlink
from sim.testing.probe import Probe, connect, start_offboard, vehicle_for, wait_flight
from sim.vehicle.mock import MockVehicle

pytestmark = pytest.mark.timeout(60)

BATTERY = {"SIM_BAT_ENABLE": 1, "SIM_BAT_DRAIN": 20.0, "SIM_BAT_MIN_PCT": 0.0}


def set_home(probe: Probe, north_m: float, east_m: float, down_m: float = 0.0, *, as_int: bool = True,
             lat_lon: tuple[float, float] | None = None) -> int | None:
    """DO_SET_HOME at a local NED point through the vehicle's EKF origin; the ACK's result."""
    origin = probe.wait_for("GPS_GLOBAL_ORIGIN", timeout_s=3.0)
    assert origin is not None
    lat0, lon0, alt0 = origin.latitude * 1e-7, origin.longitude * 1e-7, origin.altitude * 1e-3
    lat, lon = lat_lon or geodesy.reproject(north_m, east_m, lat0, lon0)
    mark = probe.mark()
    command = mavlink.MAV_CMD_DO_SET_HOME
    if as_int:
        probe.send(mavlink.MAVLink_command_int_message(1, 1, mavlink.MAV_FRAME_GLOBAL, command, 0, 0, 0.0, 0.0, 0.0,
                                                       math.nan, round(lat * 1e7), round(lon * 1e7), alt0 - down_m))
    else:
        probe.send(mavlink.MAVLink_command_long_message(1, 1, command, 0, 0.0, 0.0, 0.0, math.nan, lat, lon,
                                                        alt0 - down_m))
    ack = probe.wait_for("COMMAND_ACK", lambda m: m.command == command, 3.0, mark)
    return None if ack is None else ack.result


def home_is(v: MockVehicle, ned: tuple[float, float, float], tol_m: float) -> bool:
    return bool(np.allclose(v.snapshot().home_ned_m, ned, atol=tol_m))


def test_battery_drains_while_armed_in_sys_status_and_battery_status_then_px4_returns_at_critical(probe: Probe):
    with vehicle_for(probe, paced=True, speed=20.0, params=BATTERY) as v:
        connect(probe)
        status = probe.wait_for("SYS_STATUS", timeout_s=3.0)
        assert (status.voltage_battery, status.current_battery, status.battery_remaining) == (16200, -100, 100)
        assert probe.wait_for("BATTERY_STATUS", lambda m: m.battery_remaining == 100, 5.0) is not None
        with start_offboard(probe, (0.0, 0.0, -1.0)):
            mark = probe.mark()
            wait_flight(v, lambda s: s.position_ned_m[2] < -2.0, 5.0, "climbed")
            pass
            failsafe = wait_flight(v, lambda s: s.mode == "AUTO.RTL", 30.0, "PX4's battery failsafe")
        assert failsafe.in_failsafe and failsafe.battery_pct <= 7
        t_low, t_critical = v.event_time("Low battery level"), v.event_time("Failsafe activated: battery critical")
        t_armed = v.event_time("Armed by external command")
        assert t_low is not None and t_critical is not None and t_armed is not None
        # below BAT_LOW_THR 0.15 and BAT_CRIT_THR 0.07 of a 20 s drain, the estimate 1 s late
        assert t_low - t_armed == pytest.approx(20.0 * 0.85 + 1.0, abs=0.3)
        assert t_critical - t_armed == pytest.approx(20.0 * 0.93 + 1.0, abs=0.3)
        seen = [m.battery_remaining for m in probe.messages("SYS_STATUS", mark)]
        assert seen == sorted(seen, reverse=True) and seen[0] >= 85 and seen[-1] <= 8


def test_no_battery_unless_asked(probe: Probe):
    with vehicle_for(probe, paced=True, speed=20.0) as v:
        connect(probe)
        status = probe.wait_for("SYS_STATUS", timeout_s=3.0)
        assert status.battery_remaining == -1 and v.snapshot().battery_pct is None
        probe.wait_for("GPS_GLOBAL_ORIGIN", timeout_s=3.0)  # 1 Hz: BATTERY_STATUS (0.5 Hz) would be due by now
        probe.wait_for("GPS_GLOBAL_ORIGIN", lambda m: True, 3.0, probe.mark())
        assert probe.messages("BATTERY_STATUS") == []


def test_set_home_disarmed_and_in_flight_survives_arming_and_reads_back(probe: Probe):
    with vehicle_for(probe, paced=True, speed=20.0) as v:
        connect(probe)
        assert set_home(probe, 10.0, -4.0) == px4.MAV_RESULT_ACCEPTED
        assert home_is(v, (10.0, -4.0, 0.0), 0.02)  # COMMAND_INT: degrees x 1e7, about a centimetre
        mark = probe.mark()
        back = probe.wait_for("HOME_POSITION", None, 3.0, mark)
        assert back is not None and (back.x, back.y, back.z) == pytest.approx((10.0, -4.0, 0.0), abs=0.02)
        with start_offboard(probe, (0.0, 0.0, -1.0)):  # arming on the ground keeps a commanded home
            wait_flight(v, lambda s: s.position_ned_m[2] < -2.0, 5.0, "climbed")
            assert home_is(v, (10.0, -4.0, 0.0), 0.02)
            assert set_home(probe, -10.0, 5.0, as_int=False) == px4.MAV_RESULT_ACCEPTED  # armed, in the air
            # COMMAND_LONG's float32 params: 47.4 deg has a 4e-6 deg step, about 0.4 m (PX4 SITL: 0.18 m off)
            home = v.snapshot().home_ned_m
            assert np.allclose(home, (-10.0, 5.0, 0.0), atol=0.5) and not np.allclose(home, (-10.0, 5.0, 0.0), atol=1e-3)
            assert set_home(probe, 0.0, 0.0, as_int=False, lat_lon=(math.nan, 8.5)) == px4.MAV_RESULT_DENIED
            v.lose_position_estimate(True)
            assert set_home(probe, 3.0, 3.0) == px4.MAV_RESULT_TEMPORARILY_REJECTED


def test_rtl_keeps_the_destination_it_started_with_and_returns_in_the_cone(probe: Probe):
    """Home 7.2 m away: within RTL_MIN_DIST (10 m), the 45 deg cone's height there is 7.2 m; the home
    moved during the return is not followed (a PX4 SITL landed at the first one)."""
    with vehicle_for(probe, paced=True, speed=20.0) as v:
        connect(probe)
        with start_offboard(probe, (0.0, 0.0, -1.0)):
            wait_flight(v, lambda s: s.position_ned_m[2] < -2.0, 5.0, "climbed")
            assert set_home(probe, -6.0, 4.0) == px4.MAV_RESULT_ACCEPTED
            start = v.snapshot().position_ned_m
            assert probe.command(px4.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == px4.MAV_RESULT_ACCEPTED
            wait_flight(v, lambda s: s.mode == "AUTO.RTL", 2.0, "RTL")
            assert set_home(probe, 6.0, 6.0) == px4.MAV_RESULT_ACCEPTED
            top = wait_flight(v, lambda s: s.velocity_ned_m_s[2] > 0.3, 20.0, "the descent")
            landed = wait_flight(v, lambda s: s.landed_state == px4.LANDED_ON_GROUND, 60.0, "landed")
        dist = math.hypot(start[0] + 6.0, start[1] - 4.0)
        assert 6.0 < dist < 10.0
        assert -top.position_ned_m[2] == pytest.approx(dist, abs=0.6)  # the cone, not RTL_RETURN_ALT's 30 m
        assert np.allclose(landed.position_ned_m[:2], (-6.0, 4.0), atol=0.6)


def test_offboard_loss_set_to_return_flies_to_the_home_last_set_not_the_takeoff_point(probe: Probe):
    with vehicle_for(probe, paced=True, speed=20.0, params={"COM_OBL_RC_ACT": 3}) as v:
        connect(probe)
        with start_offboard(probe, (1.0, 0.0, -1.0)):
            wait_flight(v, lambda s: s.position_ned_m[2] < -3.0, 5.0, "climbed")
            assert set_home(probe, 8.0, 8.0) == px4.MAV_RESULT_ACCEPTED
        failsafe = wait_flight(v, lambda s: s.mode == "AUTO.RTL", 5.0, "the offboard-loss failsafe")
        assert failsafe.in_failsafe
        landed = wait_flight(v, lambda s: s.landed_state == px4.LANDED_ON_GROUND, 60.0, "landed")
        assert np.allclose(landed.position_ned_m[:2], (8.0, 8.0), atol=0.6)
