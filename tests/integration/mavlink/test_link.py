"""VehicleLink against a real pymavlink PX4-like peer over real loopback sockets: identity, state,
commands, setpoints, robustness (tlog, transports and signing: test_link_transports.py).

Every test binds ephemeral ports, waits on conditions with deadlines, and checks that the
link's threads and sockets are gone afterwards.
"""
from __future__ import annotations

import dataclasses
import math
import socket
import struct

import numpy as np
import pytest

from mission.core import geodesy
from mission.core.setpoint import Setpoint
from mission.mavlink import px4
from mission.time.clock import ManualClock, ScaledClock
from mission.errors import CommandRejected, LinkError, LinkTimeout
from mission.mavlink.link import VehicleLink, VehicleState
from mission.mavlink.env import mavlink
from sim.testing.fake_px4 import FakePx4 as Px4Peer
from sim.net import wait_for as eventually
from tests.integration.mavlink.conftest import ANY_PORT, link_threads
from tests.integration.mavlink.conftest import connected as _connected


# ------------------------------------------------------------------------------ identity, state


def test_identifies_px4_and_snapshots_state() -> None:
    # With a ManualClock, link deadlines never pass by themselves: every wait here must succeed.
    clock = ManualClock(5.0)
    with VehicleLink(ANY_PORT, clock) as link, Px4Peer(link.port, position_ned_m=(1.0, 2.0, -3.0)) as peer:
        peer.armed, peer.custom_mode = True, px4.custom_mode_of("OFFBOARD")
        first = link.wait_vehicle(timeout_s=5.0)  # adopted after 3 HEARTBEATs; nothing before counts
        peer.send(mavlink.MAVLink_extended_sys_state_message(0, px4.LANDED_IN_AIR))
        peer.send(mavlink.MAVLink_gps_global_origin_message(473977418, 85455939, 488000, 0))
        ahrs = mavlink.MAV_SYS_STATUS_AHRS
        peer.send(mavlink.MAVLink_sys_status_message(ahrs, ahrs, ahrs, 0, 65535, -1, -1, 0, 0, 0, 0, 0, 0))
        assert (first.system_id, first.component_id) == (1, 1)
        assert link.vehicle_id == (1, 1)
        s = link.wait_until(
            lambda s: s.mode == "OFFBOARD" and s.origin is not None and s.landed_state is not None
            and s.position_ned_m is not None, 5.0)
        assert isinstance(s, VehicleState)
        assert s.t_s == 5.0 and s.position_rx_s == 5.0 and s.heartbeat_rx_s == 5.0
        np.testing.assert_allclose(s.position_ned_m, [1.0, 2.0, -3.0], rtol=1e-6)
        np.testing.assert_allclose(s.velocity_ned_m_s, [0.1, 0.2, 0.3], rtol=1e-6)
        assert s.armed and s.system_status == px4.MAV_STATE_ACTIVE
        assert s.custom_mode == 0x00060000 and s.base_mode == 129
        assert s.landed_state == px4.LANDED_IN_AIR
        assert s.origin == pytest.approx((47.3977418, 8.5455939, 488.0))
        assert s.position_valid
        # snapshots are immutable
        with pytest.raises(dataclasses.FrozenInstanceError):
            s.armed = False  # type: ignore[misc]
        with pytest.raises(ValueError):
            s.position_ned_m[0] = 9.0  # type: ignore[index]
        # position goes stale when the stream stops (and only then)
        peer.position_hz = 0.0
        peer.statustext("marker", severity=6)  # after the last LOCAL_POSITION_NED on the same socket
        link.wait_until(lambda s: s.last_statustext == "marker", 5.0)
        clock.advance(0.4)
        assert link.state.position_valid and link.state.position_age_s == pytest.approx(0.4)
        clock.advance(0.2)
        stale = link.state
        assert not stale.position_valid and stale.position_ned_m is not None
        # an unhealthy estimator invalidates a fresh position
        peer.position_hz = 50.0
        link.wait_until(lambda s: s.position_rx_s is not None and s.position_rx_s > 5.5, 5.0)
        assert link.state.position_valid
        peer.send(mavlink.MAVLink_sys_status_message(ahrs, ahrs, 0, 0, 65535, -1, -1, 0, 0, 0, 0, 0, 0))
        link.wait_until(lambda s: not s.position_valid, 5.0)


