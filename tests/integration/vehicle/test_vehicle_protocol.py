"""Mock vehicle MAVLink protocol: targets, NaN parameters, parameters, message requests and
intervals, TIMESYNC, setpoint validation, streams and their rates, latching, GCS link, CLI."""
from __future__ import annotations

import math
import signal
import statistics
import subprocess
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner

from mission.core import geodesy

from mission.mavlink import px4, setpoints
from mission.mavlink.env import mavlink
from sim.net import wait_for
from sim.vehicle.mock import FaultOptions, MockVehicle, VehicleOptions, spawn_process
from sim.vehicle.cli import mock_vehicle, signing_key_option
from sim.vehicle.endpoints import parse_endpoint
from sim.vehicle.params import PARAM_SPECS, pack_int32, unpack_int32
from sim.testing.probe import Lockstep, Probe, SetpointStream, connect, start_offboard, vehicle_for, wait_flight

pytestmark = pytest.mark.timeout(30)
NAN = math.nan


@pytest.mark.parametrize("target", [(2, 1), (1, 50), (255, 190)])
def test_command_with_wrong_target_gets_no_ack(probe: Probe, target: tuple[int, int]) -> None:
    with vehicle_for(probe) as v:
        connect(probe)
        ack = probe.command(px4.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,), target=target, timeout_s=0.3)
        assert ack is None
        assert v.counters["rx_wrong_target"] == 1 and not v.snapshot().armed
        broadcast = probe.command(px4.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,), target=(0, 0))
        assert broadcast is not None and broadcast.result == px4.MAV_RESULT_ACCEPTED
        assert (broadcast.target_system, broadcast.target_component) == (255, 190)  # ACK goes to the sender


def test_setpoints_to_another_system_are_not_proof_of_life(probe: Probe) -> None:
    with vehicle_for(probe, paced=True) as v:
        connect(probe)
        with SetpointStream(probe, 0.01, target=(2, 1)):
            wait_flight(v, lambda s: s.counters["rx_wrong_target"] >= 5, 2.0, "s.counters['rx_wrong_target'] >= 5")
            assert probe.set_mode("OFFBOARD").result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        assert v.counters["setpoints_accepted"] == 0


def test_nan_parameters_are_tolerated(probe: Probe) -> None:
    with vehicle_for(probe) as v:
        connect(probe)
        # what MAVSDK sends: arm with param1 = 1 and NaN elsewhere; DO_SET_MODE(129, 6, 0, NaN...)
        assert probe.command(px4.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,)).result == px4.MAV_RESULT_ACCEPTED
        assert probe.command(px4.MAV_CMD_DO_SET_MODE, (129.0, 3.0, NAN)).result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        assert probe.command(px4.MAV_CMD_DO_SET_MODE, (129.0, 4.0, 3.0)).result == px4.MAV_RESULT_ACCEPTED
        assert probe.command(px4.MAV_CMD_COMPONENT_ARM_DISARM, (NAN,)).result == px4.MAV_RESULT_ACCEPTED  # NaN -> 0
        assert not v.snapshot().armed
        assert probe.command(px4.MAV_CMD_DO_SET_MODE, (NAN, NAN, NAN)).result == px4.MAV_RESULT_UNSUPPORTED
        assert v.counters["internal_errors"] == 0


def test_set_mode_as_command_int(probe: Probe) -> None:
    with vehicle_for(probe, paced=True) as v:
        connect(probe)
        with SetpointStream(probe, 0.01):
            wait_flight(v, lambda s: s.counters["setpoints_accepted"] > 2, 2.0, "s.counters['setpoints_accepted'] > 2")
            ack = probe.command(px4.MAV_CMD_DO_SET_MODE, (129.0, 6.0, 0.0), as_int=True)
            assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED
            assert probe.wait_mode("OFFBOARD", 2.0)


def test_a_forced_arm_from_a_ground_station_still_runs_the_checks(probe: Probe) -> None:
    """PX4's Commander runs the pre-arm checks for every external arm (``arm(reason, from_external
    || !forced)``; docs/flying-px4.md has the real SITL refusing both)."""
    with vehicle_for(probe, faults=FaultOptions(refuse_arming_reason="Arming denied: test")) as v:
        connect(probe)
        assert probe.arm().result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        assert probe.arm(force=True).result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        assert not v.snapshot().armed


