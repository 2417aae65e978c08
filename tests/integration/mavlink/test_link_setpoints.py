"""Setpoints and the telemetry rate request on the wire (VehicleLink against a PX4-like peer and
the mock vehicle)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.core.setpoint import Setpoint
from mission.mavlink import px4
from mission.time.clock import ManualClock, ScaledClock
from mission.errors import CommandRejected
from mission.mavlink.link import VehicleLink
from sim.net import wait_for as eventually
from sim.vehicle.mock import MockVehicle, VehicleOptions
from sim.testing.fake_px4 import FakePx4 as Px4Peer

ANY_PORT = "udpin:127.0.0.1:0"


def test_full_setpoint_encoding_never_sets_the_force_bit() -> None:
    clock = ManualClock(3.5)
    with VehicleLink(ANY_PORT, clock) as link, Px4Peer(link.port) as peer:
        link.wait_vehicle(5.0)
        link.send(Setpoint.triple(np.array([1.0, 2.0, -3.0]), np.array([0.5, -0.25, 0.0]), np.array([0.1, 0.2, -0.3])))
        (msg,) = eventually(lambda: peer.received("SET_POSITION_TARGET_LOCAL_NED"), what="one setpoint")
        assert msg.type_mask == 3072 and not msg.type_mask & 512  # 512 is *force*: PX4 drops those
        assert msg.coordinate_frame == px4.MAV_FRAME_LOCAL_NED and msg.time_boot_ms == 3500
        assert (msg.x, msg.y, msg.z) == (1.0, 2.0, -3.0)
        assert (msg.vx, msg.vy, msg.vz) == (0.5, -0.25, 0.0)
        assert (msg.afx, msg.afy, msg.afz) == pytest.approx((0.1, 0.2, -0.3))
        with pytest.raises(ValueError, match="acceleration"):
            link.send(Setpoint.triple(np.zeros(3), np.zeros(3), np.array([0.0, math.nan, 0.0])))
        with pytest.raises(ValueError, match="position"):
            link.send(Setpoint.triple(np.zeros(2), np.zeros(3), np.zeros(3)))
        assert link.counters.tx_setpoints == 1


def test_the_mock_vehicle_reads_every_kind_the_link_sends() -> None:
    """Each kind of setpoint, sent by the link over UDP, is what the mock vehicle accepted (its
    decoder and the link's encoder are one module): the setpoint's fields, NaN where absent."""
    p, v, a = np.array([1.0, 2.0, -3.0]), np.array([0.5, -0.25, 0.0]), np.array([0.125, 0.25, -0.375])
    kinds = [Setpoint.velocity_only(v), Setpoint.velocity_only(v, yaw_rad=0.75), Setpoint.triple(p, v, a),
             Setpoint.triple(p, v, a, yaw_rad=-1.5), Setpoint.hold_still()]
    nan3 = (math.nan,) * 3
    with VehicleLink(ANY_PORT, ScaledClock(10.0)) as link, \
            MockVehicle(VehicleOptions(bind="127.0.0.1:0", target=f"127.0.0.1:{link.port}", speed=10.0)) as vehicle:
        link.wait_vehicle(20.0)
        for n, sp in enumerate(kinds, start=1):
            link.send(sp)
            got = eventually(vehicle.when(lambda s: s.counters["setpoints_accepted"] == n), what=f"setpoint {n}").setpoint
            assert got is not None
            np.testing.assert_array_equal(got.velocity, sp.velocity_ned_m_s)
            np.testing.assert_array_equal(got.position, nan3 if sp.position_ned_m is None else sp.position_ned_m)
            np.testing.assert_array_equal(got.acceleration, nan3 if sp.acceleration_ned_m_s2 is None else sp.acceleration_ned_m_s2)
            assert got.yaw_rad == sp.yaw_rad and got.yaw_rate_rad_s is None
        assert vehicle.counters["setpoints_rejected"] == 0


def test_message_interval_request_and_the_rate_that_arrives() -> None:
    with VehicleLink(ANY_PORT, ScaledClock(1.0)) as link, Px4Peer(link.port, position_hz=50.0) as peer:
        link.wait_vehicle(5.0)
        link.set_message_interval(32, 50.0)
        cmd = [m for m in peer.received("COMMAND_LONG") if m.command == px4.MAV_CMD_SET_MESSAGE_INTERVAL][-1]
        assert (cmd.param1, cmd.param2) == (32.0, pytest.approx(20000.0))
        eventually(lambda: link.message_rate_hz(window_s=0.5) > 35.0, 5.0, "about 50 Hz of LOCAL_POSITION_NED")
        peer.on_command = lambda p, m: p.ack(m, px4.MAV_RESULT_UNSUPPORTED)
        with pytest.raises(CommandRejected):  # the caller carries on at the vehicle's own rate
            link.set_message_interval(32, 50.0, retries=0)