def test_heartbeat_age_and_liveness_follow_the_clock() -> None:
    clock = ManualClock(0.0)
    with VehicleLink(ANY_PORT, clock, heartbeat_timeout_s=3.0) as link:
        assert link.heartbeat_age_s() == math.inf and not link.vehicle_alive()
        assert link.state.mode == "" and link.state.position_ned_m is None and not link.state.position_valid
        with Px4Peer(link.port):
            link.wait_vehicle(5.0)
        clock.advance(2.5)
        assert link.heartbeat_age_s() == pytest.approx(2.5) and link.vehicle_alive()
        clock.advance(1.0)
        assert not link.vehicle_alive()


def test_sends_its_own_heartbeat_as_onboard_controller() -> None:
    with VehicleLink(ANY_PORT, ScaledClock(20.0)) as link, Px4Peer(link.port) as peer:
        link.wait_vehicle(5.0)
        beats = eventually(lambda: len(peer.received("HEARTBEAT")) >= 3 and peer.received("HEARTBEAT"), what="3 heartbeats")
        for hb in beats:
            assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 191)
            assert hb.type == px4.MAV_TYPE_ONBOARD_CONTROLLER and hb.autopilot == 8
        # the counter moves just after the datagram leaves: wait on it, it may trail the peer's count
        eventually(lambda: link.counters.tx_heartbeats >= 3, what="3 heartbeats counted as sent")


def test_vehicle_hears_our_heartbeat_before_any_command(link: VehicleLink) -> None:
    """PX4 sends STATUSTEXT (refusal reasons) only to a peer that sent a HEARTBEAT."""
    with _connected(link, heartbeat_hz=2.0) as peer:
        link.wait_vehicle(5.0)
        assert link.command_long(px4.MAV_CMD_REQUEST_MESSAGE, 148.0) == 0
        first = peer.received()[0]
        assert first.get_type() == "HEARTBEAT" and first.get_seq() == 0


def test_rogue_system_on_the_same_port_is_counted_and_ignored(link: VehicleLink) -> None:
    with Px4Peer(link.port, sysid=1, position_ned_m=(1.0, 2.0, -3.0)) as vehicle:
        link.wait_vehicle(5.0)
        with Px4Peer(link.port, sysid=42, position_ned_m=(100.0, 100.0, -100.0)) as rogue:
            rogue.armed, rogue.custom_mode = True, px4.custom_mode_of("OFFBOARD")
            eventually(lambda: link.counters.rejected_foreign >= 20, what="rogue packets counted")
            link.command_long(px4.MAV_CMD_REQUEST_MESSAGE, 148.0)
            link.send(Setpoint.velocity_only(np.array([0.5, 0.0, 0.0])))
            eventually(lambda: vehicle.received("SET_POSITION_TARGET_LOCAL_NED"), what="setpoint at vehicle")
            s = link.state
            np.testing.assert_allclose(s.position_ned_m, [1.0, 2.0, -3.0], rtol=1e-6)
            assert s.system_id == 1 and not s.armed and s.mode == "AUTO.LOITER"
            # the link answers only the vehicle's address: the rogue hears nothing at all
            assert rogue.received() == []
            # and with target_system unset, a second PX4 autopilot makes the vehicle ambiguous
            problem = link.identity_problem()
            assert problem is not None and "sysid 42 compid 1" in problem
        assert len(vehicle.received("COMMAND_LONG")) == 1


