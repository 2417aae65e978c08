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
import struct
from dataclasses import dataclass
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


# --- rmw_zenoh's attachment, type names and liveliness tokens (docs/carrier.md "With ROS 2") ---

GID_BYTES = 16  # RMW_GID_STORAGE_SIZE
ATTACHMENT_FORMS = ("current", "legacy")
_CURRENT = struct.Struct("<qqB16s")  # seq, source timestamp [ns], sequence length 16, the gid: 33 bytes
CURRENT_ATTACHMENT_BYTES = _CURRENT.size
_LEGACY_LABELS = (b"sequence_number", b"source_timestamp", b"source_gid")
_LEGACY = struct.Struct(f"<B{len(_LEGACY_LABELS[0])}sqB{len(_LEGACY_LABELS[1])}sqB{len(_LEGACY_LABELS[2])}sB16s")
LEGACY_ATTACHMENT_BYTES = _LEGACY.size  # 77
MAX_ATTACHMENT_BYTES = 512  # an rmw_zenoh attachment (33 or 77 bytes) plus a signing trailer, with room to spare


@dataclass(frozen=True)
class RmwAttachment:
    """One sample's rmw_zenoh attachment: ``form`` ("current" or "legacy"), sequence number (from 1),
    source timestamp [ns since the Unix epoch], the publisher's 16-byte gid, and ``size`` [bytes]
    read (bytes after them, e.g. an authentication trailer, are not rmw_zenoh's)."""

    form: str
    sequence_number: int
    source_timestamp_ns: int
    source_gid: bytes
    size: int


def encode_rmw_attachment(sequence_number: int, source_timestamp_ns: int, gid: bytes, form: str = "current") -> bytes:
    """rmw_zenoh's attachment in zenoh-ext serialization. ``current`` (rmw_zenoh_cpp since the
    change of its attachment serialization: Jazzy 0.2.4, Humble 0.1.2, Kilted, Rolling): int64
    sequence number, int64 source timestamp, the gid as a sequence (VLE length 16, the bytes),
    33 bytes. ``legacy`` (Jazzy <= 0.2.3): the same three, each after its label as a zenoh-ext
    string (VLE length, UTF-8), 77 bytes."""
    if len(gid) != GID_BYTES:
        raise ValueError(f"a gid has {GID_BYTES} bytes")
    if form == "current":
        return _CURRENT.pack(sequence_number, source_timestamp_ns, GID_BYTES, gid)
    if form == "legacy":
        a, b, c = _LEGACY_LABELS
        return _LEGACY.pack(len(a), a, sequence_number, len(b), b, source_timestamp_ns, len(c), c, GID_BYTES, gid)
    raise ValueError(f"attachment form {form!r} is none of {ATTACHMENT_FORMS}")


def decode_rmw_attachment(raw: bytes | bytearray | memoryview) -> RmwAttachment:
    """An rmw_zenoh attachment of either form, checked by length and shape before any field is
    read (no length in it is trusted: each is compared with the one the format fixes). Bytes after
    it are left to the caller (rmw_zenoh's own parser ignores them). Raises :class:`WireError`
    "attachment"."""
    raw = bytes(raw)
    if len(raw) > MAX_ATTACHMENT_BYTES:
        raise WireError("attachment", f"{len(raw)} bytes is no rmw_zenoh attachment")
    if raw[:1 + len(_LEGACY_LABELS[0])] == bytes([len(_LEGACY_LABELS[0])]) + _LEGACY_LABELS[0]:
        if len(raw) < LEGACY_ATTACHMENT_BYTES:
            raise WireError("attachment", f"legacy attachment of {len(raw)} bytes (< {LEGACY_ATTACHMENT_BYTES})")
        n1, l1, seq, n2, l2, stamp, n3, l3, n_gid, gid = _LEGACY.unpack_from(raw)
        if (n1, l1, n2, l2, n3, l3) != (len(_LEGACY_LABELS[0]), _LEGACY_LABELS[0], len(_LEGACY_LABELS[1]),
                                         _LEGACY_LABELS[1], len(_LEGACY_LABELS[2]), _LEGACY_LABELS[2]) \
                or n_gid != GID_BYTES:
            raise WireError("attachment", "legacy attachment with wrong labels or gid length")
        form, size = "legacy", LEGACY_ATTACHMENT_BYTES
    else:
        if len(raw) < CURRENT_ATTACHMENT_BYTES:
            raise WireError("attachment", f"{len(raw)} bytes (< {CURRENT_ATTACHMENT_BYTES})")
        seq, stamp, n_gid, gid = _CURRENT.unpack_from(raw)
        if n_gid != GID_BYTES:
            raise WireError("attachment", f"gid sequence length {n_gid} (not {GID_BYTES})")
        form, size = "current", CURRENT_ATTACHMENT_BYTES
    if seq < 1:
        raise WireError("attachment", f"sequence number {seq} (rmw_zenoh counts from 1)")
    return RmwAttachment(form, seq, stamp, gid, size)


@dataclass(frozen=True)
class RosType:
    """A ROS 2 message type as rmw_zenoh names it: ``name`` (``pkg/msg/Type``), its DDS name in
    keys (``pkg::msg::dds_::Type_``) and its RIHS01 type hash."""

    name: str
    dds: str
    hash: str


ODOMETRY = RosType(ODOMETRY_TYPE, "nav_msgs::msg::dds_::Odometry_",
                   "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0")
TWIST = RosType("geometry_msgs/msg/Twist", "geometry_msgs::msg::dds_::Twist_",
                "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a")
