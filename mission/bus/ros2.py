"""ROS 2 codecs of the bus, CDR (pure: no Zenoh): the carrier's state as ``nav_msgs/msg/Odometry``
and the velocity command of a ROS 2 carrier as ``geometry_msgs/msg/Twist``.

Carrier state, ROS 2 ``nav_msgs/msg/Odometry`` in CDR (with the 4-byte encapsulation header), as
zenoh-bridge-ros2dds (key ``<namespace>/odom``) or rmw_zenoh (key
``<domain>/<topic>/nav_msgs::msg::dds_::Odometry_/*``) publish it. Decoded with ``rosbags``.
ROS uses ENU (world) and FLU (body); we convert to NED/FRD:

- position (x=e, y=n, z=u) -> (n, e, -u) [m], in the odometry's world frame taken as the
  vehicle's local frame (same origin: the user's job, as with any ROS-PX4 setup);
- twist: REP 105 puts ``twist`` in ``child_frame_id`` (the body, FLU). Assumption: if
  ``child_frame_id`` is empty or equals ``header.frame_id`` the twist is already world ENU;
  otherwise it is body FLU and is rotated to ENU by the pose orientation (a unit quaternion is
  then required). Then ENU -> NED like the position. Angular twist is ignored.
- yaw: ENU yaw (from east, counter-clockwise) -> NED yaw ``pi/2 - yaw_enu`` wrapped to
  (-pi, pi]; an all-zero quaternion means "no orientation" and gives ``yaw None``.
- stamp: ``header.stamp`` [s]; Odometry has no sequence number, so ``seq`` is given by the caller
  (the bridge numbers samples on receipt and orders CDR samples by stamp only).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from mission.bus.wire import VELOCITY_LIMIT_M_S, CarrierState, WireError, velocity3
from mission.core.geodesy import wrap_pi

ODOMETRY_TYPE = "nav_msgs/msg/Odometry"

def ros2dds_odom_key(namespace: str = "") -> str:
    """Key of ``<namespace>/odom`` as zenoh-bridge-ros2dds routes it (no leading slash)."""
    ns = namespace.strip("/")
    return f"{ns}/odom" if ns else "odom"


def rmw_zenoh_odom_key(domain_id: int = 0, topic: str = "odom") -> str:
    """Key expression matching an Odometry topic published through rmw_zenoh (any type hash)."""
    return f"{domain_id}/{topic.strip('/')}/nav_msgs::msg::dds_::Odometry_/*"


_typestore: Any = None


def _ros() -> Any:
    """The rosbags ROS 2 Humble type store (built once, on first use)."""
    global _typestore
    if _typestore is None:
        from rosbags.typesys import Stores, get_typestore

        _typestore = get_typestore(Stores.ROS2_HUMBLE)
    return _typestore


def _quat_rotate(q_xyzw: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate ``v`` by the unit quaternion ``q`` (x, y, z, w): ``q v q*``."""
    x, y, z, w = q_xyzw
    u = np.array([x, y, z])
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def enu_to_ned(v: np.ndarray) -> np.ndarray:
    """(e, n, u) -> (n, e, -u); its own inverse."""
    return np.array([v[1], v[0], -v[2]], dtype=float)


def _yaw_quat_enu(yaw_ned_rad: float) -> np.ndarray:
    """Quaternion (x, y, z, w) of a pure ENU yaw equivalent to the NED heading ``yaw_ned_rad``."""
    yaw_enu = math.pi / 2 - yaw_ned_rad
    return np.array([0.0, 0.0, math.sin(yaw_enu / 2), math.cos(yaw_enu / 2)])


def encode_odometry_cdr(
    state: CarrierState,
    *,
    frame_id: str = "odom",
    child_frame_id: str = "base_link",
) -> bytes:
    """``state`` (local_ned) as a CDR ``nav_msgs/msg/Odometry`` (little endian, with header).

    Position and orientation in ENU; with a ``child_frame_id`` other than ``""``/``frame_id``
    the linear twist is expressed in the body FLU frame (rotated by the yaw; the state must then
    have a yaw), else in world ENU. ``yaw None`` gives an all-zero quaternion.
    """
    if state.frame != "local_ned":
        raise WireError("frame", "encode_odometry_cdr needs a local_ned state")
    ts = _ros()
    T = ts.types
    body = child_frame_id not in ("", frame_id)
    if state.yaw_rad is None:
        if body:
            raise WireError("orientation", "a body-frame twist needs the state's yaw")
        q = np.zeros(4)
    else:
        q = _yaw_quat_enu(state.yaw_rad)
    p_enu = enu_to_ned(state.position)
    v_enu = enu_to_ned(state.velocity_ned_m_s)
    if body:
        q_inv = np.array([-q[0], -q[1], -q[2], q[3]])
        v_enu = _quat_rotate(q_inv, v_enu)
    sec = math.floor(state.stamp_s)
    nanosec = min(int(round((state.stamp_s - sec) * 1e9)), 999_999_999)
    msg = T[ODOMETRY_TYPE](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame_id),
        child_frame_id=child_frame_id,
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=float(p_enu[0]), y=float(p_enu[1]), z=float(p_enu[2])),
                orientation=T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
            ),
            covariance=np.zeros(36),
        ),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](
                linear=T["geometry_msgs/msg/Vector3"](x=float(v_enu[0]), y=float(v_enu[1]), z=float(v_enu[2])),
                angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
            ),
            covariance=np.zeros(36),
        ),
    )
    return bytes(ts.serialize_cdr(msg, ODOMETRY_TYPE))