def test_a_lone_rogue_is_adopted_with_a_warning_and_refused_once_the_real_vehicle_talks(
        link: VehicleLink, caplog: pytest.LogCaptureFixture) -> None:
    """mavlink.target_system unset and a rogue PX4 (sysid 42) talks alone first: it is adopted, and
    the log says so as a warning; the real vehicle's first HEARTBEAT then makes the link report an
    identity problem (the mission aborts vehicle_ambiguous), and the real vehicle is never answered."""
    import logging

    caplog.set_level(logging.WARNING, logger="mission.mavlink.link")
    with Px4Peer(link.port, sysid=42, heartbeat_hz=5.0) as rogue:
        assert link.wait_vehicle(5.0).system_id == 42
        assert "WITHOUT mavlink.target_system" in caplog.text and link.identity_problem() is None
        with Px4Peer(link.port, sysid=1) as vehicle:
            eventually(lambda: link.identity_problem() is not None, what="the second autopilot noticed")
            problem = link.identity_problem()
            assert "sysid 1 compid 1" in problem and "set mavlink.target_system" in problem  # type: ignore[operator]
            # we only ever speak to the adopted one (its first GCS HEARTBEAT may come after the notice)
            eventually(lambda: bool(rogue.received()), what="the link speaking to the adopted vehicle")
            assert vehicle.received() == []


def test_target_system_selects_the_vehicle_among_several() -> None:
    with VehicleLink(ANY_PORT, ScaledClock(1.0), target_system=42) as link:
        with Px4Peer(link.port, sysid=1) as other:
            eventually(lambda: link.counters.rx_ignored >= 5, what="packets of sysid 1 ignored")
            assert link.vehicle_id is None
            with Px4Peer(link.port, sysid=42, position_ned_m=(7.0, 8.0, -9.0)):
                s = link.wait_vehicle(5.0)
                assert s.system_id == 42
                s = link.wait_until(lambda s: s.position_ned_m is not None, 5.0)
                np.testing.assert_allclose(s.position_ned_m, [7.0, 8.0, -9.0], rtol=1e-6)
                eventually(lambda: link.counters.rejected_foreign >= 5, what="sysid 1 now foreign")
        assert other.received() == []  # the link never answered the system it was not told to fly


@pytest.mark.parametrize(("autopilot", "mav_type"), [(3, 2), (12, 6)], ids=["ardupilot", "px4-gcs-type"])
def test_non_px4_autopilot_heartbeat_is_not_a_vehicle(link: VehicleLink, autopilot: int, mav_type: int) -> None:
    with Px4Peer(link.port, autopilot=autopilot, mav_type=mav_type):
        eventually(lambda: link.counters.rx_ignored >= 10, what="heartbeats ignored")
        with pytest.raises(LinkTimeout):
            link.wait_vehicle(timeout_s=0.2)
        assert link.vehicle_id is None


# ------------------------------------------------------------------------------ commands


def test_command_retried_until_acknowledged(link: VehicleLink) -> None:
    with _connected(link) as peer:
        link.wait_vehicle(5.0)
        seen: list[int] = []

        def drop_first(p: Px4Peer, msg: object) -> None:
            seen.append(msg.confirmation)  # type: ignore[attr-defined]
            if len(seen) > 1:
                p.ack(msg, px4.MAV_RESULT_ACCEPTED)

        peer.on_command = drop_first
        assert link.command_long(px4.MAV_CMD_REQUEST_MESSAGE, 148.0, timeout_s=0.2, retries=3) == 0
        assert seen == [0, 1]
        c = link.counters
        assert (c.tx_commands, c.command_retries, c.command_timeouts) == (2, 1, 0)
        cmd = peer.received("COMMAND_LONG")[-1]
        assert (cmd.target_system, cmd.target_component, cmd.command, cmd.param1) == (1, 1, 512, 148.0)


def test_command_times_out_after_all_retries(link: VehicleLink) -> None:
    with _connected(link) as peer:
        link.wait_vehicle(5.0)
        peer.on_command = Px4Peer.silent
        with pytest.raises(LinkTimeout, match="no COMMAND_ACK for command 512 after 3 attempts"):
            link.command_long(px4.MAV_CMD_REQUEST_MESSAGE, 148.0, timeout_s=0.1, retries=2)
        eventually(lambda: len(peer.received("COMMAND_LONG")) == 3, what="3 attempts at the peer")
        assert [m.confirmation for m in peer.received("COMMAND_LONG")] == [0, 1, 2]
        c = link.counters
        assert (c.tx_commands, c.command_retries, c.command_timeouts) == (3, 2, 1)