def test_unknown_command_is_unsupported(probe: Probe) -> None:
    with vehicle_for(probe):
        connect(probe)
        ack = probe.command(31000)
        assert ack is not None and ack.result == px4.MAV_RESULT_UNSUPPORTED


def test_parameter_protocol_list_read_set(probe: Probe) -> None:
    with vehicle_for(probe, params={"MPC_XY_VEL_MAX": 8.0}) as v:
        connect(probe)
        mark = probe.mark()
        probe.send(mavlink.MAVLink_param_request_list_message(1, 1))
        wait_for(lambda: len(probe.messages("PARAM_VALUE", after=mark)) >= len(PARAM_SPECS), 3.0, "every PARAM_VALUE")
        values = {m.param_id: m for m in probe.messages("PARAM_VALUE", after=mark)}
        assert set(values) >= {"COM_OF_LOSS_T", "COM_OBL_RC_ACT", "COM_DISARM_PRFLT", "COM_DISARM_LAND", "MPC_XY_VEL_MAX",
                               "MPC_Z_VEL_MAX_UP", "MPC_Z_VEL_MAX_DN", "MPC_ACC_HOR", "MPC_TKO_SPEED", "MPC_LAND_SPEED",
                               "MIS_TAKEOFF_ALT", "NAV_RCL_ACT", "COM_ARM_WO_GPS"}
        assert sorted(m.param_index for m in values.values()) == list(range(len(PARAM_SPECS)))
        assert all(m.param_count == len(PARAM_SPECS) for m in values.values())
        assert values["COM_OF_LOSS_T"].param_type == px4.MAV_PARAM_TYPE_REAL32 and values["COM_OF_LOSS_T"].param_value == 1.0
        assert values["MPC_XY_VEL_MAX"].param_value == 8.0  # the override
        rc_act = values["NAV_RCL_ACT"]
        assert rc_act.param_type == px4.MAV_PARAM_TYPE_INT32 and unpack_int32(rc_act.param_value) == 2  # bit-packed

        mark = probe.mark()
        probe.send(mavlink.MAVLink_param_request_read_message(1, 1, b"MPC_LAND_SPEED", -1))
        reply = probe.wait_for("PARAM_VALUE", after=mark, timeout_s=2.0)
        assert reply is not None and reply.param_id == "MPC_LAND_SPEED" and reply.param_value == pytest.approx(0.7)
        mark = probe.mark()
        probe.send(mavlink.MAVLink_param_request_read_message(1, 1, b"", 0))
        reply = probe.wait_for("PARAM_VALUE", after=mark, timeout_s=2.0)
        assert reply is not None and reply.param_index == 0 and reply.param_id == PARAM_SPECS[0].name

        mark = probe.mark()
        probe.send(mavlink.MAVLink_param_set_message(1, 1, b"COM_OF_LOSS_T", 2.5, px4.MAV_PARAM_TYPE_REAL32))
        reply = probe.wait_for("PARAM_VALUE", lambda m: m.param_id == "COM_OF_LOSS_T", 2.0, mark)
        assert reply is not None and reply.param_value == 2.5 and v.params.get("COM_OF_LOSS_T") == 2.5
        probe.send(mavlink.MAVLink_param_set_message(1, 1, b"COM_OBL_RC_ACT", pack_int32(5), px4.MAV_PARAM_TYPE_INT32))
        reply = probe.wait_for("PARAM_VALUE", lambda m: m.param_id == "COM_OBL_RC_ACT", 2.0, mark)
        assert reply is not None and unpack_int32(reply.param_value) == 5 and v.params.get("COM_OBL_RC_ACT") == 5

        mark = probe.mark()
        probe.send(mavlink.MAVLink_param_set_message(1, 1, b"NO_SUCH_PARAM", 1.0, px4.MAV_PARAM_TYPE_REAL32))
        probe.send(mavlink.MAVLink_param_request_read_message(1, 1, b"NO_SUCH_PARAM", -1))
        assert probe.wait_for("PARAM_VALUE", after=mark, timeout_s=0.3) is None


