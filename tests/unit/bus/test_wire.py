"""Wire formats: JSON and CDR codecs, frame conversions, validation reasons."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mission.bus.wire import (
    CarrierState,
    GeoOrigin,
    PassengerStatus,
    WireError,
    decode_carrier_json,
    decode_passenger_json,
    encode_carrier_json,
    encode_passenger_json,
    geodetic_to_ned,
    ned_to_geodetic,
    to_local_ned,
)
from mission.bus.ros2 import decode_odometry_cdr, encode_odometry_cdr, rmw_zenoh_odom_key, ros2dds_odom_key

GOOD = {"stamp": 12.345, "seq": 7, "frame": "local_ned", "position": [1.0, 2.0, -3.0],
        "velocity": [0.5, -0.25, 0.0], "yaw": 0.1}


def _json(**changes: object) -> bytes:
    obj = dict(GOOD)
    for k, v in changes.items():
        if v is _DELETE:
            del obj[k]
        else:
            obj[k] = v
    return json.dumps(obj).encode()


_DELETE = object()


def test_json_round_trip_keeps_every_field() -> None:
    s = decode_carrier_json(_json())
    assert (s.stamp_s, s.seq, s.frame, s.yaw_rad) == (12.345, 7, "local_ned", 0.1)
    np.testing.assert_array_equal(s.position, [1.0, 2.0, -3.0])
    np.testing.assert_array_equal(s.velocity_ned_m_s, [0.5, -0.25, 0.0])
    again = decode_carrier_json(encode_carrier_json(s))
    assert again.stamp_s == s.stamp_s and again.seq == s.seq and again.yaw_rad == s.yaw_rad
    np.testing.assert_array_equal(again.position, s.position)


def test_yaw_is_optional_and_unknown_fields_are_ignored() -> None:
    s = decode_carrier_json(_json(yaw=_DELETE, extra="future field"))
    assert s.yaw_rad is None
    assert decode_carrier_json(_json(yaw=None)).yaw_rad is None


def test_acceleration_is_optional_round_trips_and_is_none_when_absent_or_null() -> None:
    assert decode_carrier_json(_json()).acceleration_ned_m_s2 is None  # an older carrier sends none
    assert decode_carrier_json(_json(acceleration=None)).acceleration_ned_m_s2 is None
    s = decode_carrier_json(_json(acceleration=[0.5, -1.25, 0.0]))
    np.testing.assert_array_equal(s.acceleration_ned_m_s2, [0.5, -1.25, 0.0])
    again = decode_carrier_json(encode_carrier_json(s))
    np.testing.assert_array_equal(again.acceleration_ned_m_s2, [0.5, -1.25, 0.0])
    assert json.loads(encode_carrier_json(decode_carrier_json(_json())))["acceleration"] is None
    local = to_local_ned(decode_carrier_json(_json(frame="wgs84", position=[47.0, 8.0, 400.0], acceleration=[1, 2, 3])),
                         GeoOrigin(47.0, 8.0, 400.0))
    np.testing.assert_array_equal(local.acceleration_ned_m_s2, [1.0, 2.0, 3.0])


@pytest.mark.parametrize(("value", "reason"), [([1.0, 2.0], "shape"), ("fast", "type"), ([0.0, "a", 0.0], "type"),
                                               ([0.0, 2e3, 0.0], "range"), ([True, 0.0, 0.0], "type")])
def test_a_bad_acceleration_is_rejected_naming_the_field(value: object, reason: str) -> None:
    with pytest.raises(WireError) as info:
        decode_carrier_json(_json(acceleration=value))
    assert info.value.reason == reason and "acceleration" in str(info.value)


def test_state_arrays_are_read_only() -> None:
    s = decode_carrier_json(_json())
    with pytest.raises(ValueError):
        s.position[0] = 5.0


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (b"\xff\xfe garbage \x00", "decode"),
        (b"{not json", "decode"),
        (b"[1, 2, 3]", "decode"),
        (b'{"stamp": 1, "seq": 1, "frame": "local_ned", "position": [NaN, 0, 0], "velocity": [0, 0, 0]}', "nonfinite"),
        (b'{"stamp": Infinity, "seq": 1, "frame": "local_ned", "position": [0, 0, 0], "velocity": [0, 0, 0]}', "nonfinite"),
        (_json(stamp=_DELETE), "missing"),
        (_json(position=_DELETE), "missing"),
        (_json(stamp="12.3"), "type"),
        (_json(seq=1.5), "type"),
        (_json(seq=True), "type"),
        (_json(seq=-1), "range"),
        (_json(position=[1, 2]), "shape"),
        (_json(position="1,2,3"), "type"),
        (_json(velocity=[1, "a", 2]), "type"),
        (_json(velocity=[1, None, 2]), "type"),
        (_json(yaw="north"), "type"),
        (_json(frame="enu"), "frame"),
        (_json(frame=3), "type"),
        (_json(stamp=10**400), "nonfinite"),
        (_json(frame="wgs84", position=[95.0, 8.0, 400.0]), "range"),
    ],
)
def test_bad_json_raises_with_reason(payload: bytes, reason: str) -> None:
    with pytest.raises(WireError) as info:
        decode_carrier_json(payload)
    assert info.value.reason == reason


def test_geodetic_numbers_match_a_sphere_of_px4_radius() -> None:
    origin = GeoOrigin(47.0, 8.0, 400.0)
    ned = geodetic_to_ned(47.001, 8.0, 395.0, origin)
    # 0.001 deg of latitude on R = 6 371 000 m: R * pi / 180 * 1e-3 = 111.194927 m
    assert ned[0] == pytest.approx(111.194927, abs=1e-4)
    assert ned[1] == pytest.approx(0.0, abs=1e-9)
    assert ned[2] == pytest.approx(5.0)  # 5 m below the origin's altitude: down = +5
    east = geodetic_to_ned(47.0, 8.001, 400.0, origin)
    assert east[1] == pytest.approx(111.194927 * math.cos(math.radians(47.0)), rel=1e-6)
    assert east[0] == pytest.approx(0.0, abs=2e-3)  # the projection's curvature term


@settings(max_examples=200, deadline=None)
@given(
    lat0=st.floats(-80, 80), lon0=st.floats(-179, 179),
    n=st.floats(-5000, 5000), e=st.floats(-5000, 5000), d=st.floats(-500, 500),
)
def test_geodetic_conversion_inverts(lat0: float, lon0: float, n: float, e: float, d: float) -> None:
    origin = GeoOrigin(lat0, lon0, 100.0)
    lat, lon, alt = ned_to_geodetic(np.array([n, e, d]), origin)
    back = geodetic_to_ned(lat, lon, alt, origin)
    np.testing.assert_allclose(back, [n, e, d], atol=1e-6)


def test_wgs84_state_is_converted_through_the_origin() -> None:
    s = decode_carrier_json(_json(frame="wgs84", position=[47.001, 8.0, 395.0]))
    local = to_local_ned(s, GeoOrigin(47.0, 8.0, 400.0))
    assert local.frame == "local_ned"
    np.testing.assert_allclose(local.position, [111.194927, 0.0, 5.0], atol=1e-4)
    np.testing.assert_array_equal(local.velocity_ned_m_s, s.velocity_ned_m_s)
    with pytest.raises(WireError) as info:
        to_local_ned(s, None)
    assert info.value.reason == "origin"


def test_cdr_world_twist_enu_to_ned_numbers() -> None:
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    yaw_enu = 0.0  # facing east
    msg = T["nav_msgs/msg/Odometry"](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=100, nanosec=250_000_000), frame_id="odom"),
        child_frame_id="",  # empty: the twist is world ENU (our documented assumption)
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=10.0, y=20.0, z=3.0),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw_enu / 2), w=math.cos(yaw_enu / 2)),
            ),
            covariance=np.zeros(36),
        ),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](
                linear=T["geometry_msgs/msg/Vector3"](x=1.0, y=2.0, z=0.5),
                angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
            ),
            covariance=np.zeros(36),
        ),
    )
    raw = bytes(ts.serialize_cdr(msg, "nav_msgs/msg/Odometry"))
    s = decode_odometry_cdr(raw, seq=4)
    assert s.frame == "local_ned" and s.seq == 4
    assert s.stamp_s == pytest.approx(100.25)
    np.testing.assert_allclose(s.position, [20.0, 10.0, -3.0])  # (e, n, u) -> (n, e, -u)
    np.testing.assert_allclose(s.velocity_ned_m_s, [2.0, 1.0, -0.5])
    assert s.yaw_rad == pytest.approx(math.pi / 2)  # east in NED


def test_cdr_body_twist_is_rotated_by_the_orientation() -> None:
    # Heading north-east in NED (yaw 45 deg), moving 2 m/s forward: body FLU twist (2, 0, 0).
    state = CarrierState(5.0, 0, "local_ned", [3.0, 4.0, 0.0], [math.sqrt(2), math.sqrt(2), 0.0], math.pi / 4)
    raw = encode_odometry_cdr(state, child_frame_id="base_link")
    from rosbags.typesys import Stores, get_typestore

    msg = get_typestore(Stores.ROS2_HUMBLE).deserialize_cdr(raw, "nav_msgs/msg/Odometry")
    assert msg.twist.twist.linear.x == pytest.approx(2.0)  # forward in the body frame
    assert msg.twist.twist.linear.y == pytest.approx(0.0, abs=1e-12)
    back = decode_odometry_cdr(raw)
    np.testing.assert_allclose(back.velocity_ned_m_s, state.velocity_ned_m_s, atol=1e-12)
    np.testing.assert_allclose(back.position, state.position)
    assert back.yaw_rad == pytest.approx(math.pi / 4)


def test_cdr_garbage_and_bad_quaternion_are_rejected() -> None:
    with pytest.raises(WireError) as info:
        decode_odometry_cdr(b"\x00\x01\x00\x00garbage")
    assert info.value.reason == "decode"
    state = CarrierState(1.0, 0, "local_ned", [0, 0, 0], [1, 0, 0], None)
    raw = encode_odometry_cdr(state, child_frame_id="")  # no yaw: zero quaternion, world twist
    assert decode_odometry_cdr(raw).yaw_rad is None
    with pytest.raises(WireError):
        encode_odometry_cdr(state, child_frame_id="base_link")  # body twist needs a yaw


def test_cdr_nan_is_rejected() -> None:
    state = CarrierState(1.0, 0, "local_ned", [0, 0, 0], [1, 0, 0], 0.0)
    raw = bytearray(encode_odometry_cdr(state))
    good = decode_odometry_cdr(bytes(raw))
    assert good.position[0] == 0.0
    # pose.position.x sits after the header (4) + stamp (8) + frame_id "odom" (4 + 5, padded)
    # + child_frame_id "base_link" (4 + 10, padded to 8): find the float64 slot of e (= 0.0)
    # by writing NaN over every 8-byte aligned zero until decoding rejects it.
    nan = np.array([np.nan]).tobytes()
    rejected = False
    for off in range(4, len(raw) - 8, 8):
        trial = bytearray(raw)
        trial[off:off + 8] = nan
        try:
            decode_odometry_cdr(bytes(trial))
        except WireError as exc:
            if exc.reason == "nonfinite":
                rejected = True
                break
    assert rejected


def test_ros_key_forms() -> None:
    assert ros2dds_odom_key("") == "odom"
    assert ros2dds_odom_key("/robot1/") == "robot1/odom"
    assert rmw_zenoh_odom_key(0, "/odom") == "0/odom/nav_msgs::msg::dds_::Odometry_/*"


def test_passenger_status_round_trip_and_validation() -> None:
    st_ = PassengerStatus("SEPARATED", 3.5, 12, [1, 2, -3], [0.1, 0.2, 0.3], True, [4.0, 5.0, 0.0])
    back = decode_passenger_json(encode_passenger_json(st_))
    assert (back.phase, back.stamp_s, back.seq, back.separated) == ("SEPARATED", 3.5, 12, True)
    np.testing.assert_array_equal(back.anchor_ned_m, [4.0, 5.0, 0.0])
    riding = decode_passenger_json(encode_passenger_json(
        PassengerStatus("RIDING", 1.0, 1, [0, 0, 0], [0, 0, 0])))
    assert riding.anchor_ned_m is None and riding.separated is False and riding.reason is None
    aborted = decode_passenger_json(encode_passenger_json(
        PassengerStatus("ABORT", 2.0, 3, [0, 0, 0], [0, 0, 0], reason="vehicle_disarmed")))
    assert (aborted.phase, aborted.reason) == ("ABORT", "vehicle_disarmed")
    assert json.loads(encode_passenger_json(aborted))["reason"] == "vehicle_disarmed"
    for bad, reason in [
        ({"phase": "FLYING"}, "phase"),
        ({"phase": 3}, "type"),
        ({"separated": "no"}, "type"),
        ({"reason": "x" * 33}, "type"),
        ({"reason": "Disarmed!\n"}, "type"),
        ({"reason": 7}, "type"),
        ({"anchor": [1, 2]}, "shape"),
        ({"position": [0, float("nan"), 0]}, "nonfinite"),
    ]:
        obj = json.loads(encode_passenger_json(st_))
        obj.update(bad)
        with pytest.raises(WireError) as info:
            decode_passenger_json(json.dumps(obj).encode())
        assert info.value.reason == reason, bad


def test_a_teams_queue_fields_go_only_when_given_and_are_range_checked() -> None:
    """A single pair's status has no ``recovery`` or ``battery`` key (its bytes as they always
    were); a team's carries them; a negative recovery time or a battery over 100 % is dropped."""
    plain = json.loads(encode_passenger_json(PassengerStatus("HOLDOFF", 1.0, 1, [0, 0, -5], [0, 0, 0])))
    assert "recovery" not in plain and "battery" not in plain
    team = PassengerStatus("HOLDOFF", 1.0, 1, [0, 0, -5], [0, 0, 0], recovery_s=8.25, battery_pct=37.5)
    back = decode_passenger_json(encode_passenger_json(team))
    assert (back.recovery_s, back.battery_pct) == (8.25, 37.5)
    for bad in ({"recovery": -1.0}, {"battery": 100.5}, {"battery": float("nan")}, {"recovery": "long"}):
        obj = json.loads(encode_passenger_json(team))
        obj.update(bad)
        with pytest.raises(WireError):
            decode_passenger_json(json.dumps(obj).encode())