@pytest.mark.parametrize("text_after_ack", [False, True], ids=["text-before-ack", "text-after-ack"])
def test_rejected_command_carries_the_statustext_reason(link: VehicleLink, text_after_ack: bool) -> None:
    reason = "Arming denied: Resolve system health failures first"
    with _connected(link) as peer:
        link.wait_vehicle(5.0)

        def deny(p: Px4Peer, msg: object) -> None:
            if not text_after_ack:
                p.long_statustext(reason + "\t", severity=2)  # 52 characters: two chunks
            p.ack(msg, px4.MAV_RESULT_TEMPORARILY_REJECTED)
            if text_after_ack:
                p.long_statustext(reason + "\t", severity=2)

        peer.on_command = deny
        with pytest.raises(CommandRejected) as info:
            link.arm(timeout_s=0.3, retries=0)
        assert info.value.command == px4.MAV_CMD_COMPONENT_ARM_DISARM
        assert info.value.result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        assert info.value.reason == reason
        assert isinstance(info.value, LinkError)
        assert link.counters.command_rejections == 1
        assert link.statustexts[-1][1:] == (2, reason)


def test_arm_and_disarm_are_confirmed_by_heartbeat(link: VehicleLink) -> None:
    with _connected(link) as peer:
        link.wait_vehicle(5.0)
        link.arm()
        assert link.state.armed
        link.disarm(force=True)
        assert not link.state.armed
        arm_cmd, disarm_cmd = peer.received("COMMAND_LONG")[-2:]
        assert (arm_cmd.param1, arm_cmd.param2) == (1.0, 0.0)
        assert (disarm_cmd.param1, disarm_cmd.param2) == (0.0, float(px4.ARM_FORCE_MAGIC))


def test_set_mode_is_confirmed_by_heartbeat(link: VehicleLink) -> None:
    with _connected(link) as peer:
        link.wait_vehicle(5.0)
        link.set_mode("OFFBOARD")
        assert link.state.mode == "OFFBOARD"
        cmd = peer.received("COMMAND_LONG")[-1]
        assert (cmd.command, cmd.param1, cmd.param2, cmd.param3) == (176, 1.0, 6.0, 0.0)
        link.hold()
        assert link.state.mode == "AUTO.LOITER"
        link.land()
        assert link.state.mode == "AUTO.LAND"
        cmd = peer.received("COMMAND_LONG")[-1]
        assert (cmd.param2, cmd.param3) == (4.0, 6.0)
        with pytest.raises(ValueError):
            link.set_mode("SPORT")


def test_set_mode_double_ack_second_rejection_wins(link: VehicleLink) -> None:
    """PX4 2025: ACCEPTED from the MAVLink layer, then the real TEMPORARILY_REJECTED."""
    with _connected(link) as peer:
        link.wait_vehicle(5.0)

        def double_ack(p: Px4Peer, msg: object) -> None:
            p.ack(msg, px4.MAV_RESULT_ACCEPTED)
            p.statustext("Offboard: no valid setpoint", severity=4)
            p.ack(msg, px4.MAV_RESULT_TEMPORARILY_REJECTED)

        peer.on_command = double_ack
        with pytest.raises(CommandRejected) as info:
            link.set_mode("OFFBOARD", confirm_timeout_s=2.0)
        assert info.value.result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        assert info.value.reason == "Offboard: no valid setpoint"
        assert link.state.mode == "AUTO.LOITER"


def test_set_mode_accepted_but_never_shown_times_out(link: VehicleLink) -> None:
    with _connected(link) as peer:
        link.wait_vehicle(5.0)
        peer.on_command = lambda p, msg: p.ack(msg, px4.MAV_RESULT_ACCEPTED)
        with pytest.raises(LinkTimeout, match="not confirmed by HEARTBEAT"):
            link.set_mode("OFFBOARD", confirm_timeout_s=0.3)


def test_takeoff_altitude_is_converted_to_amsl(link: VehicleLink) -> None:
    with _connected(link) as peer:
        link.wait_vehicle(5.0)
        with pytest.raises(LinkError, match="origin"):
            link.takeoff(5.0)
        peer.send(mavlink.MAVLink_gps_global_origin_message(473977418, 85455939, 488000, 0))
        link.wait_until(lambda s: s.origin is not None, 5.0)
        assert link.takeoff(5.0) == 0
        cmd = peer.received("COMMAND_LONG")[-1]
        assert cmd.command == px4.MAV_CMD_NAV_TAKEOFF and cmd.param7 == pytest.approx(493.0)
        assert math.isnan(cmd.param5) and math.isnan(cmd.param6)