def test_request_message_autopilot_version_and_home(probe: Probe) -> None:
    with vehicle_for(probe):
        connect(probe)
        mark = probe.mark()
        ack = probe.command(px4.MAV_CMD_REQUEST_MESSAGE, (float(mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION),))
        assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED
        version = probe.wait_for("AUTOPILOT_VERSION", after=mark, timeout_s=2.0)
        assert version is not None
        for capability in (px4.MAV_PROTOCOL_CAPABILITY_MAVLINK2, px4.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED,
                           px4.MAV_PROTOCOL_CAPABILITY_COMMAND_INT, px4.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT,
                           px4.MAV_PROTOCOL_CAPABILITY_MISSION_INT):
            assert version.capabilities & capability
        mark = probe.mark()
        ack = probe.command(px4.MAV_CMD_REQUEST_MESSAGE, (float(mavlink.MAVLINK_MSG_ID_HOME_POSITION),))
        assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED
        home = probe.wait_for("HOME_POSITION", after=mark, timeout_s=2.0)
        assert home is not None and (home.latitude, home.longitude, home.altitude) == (473977420, 85455940, 488000)
        ack = probe.command(px4.MAV_CMD_REQUEST_MESSAGE, (12345.0,))
        assert ack is not None and ack.result != px4.MAV_RESULT_ACCEPTED


def test_set_message_interval(probe: Probe) -> None:
    """PX4's answers, measured on SITL: -1 stops a stream, 0 restores its default, HEARTBEAT and
    unknown messages FAILED; GET_MESSAGE_INTERVAL tells the configured interval (0: not streamed).
    In lockstep (the probe moves the vehicle's time; commands are answered at its barrier), so the
    rates are counted in simulated time whatever the machine's load."""
    with vehicle_for(probe, lockstep=True) as v:
        clock = Lockstep(probe)
        connect(probe)
        clock.barrier()
        interval = lambda msg_id, us, *extra: probe.command(px4.MAV_CMD_SET_MESSAGE_INTERVAL, (float(msg_id), us, *extra))  # noqa: E731
        assert interval(mavlink.MAVLINK_MSG_ID_ATTITUDE, -1.0).result == px4.MAV_RESULT_ACCEPTED
        assert interval(mavlink.MAVLINK_MSG_ID_SYS_STATUS, 125_000.0).result == px4.MAV_RESULT_ACCEPTED
        assert interval(mavlink.MAVLINK_MSG_ID_HEARTBEAT, 100_000.0).result == px4.MAV_RESULT_FAILED  # PX4 keeps 1 Hz
        t0 = v.snapshot().t_s + 0.2
        clock.run_for(2.5, lambda: None, period_s=0.1)
        assert 15 <= probe.count_between("SYS_STATUS", t0, t0 + 2.0) <= 17  # 8 Hz simulated (5 Hz by default)
        assert probe.count_between("ATTITUDE", t0, t0 + 2.0) == 0
        assert 1 <= probe.count_between("HEARTBEAT", t0, t0 + 2.0) <= 3
        mark = probe.mark()
        assert probe.command(px4.MAV_CMD_GET_MESSAGE_INTERVAL, (float(mavlink.MAVLINK_MSG_ID_ATTITUDE),)).result == \
            px4.MAV_RESULT_ACCEPTED
        reply = probe.wait_for("MESSAGE_INTERVAL", after=mark, timeout_s=1.0)
        assert reply is not None and (reply.message_id, reply.interval_us) == (mavlink.MAVLINK_MSG_ID_ATTITUDE, 0)
        assert interval(mavlink.MAVLINK_MSG_ID_ATTITUDE, 0.0).result == px4.MAV_RESULT_ACCEPTED  # default again
        mark = probe.mark()
        clock.run_for(0.1, lambda: None, period_s=0.02)
        assert probe.wait_for("ATTITUDE", after=mark, timeout_s=1.0) is not None
        mark = probe.mark()
        probe.command(px4.MAV_CMD_GET_MESSAGE_INTERVAL, (float(mavlink.MAVLINK_MSG_ID_ATTITUDE),))
        reply = probe.wait_for("MESSAGE_INTERVAL", after=mark, timeout_s=1.0)
        assert reply is not None and reply.interval_us == 10_000
        assert interval(12345, 1000.0).result == px4.MAV_RESULT_FAILED
        assert interval(mavlink.MAVLINK_MSG_ID_ALTITUDE, 1000.0, 1.0).result == px4.MAV_RESULT_FAILED  # param3 unsupported