TWIST_STAMPED = RosType("geometry_msgs/msg/TwistStamped", "geometry_msgs::msg::dds_::TwistStamped_",
                        "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64")
CMD_VEL_TYPES = {"Twist": TWIST, "TwistStamped": TWIST_STAMPED}

LIVELINESS_ROOT = "@ros2_lv"
DEFAULT_QOS = "::,:,:,:,,"  # rmw_zenoh writes only what differs from its default profile (reliable, volatile, keep last 10)


def mangle(name: str) -> str:
    """A ROS name in one key chunk: every ``/`` becomes ``%`` (rmw_zenoh's ``mangle_name``)."""
    return name.replace("/", "%")


def ros_name(namespace: str, name: str) -> str:
    """The fully qualified ROS name of ``name`` in ``namespace`` (``/ns/name``; ``/name`` without one)."""
    ns = namespace.strip("/")
    return "/" + "/".join(p for p in (ns, name.strip("/")) if p)


def liveliness_key(domain_id: int, zid: str, node_id: int, entity_id: int, kind: str, namespace: str, node: str,
                   topic: str | None = None, ros_type: RosType | None = None, qos: str = DEFAULT_QOS,
                   enclave: str = "/") -> str:
    """rmw_zenoh's liveliness token of an entity: ``@ros2_lv/<domain>/<zid>/<nid>/<id>/<kind>/
    <enclave>/<namespace>/<node>`` and, for a publisher (``MP``) or a subscription (``MS``),
    ``/<topic>/<type>/<type hash>/<qos>``, every name mangled. ``namespace`` as ROS writes it
    (``/`` for none), ``topic`` fully qualified."""
    if kind not in ("NN", "MP", "MS"):
        raise ValueError(f"entity kind {kind!r}")
    ns = "/" + namespace.strip("/") if namespace.strip("/") else "/"
    parts = [LIVELINESS_ROOT, str(domain_id), zid, str(node_id), str(entity_id), kind, mangle(enclave), mangle(ns),
             mangle(node)]
    if kind != "NN":
        if topic is None or ros_type is None:
            raise ValueError("a publisher or subscription token names its topic and type")
        parts += [mangle(topic), mangle(ros_type.dds), mangle(ros_type.hash), qos]
    return "/".join(parts)


def publishers_of(domain_id: int, topic: str, ros_type: RosType) -> str:
    """Key expression of every publisher token of ``topic`` (fully qualified) with ``ros_type``'s
    DDS name, any hash, node or session."""
    return f"{LIVELINESS_ROOT}/{domain_id}/*/*/*/MP/*/*/*/{mangle(topic)}/{mangle(ros_type.dds)}/*/*"


def encode_cmd_vel_cdr(linear_flu_m_s: np.ndarray, angular_flu_rad_s: np.ndarray, ros_type: RosType,
                       stamp_s: float = 0.0, frame_id: str = "base_link") -> bytes:
    """A CDR velocity command of ``ros_type`` (:data:`TWIST` or :data:`TWIST_STAMPED`, whose header
    carries ``stamp_s`` [s since the Unix epoch] and ``frame_id``), body FLU as :func:`encode_twist_cdr`."""
    if ros_type is TWIST:
        return encode_twist_cdr(linear_flu_m_s, angular_flu_rad_s)
    if ros_type is not TWIST_STAMPED:
        raise ValueError(f"{ros_type.name} is no velocity command")
    lin, ang = velocity3(linear_flu_m_s, "linear"), velocity3(angular_flu_rad_s, "angular")
    T = _ros().types
    sec = math.floor(stamp_s)
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](
        sec=int(sec), nanosec=min(int(round((stamp_s - sec) * 1e9)), 999_999_999)), frame_id=frame_id)
    twist = T[TWIST_TYPE](linear=T["geometry_msgs/msg/Vector3"](x=float(lin[0]), y=float(lin[1]), z=float(lin[2])),
                          angular=T["geometry_msgs/msg/Vector3"](x=float(ang[0]), y=float(ang[1]), z=float(ang[2])))
    return bytes(_ros().serialize_cdr(T[TWIST_STAMPED.name](header=header, twist=twist), TWIST_STAMPED.name))


MAX_CMD_VEL_BYTES = 512  # a Twist is 52 bytes, a TwistStamped 60 plus its frame id


def decode_cmd_vel_cdr(raw: bytes | bytearray | memoryview, ros_type: RosType) -> tuple[np.ndarray, np.ndarray]:
    """(linear [m/s], angular [rad/s]) body FLU from a CDR command of ``ros_type`` (Twist or
    TwistStamped). Raises :class:`WireError` "size", "decode", "nonfinite" or "range"."""
    if ros_type is TWIST:
        return decode_twist_cdr(raw)
    if len(raw) > MAX_CMD_VEL_BYTES:
        raise WireError("size", f"{len(raw)} bytes is no {ros_type.name}")
    try:
        msg = _ros().deserialize_cdr(bytes(raw), ros_type.name)
    except Exception as exc:  # rosbags raises assorted errors on garbage
        raise WireError("decode", f"not a CDR {ros_type.name}: {type(exc).__name__}: {exc}") from None
    lin = np.array([msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z], dtype=float)
    ang = np.array([msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z], dtype=float)
    if not (np.all(np.isfinite(lin)) and np.all(np.isfinite(ang))):
        raise WireError("nonfinite", f"{ros_type.name} has a non-finite number")
    return velocity3(lin, "linear"), velocity3(ang, "angular")