# ------------------------------------------------------------------------------ setpoints


def test_velocity_setpoint_encoding() -> None:
    clock = ManualClock(12.345)
    with VehicleLink(ANY_PORT, clock) as link, Px4Peer(link.port) as peer:
        link.wait_vehicle(5.0)
        link.send(Setpoint.velocity_only(np.array([1.5, -2.0, 0.25])))
        link.send(Setpoint.velocity_only(np.array([0.0, 1.0, -0.5]), yaw_rad=0.75))
        first, second = eventually(lambda: len(peer.received("SET_POSITION_TARGET_LOCAL_NED")) == 2
                                   and peer.received("SET_POSITION_TARGET_LOCAL_NED"), what="2 setpoints")
        assert first.time_boot_ms == 12345
        assert (first.target_system, first.target_component, first.coordinate_frame) == (1, 1, 1)
        assert first.type_mask == 3527 and (first.vx, first.vy, first.vz) == (1.5, -2.0, 0.25)
        assert second.type_mask == 2503 and second.yaw == pytest.approx(0.75)
        assert (second.vx, second.vy, second.vz) == (0.0, 1.0, -0.5)
        assert link.counters.tx_setpoints == 2


@pytest.mark.parametrize(
    ("velocity", "yaw"),
    [([math.nan, 0, 0], None), ([0, math.inf, 0], None), ([0, 0, -math.inf], None), ([1e39, 0, 0], None),
     ([0, 0, 0], math.nan), ([0, 0, 0], math.inf), ([1, 2], None), ([[1, 2, 3]], None)],
    ids=["nan", "inf", "-inf", "float32-overflow", "yaw-nan", "yaw-inf", "short", "2d"],
)
def test_nonfinite_or_malformed_setpoint_is_refused(link: VehicleLink, velocity: list, yaw: float | None) -> None:
    with _connected(link) as peer:
        link.wait_vehicle(5.0)
        with pytest.raises(ValueError):
            link.send(Setpoint.velocity_only(np.array(velocity, dtype=float), yaw_rad=yaw))
        link.send(Setpoint.hold_still())  # a marker that does get through
        got = eventually(lambda: peer.received("SET_POSITION_TARGET_LOCAL_NED"), what="marker setpoint")
        assert len(got) == 1 and (got[0].vx, got[0].vy, got[0].vz) == (0.0, 0.0, 0.0)
        assert link.counters.tx_setpoints == 1


def test_no_background_resend_of_setpoints() -> None:
    with VehicleLink(ANY_PORT, ScaledClock(20.0)) as link, Px4Peer(link.port) as peer:
        link.wait_vehicle(5.0)
        link.send(Setpoint.velocity_only(np.array([1.0, 0.0, 0.0])))
        beats = len(peer.received("HEARTBEAT"))
        eventually(lambda: len(peer.received("HEARTBEAT")) >= beats + 4, what="4 more heartbeats")
        assert len(peer.received("SET_POSITION_TARGET_LOCAL_NED")) == 1


def test_setpoints_and_commands_need_an_open_link_and_a_vehicle(link: VehicleLink) -> None:
    with pytest.raises(LinkError, match="no vehicle identified"):
        link.send(Setpoint.hold_still())
    with pytest.raises(LinkError, match="no vehicle identified"):
        link.arm()
    closed = VehicleLink(ANY_PORT, ScaledClock(1.0))
    with pytest.raises(LinkError, match="not open"):
        closed.send(Setpoint.hold_still())
    with pytest.raises(LinkTimeout, match="PX4 autopilot HEARTBEAT"):
        link.wait_vehicle(timeout_s=0.1)


# ------------------------------------------------------------------------------ robustness