def test_local_position_rate_up_to_what_px4_delivers(probe: Probe) -> None:
    """LOCAL_POSITION_NED asked at 50 Hz arrives at 50 Hz; asked at 500 Hz, at no more than PX4's
    125 Hz. Only the link that asked changes (the GCS link keeps 30 Hz). The rate is judged by the
    median interval between the samples' own stamps and an upper bound on their count: a vehicle
    behind wall time on a loaded machine skips what it missed, as PX4 does, so a count's lower
    bound measures the machine (a CI run counted 57 of 125 in a second), not the stream."""
    with Probe() as gcs, vehicle_for(probe, speed=1.0, gcs_target=f"127.0.0.1:{gcs.port}") as v:
        connect(probe)
        lpn = float(mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED)

        def stamps(p: Probe, t0: float) -> list[float]:
            return sorted(m.time_boot_ms / 1000.0 for m in p.messages("LOCAL_POSITION_NED")
                          if t0 <= m.time_boot_ms / 1000.0 < t0 + 1.0)

        def assert_rate(p: Probe, t0: float, hz: float) -> None:
            got = stamps(p, t0)
            assert 0.25 * hz <= len(got) <= hz + 1, (hz, len(got))  # streaming, never faster than asked
            median = statistics.median(b - a for a, b in zip(got, got[1:]))
            assert 0.8 / hz <= median <= 1.25 / hz + 0.001, (hz, median)  # the stamps' 1 ms resolution

        for interval_us, expected_hz in ((20_000.0, 50), (2_000.0, 125)):
            assert probe.command(px4.MAV_CMD_SET_MESSAGE_INTERVAL, (lpn, interval_us)).result == px4.MAV_RESULT_ACCEPTED
            t0 = v.clock.now() + 0.1
            wait_flight(v, lambda s: s.t_s > t0 + 1.1, 3.0, "s.t_s > t0 + 1.1")
            assert_rate(probe, t0, expected_hz)
            assert_rate(gcs, t0, 30)


def test_timesync_is_answered(probe: Probe) -> None:
    with vehicle_for(probe):
        connect(probe)
        mark = probe.mark()
        probe.send(mavlink.MAVLink_timesync_message(0, 123456789))
        reply = probe.wait_for("TIMESYNC", after=mark, timeout_s=2.0)
        assert reply is not None and reply.ts1 == 123456789 and reply.tc1 > 0


def test_onboard_streams_at_px4_rates_at_speed_1(probe: Probe) -> None:
    with vehicle_for(probe, speed=1.0) as v:
        connect(probe)
        wait_flight(v, lambda s: s.t_s > 1.2, 3.0, "s.t_s > 1.2")
    expected_ms = {"LOCAL_POSITION_NED": 1000 / 30, "ATTITUDE": 10, "ATTITUDE_QUATERNION": 20, "GLOBAL_POSITION_INT": 20,
                   "POSITION_TARGET_LOCAL_NED": 100, "ATTITUDE_TARGET": 100, "SYS_STATUS": 200, "EXTENDED_SYS_STATE": 200}
    for name, period_ms in expected_ms.items():
        stamps = [m.time_boot_ms if hasattr(m, "time_boot_ms") else None for m in probe.messages(name)]
        if stamps[0] is None:
            continue
        assert statistics.median(b - a for a, b in zip(stamps, stamps[1:])) == pytest.approx(period_ms, abs=5.1), name
    for name, period_us in (("ODOMETRY", 1e6 / 30), ("HIGHRES_IMU", 20_000)):
        stamps = [m.time_usec for m in probe.messages(name)]
        assert statistics.median(b - a for a, b in zip(stamps, stamps[1:])) == pytest.approx(period_us, abs=5100), name
    for name in ("ALTITUDE", "VFR_HUD", "GPS_GLOBAL_ORIGIN", "HOME_POSITION", "ESTIMATOR_STATUS"):
        assert probe.messages(name), name
    status = probe.latest("SYS_STATUS")
    for bits in (status.onboard_control_sensors_present, status.onboard_control_sensors_health):
        assert bits & px4.SENSOR_PREARM_CHECK and bits & px4.SYS_STATUS_EXTENSION_USED
    assert (status.voltage_battery, status.current_battery, status.battery_remaining) == (65535, -1, -1)