def test_the_frames_bias_goes_only_when_given_in_pairs_and_is_range_checked() -> None:
    """A status without the bias is byte for byte what it was before the field existed; one with
    it round-trips ``bias`` [m] and ``bias_sigma`` [m]; half a pair, a negative sigma, a bias of
    the wrong shape or not finite is dropped with the reason the feed counts."""
    plain = PassengerStatus("RIDING", 2.5, 7, [1, 2, -0.5], [0.5, 0, 0], leg=1)
    assert encode_passenger_json(plain) == (
        b'{"phase":"RIDING","stamp":2.5,"seq":7,"position":[1.0,2.0,-0.5],"velocity":[0.5,0.0,0.0],'
        b'"separated":false,"anchor":null,"leg":1,"reason":null,"holding":false}')
    shared = PassengerStatus("RIDING", 2.5, 7, [1, 2, -0.5], [0.5, 0, 0], leg=1,
                             bias_ned_m=np.array([1.75, -0.5, 0.25]), bias_sigma_m=0.125)
    raw = encode_passenger_json(shared)
    assert raw.endswith(b'"holding":false,"bias":[1.75,-0.5,0.25],"bias_sigma":0.125}')
    back = decode_passenger_json(raw)
    assert back.bias_ned_m.tolist() == [1.75, -0.5, 0.25] and back.bias_sigma_m == 0.125
    assert decode_passenger_json(encode_passenger_json(plain)).bias_ned_m is None
    for drop, reason in (("bias_sigma", "missing"), ("bias", "missing")):
        obj = json.loads(raw)
        del obj[drop]
        with pytest.raises(WireError) as info:
            decode_passenger_json(json.dumps(obj).encode())
        assert info.value.reason == reason
    for bad, reason in (({"bias_sigma": -0.1}, "range"), ({"bias": [1.0, 2.0]}, "shape"),
                        ({"bias": [1.0, float("nan"), 0.0]}, "nonfinite"), ({"bias_sigma": "small"}, "type")):
        obj = json.loads(raw)
        obj.update(bad)
        with pytest.raises(WireError) as info:
            decode_passenger_json(json.dumps(obj).encode())
        assert info.value.reason == reason, bad
    with pytest.raises(WireError):
        PassengerStatus("RIDING", 2.5, 7, [1, 2, -0.5], [0.5, 0, 0], bias_ned_m=[1.0, 0.0, 0.0])


