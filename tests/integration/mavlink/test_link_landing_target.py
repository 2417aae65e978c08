"""LANDING_TARGET on the wire: the link's bytes as PX4's C decoder lays them out, and the mock
vehicle accepting and refusing them by PX4's rule (VehicleLink over UDP)."""
from __future__ import annotations

import math
import struct

import pytest

from mission.mavlink import px4
from mission.mavlink.env import mavlink
from mission.mavlink.link import VehicleLink
from mission.passenger.target import LandingTarget
from mission.time.clock import ManualClock, ScaledClock
from sim.net import wait_for as eventually
from sim.testing.fake_px4 import FakePx4 as Px4Peer
from sim.vehicle.mock import MockVehicle, VehicleOptions

ANY_PORT = "udpin:127.0.0.1:0"
# mavlink_landing_target_t as PX4's generated C header lays it out (fields by size, then the extensions)
PX4_LAYOUT = struct.Struct("<Q5fBB3f4fBB")


def test_link_sends_what_px4_decodes_as_a_local_ned_pose() -> None:
    with VehicleLink(ANY_PORT, ManualClock(1.0)) as link, Px4Peer(link.port) as peer:
        link.wait_vehicle(5.0)
        link.send_landing_target(LandingTarget((12.5, -3.25, -0.75), 1_234_567, math.pi))
        (msg,) = eventually(lambda: peer.received("LANDING_TARGET"), what="one LANDING_TARGET")
        buf = bytes(msg.get_msgbuf())  # the packet as it came: MAVLink 2, a 10-byte header, then the payload
        assert buf[0] == 0xFD and msg.get_msgId() == 149
        payload = buf[10:10 + buf[1]]
        assert len(payload) == PX4_LAYOUT.size == 60  # nothing trimmed: position_valid, the last byte, is 1
        (time_usec, ax, ay, dist, sx, sy, target_num, frame, x, y, z, qw, qx, qy, qz, kind,
         position_valid) = PX4_LAYOUT.unpack(payload)
        assert position_valid == 1 and frame == mavlink.MAV_FRAME_LOCAL_NED == 1
        assert kind == mavlink.LANDING_TARGET_TYPE_VISION_FIDUCIAL and target_num == 0
        assert (x, y, z) == (12.5, -3.25, -0.75) and time_usec == 1_234_567
        assert (ax, ay, dist, sx, sy) == (0.0,) * 5
        assert (qw, qx, qy, qz) == pytest.approx((0.0, 0.0, 0.0, 1.0), abs=1e-7)  # yaw pi about down
        assert link.counters.tx_landing_targets == 1
        with pytest.raises(ValueError):
            link.send_landing_target(LandingTarget((math.inf, 0.0, 0.0), 0))
        assert link.counters.tx_landing_targets == 1


def test_mock_vehicle_accepts_and_refuses_like_px4() -> None:
    with VehicleLink(ANY_PORT, ScaledClock(10.0)) as link, \
            MockVehicle(VehicleOptions(bind="127.0.0.1:0", target=f"127.0.0.1:{link.port}", speed=10.0)) as vehicle:
        link.wait_vehicle(20.0)
        link.send_landing_target(LandingTarget((4.0, 5.0, -0.5), 42))
        eventually(vehicle.when(lambda s: s.counters["landing_targets_accepted"] == 1), what="accepted")
        t_s, reading = vehicle._handlers.landing_targets[-1]
        assert reading.kind == "pose" and reading.position_ned_m == (4.0, 5.0, -0.5) and reading.time_usec == 42
        body = mavlink.MAVLink_landing_target_message(7, 0, mavlink.MAV_FRAME_BODY_FRD, 0, 0, 0, 0, 0, 1.0, 2.0, 3.0,
                                                      (1, 0, 0, 0), mavlink.LANDING_TARGET_TYPE_VISION_FIDUCIAL, 1)
        irlock = mavlink.MAVLink_landing_target_message(8, 0, mavlink.MAV_FRAME_LOCAL_NED, 0.1, -0.1, 4.0, 0, 0, 0, 0, 0,
                                                        (1, 0, 0, 0), mavlink.LANDING_TARGET_TYPE_LIGHT_BEACON, 0)
        link.send_message(body)
        link.send_message(irlock)
        eventually(vehicle.when(lambda s: s.counters["landing_targets_ignored"] == 2), what="two ignored")
        assert [r.kind for _, r in list(vehicle._handlers.landing_targets)[-2:]] == ["unsupported_frame", "irlock"]
        assert vehicle.counters["landing_targets_accepted"] == 1
        assert eventually(lambda: vehicle.event_time(f"coordinate frame {mavlink.MAV_FRAME_BODY_FRD} unsupported"),
                          what="PX4's STATUSTEXT") is not None
        severity = next(s for _, s, text in vehicle.events() if "unsupported" in text)
        assert severity == px4.MAV_SEVERITY_CRITICAL