def test_stream_wall_rate_is_capped_at_high_speed(probe: Probe) -> None:
    with vehicle_for(probe, speed=20.0):
        connect(probe)
        heartbeats = probe.count_between("HEARTBEAT", 0.5, 20.5)
    stamps = [m.time_boot_ms for m in probe.messages("LOCAL_POSITION_NED")]
    # 30 Hz simulated would be 600 Hz wall; capped at 300 Hz wall = 15 Hz simulated
    assert statistics.median(b - a for a, b in zip(stamps, stamps[1:])) == pytest.approx(1000 * 20 / 300, abs=5.1)
    stamps = [m.time_boot_ms for m in probe.messages("ATTITUDE")]
    assert statistics.median(b - a for a, b in zip(stamps, stamps[1:])) == pytest.approx(1000 * 20 / 100, abs=5.1)
    # still 1 Hz simulated (lower bound loose: a vehicle behind wall time on a loaded machine skips
    # what it missed, as PX4 does; 1 s of wall time at speed 20 is 20 s of HEARTBEATs)
    assert 10 <= heartbeats <= 21


def test_global_position_consistent_with_local_ned(probe: Probe) -> None:
    with vehicle_for(probe, speed=20.0, start_ned=(100.0, -50.0, 0.0), estimate_error=0.0):  # the projection, to 0.02 m
        connect(probe)
        gpi = probe.wait_for("GLOBAL_POSITION_INT", timeout_s=2.0)
        assert gpi is not None
        north_m, east_m = geodesy.project(gpi.lat / 1e7, gpi.lon / 1e7, 47.397742, 8.545594)  # PX4's projection
        assert north_m == pytest.approx(100.0, abs=0.02)
        assert east_m == pytest.approx(-50.0, abs=0.02)
        assert gpi.alt == 488000 and gpi.relative_alt == 0


@pytest.mark.parametrize(("frame", "mask", "accepted"), [
    (px4.MAV_FRAME_LOCAL_NED, setpoints.TYPE_MASK_VELOCITY, True),
    (px4.MAV_FRAME_LOCAL_NED, setpoints.TYPE_MASK_VELOCITY_YAW, True),
    (px4.MAV_FRAME_BODY_NED, setpoints.TYPE_MASK_VELOCITY_YAW_RATE, True),
    (px4.MAV_FRAME_BODY_NED, setpoints.TYPE_MASK_VELOCITY, True),
    (px4.MAV_FRAME_LOCAL_NED, setpoints.TYPE_MASK_POSITION, True),
    (px4.MAV_FRAME_BODY_NED, setpoints.TYPE_MASK_POSITION, False),
    (9, setpoints.TYPE_MASK_VELOCITY, False),  # MAV_FRAME_BODY_OFFSET_NED: unsupported
    (px4.MAV_FRAME_LOCAL_NED, 0, True),  # everything used, as PX4 takes it
    (px4.MAV_FRAME_LOCAL_NED, 3072, True),  # position + velocity + acceleration feed-forward
    (px4.MAV_FRAME_BODY_NED, 3072, True),  # velocity + acceleration (a position has no body frame)
    (px4.MAV_FRAME_LOCAL_NED, 0x0FFF, False),  # nothing to control
    (px4.MAV_FRAME_LOCAL_NED, 3072 | 512, False),  # FORCE with an acceleration: "force not supported"
])
def test_setpoint_frames_and_type_masks(probe: Probe, frame: int, mask: int, accepted: bool) -> None:
    with vehicle_for(probe) as v:
        connect(probe)
        for _ in range(3):
            probe.send(probe.setpoint_message((1.0, 0.0, 0.0), mask, frame, position_ned_m=(1.0, 2.0, -3.0), yaw_rad=0.0,
                                              yaw_rate_rad_s=0.0, acceleration_ned_m_s2=(0.5, 0.0, 0.0)))
        wait_flight(v, lambda s: s.counters["setpoints_accepted"] + s.counters["setpoints_rejected"] == 3, 2.0, "s.counters['setpoints_accepted'] + s.counters['setpoints_rejected'] == 3")
        assert v.counters["setpoints_accepted"] == (3 if accepted else 0)
        result = probe.set_mode("OFFBOARD").result
        assert result == (px4.MAV_RESULT_ACCEPTED if accepted else px4.MAV_RESULT_TEMPORARILY_REJECTED)