def decode_odometry_cdr(raw: bytes | bytearray | memoryview, *, seq: int = 0) -> CarrierState:
    """A validated local_ned :class:`CarrierState` from a CDR ``nav_msgs/msg/Odometry``.

    Frames per the module docstring (ENU/FLU -> NED/FRD). Raises :class:`WireError`: "decode"
    (not an Odometry), "nonfinite", "orientation" (body twist with a non-unit quaternion).
    """
    try:
        msg = _ros().deserialize_cdr(bytes(raw), ODOMETRY_TYPE)
    except Exception as exc:  # rosbags raises assorted errors (struct, index, unicode) on garbage
        raise WireError("decode", f"not a CDR {ODOMETRY_TYPE}: {type(exc).__name__}: {exc}") from None
    stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
    pose = msg.pose.pose
    p_enu = np.array([pose.position.x, pose.position.y, pose.position.z], dtype=float)
    q = np.array([pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w], dtype=float)
    lin = msg.twist.twist.linear
    v = np.array([lin.x, lin.y, lin.z], dtype=float)
    if not (np.all(np.isfinite(p_enu)) and np.all(np.isfinite(q)) and np.all(np.isfinite(v)) and math.isfinite(stamp)):
        raise WireError("nonfinite", "Odometry has a non-finite number")
    # Bound before any arithmetic: a finite but huge number would overflow the norm or the
    # rotation below (an overflow warning, then inf) instead of being refused by its rule.
    if np.any(np.abs(q) > 2.0):
        raise WireError("orientation", f"quaternion {q.tolist()} is not a rotation")
    if np.any(np.abs(v) > VELOCITY_LIMIT_M_S):
        raise WireError("range", f"twist {v.tolist()}: components must be within +-{VELOCITY_LIMIT_M_S:g}")
    qn = float(np.linalg.norm(q))
    has_orientation = qn > 0.0
    if has_orientation and abs(qn - 1.0) > 1e-3:
        raise WireError("orientation", f"quaternion norm {qn:.6f} is not 1")
    body = msg.child_frame_id not in ("", msg.header.frame_id)
    if body:
        if not has_orientation:
            raise WireError("orientation", "body-frame twist with an all-zero quaternion")
        v = _quat_rotate(q / qn, v)
    yaw = None
    if has_orientation:
        x, y, z, w = q / qn
        yaw_enu = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        yaw = wrap_pi(math.pi / 2 - yaw_enu)
    return CarrierState(stamp, seq, "local_ned", enu_to_ned(p_enu), enu_to_ned(v), yaw)


TWIST_TYPE = "geometry_msgs/msg/Twist"


def encode_twist_cdr(linear_flu_m_s: np.ndarray, angular_flu_rad_s: np.ndarray) -> bytes:
    """A CDR ``geometry_msgs/msg/Twist`` (little endian, with header) of body FLU velocities:
    linear [m/s] (x forward, y left, z up) and angular [rad/s] (z: counter-clockwise from above)."""
    lin, ang = velocity3(linear_flu_m_s, "linear"), velocity3(angular_flu_rad_s, "angular")
    T = _ros().types
    msg = T[TWIST_TYPE](linear=T["geometry_msgs/msg/Vector3"](x=float(lin[0]), y=float(lin[1]), z=float(lin[2])),
                        angular=T["geometry_msgs/msg/Vector3"](x=float(ang[0]), y=float(ang[1]), z=float(ang[2])))
    return bytes(_ros().serialize_cdr(msg, TWIST_TYPE))


def decode_twist_cdr(raw: bytes | bytearray | memoryview) -> tuple[np.ndarray, np.ndarray]:
    """(linear [m/s], angular [rad/s]) body FLU from a CDR ``geometry_msgs/msg/Twist``.
    Raises :class:`WireError` "decode", "nonfinite" or "range"."""
    if len(raw) > 256:  # a Twist is 52 bytes; refuse before decoding
        raise WireError("size", f"{len(raw)} bytes is no Twist")
    try:
        msg = _ros().deserialize_cdr(bytes(raw), TWIST_TYPE)
    except Exception as exc:  # rosbags raises assorted errors on garbage
        raise WireError("decode", f"not a CDR {TWIST_TYPE}: {type(exc).__name__}: {exc}") from None
    lin = np.array([msg.linear.x, msg.linear.y, msg.linear.z], dtype=float)
    ang = np.array([msg.angular.x, msg.angular.y, msg.angular.z], dtype=float)
    if not (np.all(np.isfinite(lin)) and np.all(np.isfinite(ang))):
        raise WireError("nonfinite", "Twist has a non-finite number")
    return velocity3(lin, "linear"), velocity3(ang, "angular")