def test_values_built_in_code_take_numpy_and_are_checked_like_the_wire() -> None:
    s = CarrierState(np.float32(1.5), np.int64(3), "local_ned", np.array([1, 2, 3], dtype=np.int32),
                     (0.5, 0.0, 0.0), np.float64(0.25))
    assert (s.stamp_s, s.seq, s.yaw_rad) == (1.5, 3, 0.25) and type(s.seq) is int
    assert s.position.dtype == float and not s.position.flags.writeable
    p = PassengerStatus("RIDING", 1.0, 1, np.zeros(3), np.zeros(3), np.bool_(True), None)
    assert p.separated is True
    for kwargs, reason in [
        ({"position": np.zeros((3, 1))}, "shape"),
        ({"position": np.zeros(4)}, "shape"),
        ({"position": np.array([True, False, True])}, "type"),
        ({"position": [0.0, math.nan, 0.0]}, "nonfinite"),
        ({"velocity_ned_m_s": [0.0, 1e4, 0.0]}, "range"),
        ({"seq": 2**63}, "range"),
        ({"seq": 1.0}, "type"),
        ({"stamp_s": 10**400}, "nonfinite"),
        ({"frame": "enu"}, "frame"),
    ]:
        args = {"stamp_s": 1.0, "seq": 1, "frame": "local_ned", "position": [0.0] * 3, "velocity_ned_m_s": [0.0] * 3}
        args.update(kwargs)
        with pytest.raises(WireError) as info:
            CarrierState(**args)  # type: ignore[arg-type]
        assert info.value.reason == reason, kwargs