def test_non_finite_velocity_setpoint_is_proof_of_life_and_holds(probe: Probe) -> None:
    """PX4 forwards a setpoint whose used fields are NaN or inf (it is proof of life); its
    position controller finds it invalid and stops ("Failsafe: stop and wait")."""
    with vehicle_for(probe, paced=True, speed=10.0, estimate_error=0.0) as v:  # exact: stopped to 0.01 m/s
        connect(probe)
        with start_offboard(probe, (1.0, 0.0, -1.0)) as stream:
            wait_flight(v, lambda s: s.position_ned_m[2] < -2.0, 3.0, "s.position_ned_m[2] < -2.0")
            stream.set(velocity_ned_m_s=(NAN, 0.0, 0.0))
            accepted = v.counters["setpoints_accepted"]
            t0 = v.snapshot().t_s
            snap = wait_flight(v, lambda s: s.t_s > t0 + 5.0, 3.0, "s.t_s > t0 + 5.0")
            assert snap is not None and snap.mode == "OFFBOARD" and not snap.in_failsafe
            assert snap.counters["setpoints_accepted"] > accepted and snap.counters["setpoints_rejected"] == 0
            assert np.linalg.norm(snap.velocity_ned_m_s) < 0.2
            stream.set(velocity_ned_m_s=(math.inf, 0.0, 0.0))
            later = wait_flight(v, lambda s: s.t_s > snap.t_s + 2.0, 3.0, "s.t_s > snap.t_s + 2.0")
            assert later is not None and later.mode == "OFFBOARD" and np.linalg.norm(later.velocity_ned_m_s) < 0.2


@pytest.mark.parametrize(("mask", "frame", "text"), [
    (3072 | 512, px4.MAV_FRAME_LOCAL_NED, "force not supported"),
    (0x0FFF, px4.MAV_FRAME_LOCAL_NED, "SET_POSITION_TARGET_LOCAL_NED invalid"),
    (setpoints.TYPE_MASK_VELOCITY, 9, "coordinate frame 9"),  # (the text is longer than one STATUSTEXT chunk)
])
def test_dropped_setpoint_is_not_proof_of_life_and_says_why(probe: Probe, mask: int, frame: int, text: str) -> None:
    with vehicle_for(probe, paced=True, speed=10.0) as v:
        connect(probe)
        with start_offboard(probe, (0.0, 0.0, -1.0)) as stream:
            wait_flight(v, lambda s: s.position_ned_m[2] < -2.0, 3.0, "s.position_ned_m[2] < -2.0")
            stream.set(type_mask=mask, frame=frame, velocity_ned_m_s=(1.0, 0.0, 0.0), acceleration_ned_m_s2=(0.5, 0.0, 0.0))
            msg = probe.wait_for("STATUSTEXT", lambda m: text in m.text, 2.0)
            assert msg is not None and msg.severity == px4.MAV_SEVERITY_CRITICAL
            wait_flight(v, lambda s: s.mode == "POSCTL" and s.in_failsafe, 3.0, "s.mode == 'POSCTL' and s.in_failsafe")  # the stream is lost: offboard loss
        counters = v.counters
        assert counters["setpoints_rejected"] >= 5
        # said at most once a second, not for every dropped message
        assert len([m for m in probe.messages("STATUSTEXT") if text in m.text]) <= 3


def test_sends_to_target_from_startup_then_latches_on_first_peer(probe: Probe) -> None:
    with Probe() as first_listener, MockVehicle(VehicleOptions(target=f"127.0.0.1:{first_listener.port}", speed=10.0)) as v:
        assert first_listener.wait_for("HEARTBEAT", timeout_s=2.0)  # talks first, before anyone speaks
        probe.vehicle = ("127.0.0.1", v.port)
        probe.heartbeat()
        assert probe.wait_for("HEARTBEAT", timeout_s=2.0) is not None
        mark = first_listener.mark()
        with Probe(vehicle=("127.0.0.1", v.port)) as second:
            second.heartbeat()
            assert second.wait_for("HEARTBEAT", timeout_s=0.3) is None  # latched on the first peer
        assert first_listener.wait_for("HEARTBEAT", after=mark, timeout_s=0.3) is None