def _v2_packet(msg_id: int, payload: bytes, sysid: int = 1, compid: int = 1, crc: int = 0) -> bytes:
    header = struct.pack("<BBBBBBBHB", 253, len(payload), 0, 0, 0, sysid, compid, msg_id & 0xFFFF, msg_id >> 16)
    return header + payload + struct.pack("<H", crc)


def test_garbage_is_counted_and_the_receiver_survives(link: VehicleLink) -> None:
    with _connected(link) as peer:
        link.wait_vehicle(5.0)
        good = mavlink.MAVLink_heartbeat_message(2, 12, 29, 0, 3, 3).pack(mavlink.MAVLink(None, 1, 1))
        bad_crc = bytearray(good)
        bad_crc[-1] ^= 0xFF
        junk = [
            bytes(range(7, 107)),                               # no magic at all
            b"\xfd\xc8\x00\x00\x00\x01\x01\x00\x00\x00" + b"\x01" * 20,  # header promising 200 bytes
            bytes(bad_crc),                                     # CRC error
            b"\xfd",                                            # a lone magic byte
        ]
        for data in junk:
            peer.send_raw(data)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stranger:
            stranger.sendto(bytes(200), ("127.0.0.1", link.port))
        peer.send_raw(_v2_packet(410, b"\x01\x02\x03"))        # valid frame, id unknown to the dialect
        peer.statustext("after the garbage", severity=6)
        link.wait_until(lambda s: s.last_statustext == "after the garbage", 5.0)
        c = link.counters
        assert c.rx_bad >= 5 and c.rx_unknown == 1 and c.rx_errors == 0
        t0 = link.wait_until(lambda s: s.position_rx_s is not None, 5.0).position_rx_s
        link.wait_until(lambda s: s.position_rx_s is not None and s.position_rx_s > t0, 5.0)
        assert all(t.is_alive() for t in link_threads() if t.name.startswith("marsupial-link-rx"))


def test_chunked_statustext_is_reassembled(link: VehicleLink) -> None:
    with _connected(link) as peer:
        link.wait_vehicle(5.0)
        head = "Preflight Fail: ekf2 missing data; please check the " [:50]
        assert len(head) == 50
        peer.statustext(head, severity=3, text_id=7, chunk_seq=0)
        peer.statustext("sensors\t", severity=3, text_id=7, chunk_seq=1)
        link.wait_until(lambda s: s.last_statustext.endswith("sensors"), 5.0)
        assert link.statustexts[-1][1:] == (3, head + "sensors")


def test_set_home_asks_for_the_origin_px4_sends_only_when_it_is_set() -> None:
    """PX4 sends GPS_GLOBAL_ORIGIN once, when its EKF origin is set (a PX4 SITL: none in 10 s after):
    a link that came later asks for it (REQUEST_MESSAGE), then places the home through it as
    COMMAND_INT (x, y in degrees x 1e7)."""
    def answer(fake: Px4Peer, msg) -> None:
        if msg.command == mavlink.MAV_CMD_REQUEST_MESSAGE and round(msg.param1) == mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN:
            fake.ack(msg, mavlink.MAV_RESULT_ACCEPTED)
            fake.send(mavlink.MAVLink_gps_global_origin_message(473977418, 85455939, 488000, 0))
    with VehicleLink(ANY_PORT, ScaledClock(1.0)) as link, Px4Peer(link.port) as peer:
        peer.on_command = answer
        link.wait_vehicle(timeout_s=5.0)
        assert link.state.origin is None
        with pytest.raises(LinkTimeout):  # the fake answers no COMMAND_INT
            link.set_home(np.array([10.0, -20.0, 1.0]), timeout_s=0.3)
        assert link.state.origin == pytest.approx((47.3977418, 8.5455939, 488.0))
        sent = [m for m in peer.received("COMMAND_INT") if m.command == mavlink.MAV_CMD_DO_SET_HOME]
        assert len(sent) == 1 and sent[0].frame == mavlink.MAV_FRAME_GLOBAL and sent[0].param1 == 0.0
        lat, lon = geodesy.reproject(10.0, -20.0, 47.3977418, 8.5455939)
        assert (sent[0].x, sent[0].y) == (round(lat * 1e7), round(lon * 1e7)) and sent[0].z == pytest.approx(487.0)