def test_several_faults_name_a_missing_field_then_the_first_in_check_order() -> None:
    for payload, reason in [
        (b'{"stamp": NaN, "frame": "local_ned", "position": [0, 0, 0], "velocity": [0, 0, 0]}', "missing"),
        (_json(stamp="x", position=[1, 2]), "type"),  # stamp before position
        (_json(seq=-1, frame="enu"), "frame"),  # the frame is judged first
        (_json(velocity=[1, 2], yaw=math.inf, position=[0, 0, 1e300]), "range"),  # position, velocity, yaw
    ]:
        with pytest.raises(WireError) as info:
            decode_carrier_json(payload)
        assert info.value.reason == reason, payload
    with pytest.raises(WireError) as info:  # the phase is judged before the numbers
        PassengerStatus("FLYING", math.nan, -1, [0, 0], [0, 0, 0], "no")  # type: ignore[arg-type]
    assert info.value.reason == "phase"


def test_the_wire_names_are_the_only_names_on_the_wire() -> None:
    named_in_code = json.dumps({"stamp_s": 1.0, "seq": 1, "frame": "local_ned", "position": [0, 0, 0],
                                "velocity_ned_m_s": [0, 0, 0]}).encode()
    with pytest.raises(WireError) as info:
        decode_carrier_json(named_in_code)
    assert info.value.reason == "missing"
    sent = json.loads(encode_carrier_json(decode_carrier_json(_json()))).keys()
    assert GOOD.keys() <= sent and not sent & {"stamp_s", "velocity_ned_m_s", "yaw_rad", "acceleration_ned_m_s2"}


