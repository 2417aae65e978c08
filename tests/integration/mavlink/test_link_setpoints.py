"""Full setpoints and the telemetry rate request on the wire (VehicleLink against a PX4-like peer)."""
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