def test_gcs_link_gets_heartbeats_too(probe: Probe) -> None:
    with Probe() as gcs, vehicle_for(probe, gcs_target=f"127.0.0.1:{gcs.port}") as v:
        assert probe.wait_for("HEARTBEAT", timeout_s=2.0) and gcs.wait_for("HEARTBEAT", timeout_s=2.0)
        assert v.gcs_port is not None and v.gcs_port != v.port
        gcs.heartbeat()
        ack = gcs.command(px4.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,))
        assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED  # answered on the GCS link


def test_statustext_only_after_peer_heartbeat(probe: Probe) -> None:
    with vehicle_for(probe) as v:
        assert probe.wait_for("HEARTBEAT", timeout_s=2.0)
        assert probe.set_mode("OFFBOARD").result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        assert v.events() and probe.wait_for("STATUSTEXT", timeout_s=0.3) is None
        probe.heartbeat()
        assert probe.set_mode("OFFBOARD").result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        assert probe.wait_for("STATUSTEXT", timeout_s=2.0) is not None


def test_cli_process_reports_port_and_stops_cleanly_on_sigterm(probe: Probe) -> None:
    args = ["--mavlink", "udpin:127.0.0.1:0", "--target", f"udpout:127.0.0.1:{probe.port}", "--speed", "10",
            "--param", "COM_OF_LOSS_T=0.5", "--status-every", "0.1"]
    process, port = spawn_process(args, stderr=subprocess.PIPE)
    try:
        assert probe.wait_for("HEARTBEAT", timeout_s=5.0) is not None
        assert probe.vehicle == ("127.0.0.1", port)
        mark = probe.mark()
        probe.send(mavlink.MAVLink_param_request_read_message(1, 1, b"COM_OF_LOSS_T", -1))
        reply = probe.wait_for("PARAM_VALUE", after=mark, timeout_s=2.0)
        assert reply is not None and reply.param_value == 0.5
        connect(probe)
        with start_offboard(probe, (0.0, 0.0, -1.0)):
            assert probe.wait_mode("OFFBOARD", 2.0)
    finally:
        process.send_signal(signal.SIGTERM)
        try:
            _, stderr = process.communicate(timeout=10)
        finally:
            if process.poll() is None:  # a vehicle that did not stop fails here, and is not left behind
                process.kill()
                process.communicate()
    assert process.returncode == 0
    assert b"OFFBOARD" in stderr and b"rx=" in stderr  # the status line


@pytest.mark.parametrize(("text", "scheme", "address"), [
    ("127.0.0.1:14580", "udpin", ("127.0.0.1", 14580)),
    ("udpin:0.0.0.0:14580", "udpin", ("0.0.0.0", 14580)),
    ("udp://127.0.0.1:0", "udpin", ("127.0.0.1", 0)),
    ("udpout:127.0.0.1:14540", "udpout", ("127.0.0.1", 14540)),
    ("udpout://10.0.0.2:14550", "udpout", ("10.0.0.2", 14550)),
    (":14540", "udpin", ("127.0.0.1", 14540)),
])
def test_endpoint_url_forms(text: str, scheme: str, address: tuple[str, int]) -> None:
    endpoint = parse_endpoint(text)
    assert (endpoint.scheme, endpoint.address) == (scheme, address)


@pytest.mark.parametrize("text", ["tcp:127.0.0.1:5760", "127.0.0.1", "udpin:host:port", "udp:1.2.3.4:70000"])
def test_bad_endpoints_are_refused(text: str) -> None:
    with pytest.raises(ValueError):
        parse_endpoint(text)


def test_cli_help_explains_every_option() -> None:
    result = CliRunner().invoke(mock_vehicle, ["--help"])
    assert result.exit_code == 0
    for param in mock_vehicle.params:
        assert param.help, param.name  # type: ignore[attr-defined]
        assert param.opts[0] in result.output


def test_signing_key_file_hex_or_raw(tmp_path: Path) -> None:
    key = bytes(range(32))
    (tmp_path / "hex").write_text(key.hex() + "\n")
    (tmp_path / "raw").write_bytes(key)
    (tmp_path / "bad").write_text("abc")
    assert signing_key_option(tmp_path / "hex") == key == signing_key_option(tmp_path / "raw")
    with pytest.raises(click.BadParameter):
        signing_key_option(tmp_path / "bad")