def test_the_announced_target_is_optional_and_absent_from_a_single_pairs_bytes() -> None:
    s = decode_carrier_json(_json())
    assert s.target_ned_m is None and "target" not in json.loads(encode_carrier_json(s))  # a single pair's bytes
    s = decode_carrier_json(_json(target=[24.0, 18.0, -5.0]))
    np.testing.assert_array_equal(decode_carrier_json(encode_carrier_json(s)).target_ned_m, [24.0, 18.0, -5.0])
    local = to_local_ned(decode_carrier_json(_json(frame="wgs84", position=[47.0, 8.0, 400.0], target=[1, 2, 3])),
                         GeoOrigin(47.0, 8.0, 400.0))
    np.testing.assert_array_equal(local.target_ned_m, [1.0, 2.0, 3.0])


@pytest.mark.parametrize(("value", "reason"), [([1.0, 2.0], "shape"), ([0.0, "a", 0.0], "type"),
                                               ([0.0, 2e7, 0.0], "range")])
def test_a_bad_target_is_rejected_naming_the_field(value: object, reason: str) -> None:
    with pytest.raises(WireError) as info:
        decode_carrier_json(_json(target=value))
    assert info.value.reason == reason and "target" in str(info.value)


def test_a_team_passengers_keys_are_its_own_and_the_wildcard_hears_only_them() -> None:
    from mission.bus.session import keys, passenger_of, team_status_keys
    from mission.errors import ConfigError

    k = keys("pair0", "alpha")
    assert (k.passenger_state, k.passenger_phase, k.passenger_alive) == (
        "marsupial/pair0/passenger/alpha/state", "marsupial/pair0/passenger/alpha/phase",
        "marsupial/pair0/passenger/alpha/alive")
    assert k.carrier_state == keys("pair0").carrier_state and keys("pair0").passenger_state == "marsupial/pair0/passenger/state"
    assert team_status_keys("pair0") == "marsupial/pair0/passenger/*/state"
    assert passenger_of(k.passenger_state, "pair0") == "alpha"
    assert passenger_of(keys("pair0").passenger_state, "pair0") is None
    assert passenger_of("marsupial/pair0/passenger/a/b/state", "pair0") is None
    with pytest.raises(ConfigError, match="team.passengers"):
        keys("pair0", "al/pha")
