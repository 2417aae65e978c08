"""The one setpoint type (mission.core.setpoint) and its one MAVLink encoding (mission.mavlink.setpoints):
the invariant, the round trip through the wire's bytes for every kind, and the mock vehicle's
decoding of what the link encodes."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.core.setpoint import Setpoint
from mission.mavlink import px4, setpoints
from mission.mavlink.env import mavlink
from mission.mavlink.setpoints import decode, decode_target, encode, type_mask
from sim.vehicle.protocol import setpoint_of

VEHICLE = (1, 1)
P = np.array([1.0, 2.0, -3.0])  # values float32 carries exactly: the round trip is exact
V = np.array([0.5, -0.25, 0.0])
A = np.array([0.125, 0.25, -0.375])

KINDS = {
    "velocity": (Setpoint.velocity_only(V), 3527),
    "velocity+yaw": (Setpoint.velocity_only(V, yaw_rad=0.75), 2503),
    "full": (Setpoint.triple(P, V, A), 3072),
    "full+yaw": (Setpoint.triple(P, V, A, yaw_rad=-1.5), 2048),
    "hold still": (Setpoint.hold_still(), 3527),
    # position and acceleration on some axes only (their ignored fields go as 0, so the round trip is exact)
    "full horizontal": (Setpoint.triple(P * [1, 1, 0], V, A * [1, 1, 0], position_axes=(True, True, False)), 3332),
    "full vertical+yaw": (Setpoint.triple(P * [0, 0, 1], V, A * [0, 0, 1], yaw_rad=0.5,
                                          position_axes=(False, False, True)), 2243),
}


def on_the_wire(msg: object) -> object:
    """``msg`` packed to bytes and parsed back, as the receiving end sees it (float32 fields)."""
    sender, receiver = mavlink.MAVLink(None, srcSystem=1, srcComponent=191), mavlink.MAVLink(None)
    return receiver.decode(bytearray(msg.pack(sender)))  # type: ignore[attr-defined]


def same(a: Setpoint, b: Setpoint) -> bool:
    def eq(x: np.ndarray | None, y: np.ndarray | None) -> bool:
        return (x is None and y is None) or (x is not None and y is not None and np.array_equal(x, y))
    return (eq(a.velocity_ned_m_s, b.velocity_ned_m_s) and eq(a.position_ned_m, b.position_ned_m)
            and eq(a.acceleration_ned_m_s2, b.acceleration_ned_m_s2) and a.yaw_rad == b.yaw_rad
            and a.position_axes == b.position_axes)


@pytest.mark.parametrize("kind", KINDS)
def test_round_trip_through_the_wire(kind: str) -> None:
    sp, mask = KINDS[kind]
    msg = on_the_wire(encode(sp, VEHICLE, 1234))
    assert msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED"  # type: ignore[attr-defined]
    assert (msg.type_mask, msg.coordinate_frame, msg.time_boot_ms) == (mask, px4.MAV_FRAME_LOCAL_NED, 1234)  # type: ignore[attr-defined]
    assert not msg.type_mask & setpoints.FORCE_SET  # type: ignore[attr-defined]  # PX4 drops a force
    back = decode(msg)
    assert same(back, sp) and back.full == sp.full


def test_the_masks_are_the_named_ones() -> None:
    assert type_mask(KINDS["velocity"][0]) == setpoints.TYPE_MASK_VELOCITY == 3527
    assert type_mask(KINDS["velocity+yaw"][0]) == setpoints.TYPE_MASK_VELOCITY_YAW == 2503
    assert type_mask(KINDS["full"][0]) == setpoints.TYPE_MASK_POSITION_VELOCITY_ACCELERATION == 3072
    assert (setpoints.TYPE_MASK_VELOCITY_YAW_RATE, setpoints.TYPE_MASK_POSITION) == (1479, 2552)


@pytest.mark.parametrize("kind", KINDS)
def test_the_mock_vehicle_decodes_what_the_link_encodes(kind: str) -> None:
    """The mock's reading (PX4's receiver rules) of each kind: the setpoint's fields, NaN where
    absent, per axis for a setpoint full on some axes only."""
    sp = KINDS[kind][0]
    got, reason = setpoint_of(on_the_wire(encode(sp, VEHICLE, 0)), yaw_rad=0.3)
    assert got is not None and reason == ""
    nan3 = np.full(3, np.nan)
    np.testing.assert_array_equal(got.velocity, sp.velocity_ned_m_s)
    sent = np.array(sp.position_axes)
    np.testing.assert_array_equal(got.position, nan3 if sp.position_ned_m is None else np.where(sent, sp.position_ned_m, np.nan))
    np.testing.assert_array_equal(got.acceleration, nan3 if sp.acceleration_ned_m_s2 is None
                                  else np.where(sent, sp.acceleration_ned_m_s2, np.nan))
    assert got.yaw_rad == sp.yaw_rad and got.yaw_rate_rad_s is None


@pytest.mark.parametrize(("position", "acceleration", "given"), [(P, None, "position_ned_m"), (None, A, "acceleration_ned_m_s2")])
def test_position_and_acceleration_come_together(position, acceleration, given) -> None:
    with pytest.raises(ValueError, match=f"has {given} but no .*come together"):
        Setpoint(V, position, acceleration)


@pytest.mark.parametrize("field", ["velocity_ned_m_s", "position_ned_m", "acceleration_ned_m_s2"])
def test_a_vector_of_the_wrong_shape_is_refused_by_name(field: str) -> None:
    parts = {"velocity_ned_m_s": V, "position_ned_m": P, "acceleration_ned_m_s2": A, field: np.zeros(2)}
    with pytest.raises(ValueError, match=f"{field} must have shape"):
        Setpoint(**parts)


@pytest.mark.parametrize(("sp", "field"), [
    (Setpoint.velocity_only(np.array([math.nan, 0.0, 0.0])), "velocity"),
    (Setpoint.velocity_only(np.array([1e39, 0.0, 0.0])), "velocity"),  # overflows float32
    (Setpoint.triple(np.array([0.0, math.inf, 0.0]), V, A), "position"),
    (Setpoint.triple(P, V, np.array([0.0, 0.0, -math.inf])), "acceleration"),
    (Setpoint.velocity_only(V, yaw_rad=math.nan), "yaw"),
])
def test_encode_refuses_a_non_finite_setpoint_by_name(sp: Setpoint, field: str) -> None:
    assert not sp.is_finite() or field == "velocity"  # 1e39 is finite, yet no float32
    with pytest.raises(ValueError, match=f"non-finite {field}"):
        encode(sp, VEHICLE, 0)


@pytest.mark.parametrize(("frame", "mask"), [
    (px4.MAV_FRAME_LOCAL_NED, setpoints.TYPE_MASK_POSITION),  # position only: no kind of ours
    (px4.MAV_FRAME_LOCAL_NED, setpoints.TYPE_MASK_VELOCITY_YAW_RATE),
    (px4.MAV_FRAME_LOCAL_NED, setpoints.TYPE_MASK_POSITION_VELOCITY_ACCELERATION | setpoints.FORCE_SET),
    (px4.MAV_FRAME_BODY_NED, setpoints.TYPE_MASK_VELOCITY),
    # north's position without east's: PX4's position controller refuses it (_inputValid)
    (px4.MAV_FRAME_LOCAL_NED, setpoints.TYPE_MASK_POSITION_VELOCITY_ACCELERATION | setpoints.Y_IGNORE | setpoints.AY_IGNORE),
    # a position without its acceleration on one axis: no setpoint of ours
    (px4.MAV_FRAME_LOCAL_NED, setpoints.TYPE_MASK_POSITION_VELOCITY_ACCELERATION | setpoints.AZ_IGNORE),
])
def test_decode_refuses_what_no_setpoint_encodes_to(frame: int, mask: int) -> None:
    msg = mavlink.MAVLink_set_position_target_local_ned_message(0, 1, 1, frame, mask, *([0.0] * 11))
    with pytest.raises(ValueError):
        decode(msg)
    assert decode_target(msg).type_mask == mask  # the mock still reads it as PX4 would


def test_hold_still_is_zero_velocity_only() -> None:
    sp = Setpoint.hold_still()
    assert not sp.full and sp.yaw_rad is None and np.array_equal(sp.velocity_ned_m_s, np.zeros(3))


@pytest.mark.parametrize("axes", [(True, False, True), (False, True, False), (False, False, False)])
def test_position_axes_name_north_and_east_together_and_at_least_one(axes) -> None:
    with pytest.raises(ValueError, match="position_axes"):
        Setpoint.triple(P, V, A, position_axes=axes)


def test_a_setpoint_full_on_some_axes_says_so() -> None:
    assert [KINDS[k][0].kind for k in ("velocity", "full", "full horizontal", "full vertical+yaw")] == [
        "velocity", "full", "full_horizontal", "full_vertical"]
