"""``carrier.backend = "ros2"``: a ROS 2 robot through Zenoh.

It subscribes to the robot's ``nav_msgs/msg/Odometry`` and publishes ``geometry_msgs/msg/Twist``
or ``TwistStamped`` (``carrier.ros2.cmd_vel_type``) on its ``cmd_vel``, both CDR (rosbags), under
either key form (:func:`ros2_topics`):

- zenoh-bridge-ros2dds: the ROS topic ``/<ns>/odom`` is the key ``<ns>/odom`` (no leading slash);
- rmw_zenoh: ``<domain>/<ns>/<topic>/<dds type>/<type hash>``; we subscribe with ``*`` for the
  hash and publish ``cmd_vel`` with its type's RIHS01 hash and rmw_zenoh's attachment
  (:func:`mission.bus.ros2.encode_rmw_attachment`, ``carrier.ros2.rmw_attachment``), and we
  announce ourselves in the ROS graph as rmw_zenoh does (:class:`RosGraph`: liveliness tokens of
  the node, the ``cmd_vel`` publisher and the ``odom`` subscription) and watch the robot's
  odometry publisher token: once seen, its loss stops the carrier ("robot gone").

Every attachment received is read by :func:`mission.bus.ros2.decode_rmw_attachment`, which checks
length and shape before reading a field (no Zenoh deserializer sees a peer's bytes); a sample with
an attachment that is not rmw_zenoh's is dropped and counted.

With ``zenoh.signing_key_file`` each command also carries the pair's authentication tag after
rmw_zenoh's attachment (:mod:`mission.bus.signing`), for a robot that checks it (``marsupial
ros2-robot --signing-key``, or a bridge of your own); rmw_zenoh's parser reads its three fields
and ignores what follows. The odometry of a ROS 2 robot is not signed.

Frames: Odometry is ENU (REP 103) with a body FLU twist; :func:`mission.bus.ros2.decode_odometry_cdr`
turns it into NED. The odom frame's origin sits at ``carrier.ros2.offset_ned_m`` [m] in the
shared frame (a robot's odometry usually starts at zero where it booted). The command is body FLU:
a diff-drive/Ackermann robot gets ``linear.x`` = forward speed and ``angular.z`` = yaw rate
(counter-clockwise positive: minus the NED yaw rate); a holonomic robot gets its NED velocity
rotated into the body (``linear.x, linear.y``).
"""
from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import zenoh

from mission.carrier.backends import OwnState
from mission.carrier.tracking import Tracked
from mission.bus.auth import bus_auth
from mission.bus.session import congestion_for, declare, undeclare
from mission.time.clock import Clock, Downstream
from mission.bus.lockstep import ZenohRelay
from mission.config.schema import CarrierRos2Section, Config
from mission.bus.wire import CarrierState, WireError
from mission.bus.ros2 import (CMD_VEL_TYPES, GID_BYTES, ODOMETRY, RmwAttachment, RosType, decode_odometry_cdr,
                              decode_rmw_attachment, encode_cmd_vel_cdr, encode_rmw_attachment, liveliness_key,
                              publishers_of, ros_name)

log = logging.getLogger(__name__)

MAX_ODOMETRY_BYTES = 4096  # an Odometry is ~700 bytes; anything far larger is refused undecoded
MAX_WATCHED_TOKENS = 64  # publisher tokens of the robot's odometry remembered (one robot has one)


@dataclass(frozen=True)
class Ros2Topics:
    """The Zenoh keys of one robot: odom_sub / cmd_vel_pub (the controller's side) and odom_pub /
    cmd_vel_sub (the robot's side; equal to the others under zenoh-bridge-ros2dds), the ROS names
    of the two topics (``/<ns>/odom``) and the command's type."""

    odom_sub: str
    odom_pub: str
    cmd_vel_sub: str
    cmd_vel_pub: str
    rmw_zenoh: bool
    odom_name: str = "/odom"
    cmd_vel_name: str = "/cmd_vel"
    cmd_vel_type: RosType = CMD_VEL_TYPES["Twist"]
    namespace: str = "/"
    domain_id: int = 0


def ros2_topics(section: CarrierRos2Section) -> Ros2Topics:
    """Keys of ``section.odom_topic`` and ``section.cmd_vel_topic`` in ``section.key_form``."""
    ns = section.namespace.strip("/")
    odom = "/".join(p for p in (ns, section.odom_topic.strip("/")) if p)
    cmd = "/".join(p for p in (ns, section.cmd_vel_topic.strip("/")) if p)
    ros_type = CMD_VEL_TYPES[section.cmd_vel_type]
    names = dict(odom_name=ros_name(ns, section.odom_topic), cmd_vel_name=ros_name(ns, section.cmd_vel_topic),
                 cmd_vel_type=ros_type, namespace="/" + ns, domain_id=section.domain_id)
    if section.key_form == "ros2dds":
        return Ros2Topics(odom, odom, cmd, cmd, False, **names)  # type: ignore[arg-type]
    d = section.domain_id
    return Ros2Topics(f"{d}/{odom}/{ODOMETRY.dds}/*", f"{d}/{odom}/{ODOMETRY.dds}/{ODOMETRY.hash}",
                      f"{d}/{cmd}/{ros_type.dds}/*", f"{d}/{cmd}/{ros_type.dds}/{ros_type.hash}", True,
                      **names)  # type: ignore[arg-type]


def robot_clock_keys(section: CarrierRos2Section) -> tuple[str, str]:
    """The (time, ready) lockstep keys of the robot of ``section`` (simulation only: the ros2
    carrier brings a ROS-2-shaped robot along, :class:`mission.bus.lockstep.ZenohRelay`)."""
    ns = section.namespace.strip("/") or "-"
    root = f"marsupial/robot_clock/{section.domain_id}/{ns}"
    return f"{root}/time", f"{root}/ready"


class AttachmentWriter:
    """rmw_zenoh's per-message attachment of one publisher, in ``form`` ("current" or "legacy"):
    sequence number (from 1), source timestamp [ns, wall clock], a random 16-byte gid."""

    def __init__(self, form: str = "current") -> None:
        self.form = form
        self.gid = os.urandom(GID_BYTES)
        self.seq = 0

    def next(self) -> bytes:
        self.seq += 1
        return encode_rmw_attachment(self.seq, time.time_ns(), self.gid, self.form)


def read_attachment(attachment: zenoh.ZBytes | None) -> RmwAttachment | None:
    """The rmw_zenoh attachment of a sample (None: it has none); raises :class:`WireError`
    "attachment" for one that is not rmw_zenoh's (checked before a field is read)."""
    if attachment is None:
        return None
    if len(attachment) == 0:
        raise WireError("attachment", "empty attachment")
    return decode_rmw_attachment(attachment.to_bytes())


def rmw_sequence(attachment: zenoh.ZBytes | None) -> int | None:
    """The sequence number of an rmw_zenoh attachment, or None (none, or not rmw_zenoh's)."""
    try:
        read = read_attachment(attachment)
    except WireError:
        return None
    return None if read is None else read.sequence_number


class RosGraph:
    """Our place in rmw_zenoh's ROS graph on ``session``: liveliness tokens of a node
    ``namespace``/``node`` (entity 0) and of its ``entities`` ((kind "MP" or "MS", topic, type),
    ids 1, 2, ...), in rmw_zenoh's key format (:func:`mission.bus.ros2.liveliness_key`); and,
    with ``watch`` (topic, type), the publisher tokens of that topic: once one was seen, none
    left is :attr:`gone`. Undeclared by :meth:`close`."""

    def __init__(self, session: zenoh.Session, domain_id: int, namespace: str, node: str,
                 entities: list[tuple[str, str, RosType]], watch: tuple[str, RosType] | None = None) -> None:
        zid = str(session.info.zid())
        self.keys = [liveliness_key(domain_id, zid, 0, 0, "NN", namespace, node)]
        self.keys += [liveliness_key(domain_id, zid, 0, i, kind, namespace, node, topic, ros_type)
                      for i, (kind, topic, ros_type) in enumerate(entities, start=1)]
        self._lock = threading.Lock()
        self._alive: set[str] = set()
        self._seen: str | None = None
        self.gone: str | None = None
        self._tokens: list[zenoh.LivelinessToken] = []
        self._watch = None
        try:
            for key in self.keys:
                self._tokens.append(self._declare_token(session, key))
            if watch is not None:
                expr = publishers_of(domain_id, watch[0], watch[1])
                self._watch = declare(f"liveliness subscriber on {expr}", lambda: session.liveliness().declare_subscriber(
                    expr, self._on_token, history=True))
        except Exception:
            self.close()
            raise

    @staticmethod
    def _declare_token(session: zenoh.Session, key: str) -> zenoh.LivelinessToken:
        return declare(f"liveliness token {key}", lambda: session.liveliness().declare_token(key))

    def _on_token(self, sample: zenoh.Sample) -> None:  # Zenoh's thread: cheap, never raises
        key = str(sample.key_expr)
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                if len(self._alive) >= MAX_WATCHED_TOKENS:
                    return  # a flood of tokens is no more robots: the ones heard first are kept
                if not self._alive:
                    log.info("ROS graph: the robot's publisher %s is there", key)
                self._alive.add(key)
                self._seen, self.gone = key, None
            else:
                self._alive.discard(key)
                if not self._alive and self._seen is not None:
                    self.gone = f"robot gone: its publisher's liveliness token {key} was dropped"
                    log.warning("ROS graph: %s", self.gone)

    @property
    def robot_seen(self) -> bool:
        """A publisher of the watched topic has been seen."""
        with self._lock:
            return self._seen is not None

    def close(self) -> None:
        undeclare(self._watch, *self._tokens)
        self._tokens, self._watch = [], None


@dataclass(frozen=True)
class Received:
    """A sample taken, by its index in its publisher's stream (rmw_zenoh sequence number - 1)."""

    seq: int


def body_twist(cmd: Tracked, yaw_rad: float | None, holonomic: bool) -> tuple[np.ndarray, np.ndarray]:
    """(linear, angular) body FLU of a command; a holonomic robot's NED velocity is rotated by
    its yaw [rad] (with no yaw known it gets no motion)."""
    if not holonomic:
        return np.array([cmd.speed_m_s, 0.0, 0.0]), np.array([0.0, 0.0, -cmd.yaw_rate_rad_s])
    if yaw_rad is None:
        return np.zeros(3), np.zeros(3)
    vn, ve = float(cmd.velocity_ned_m_s[0]), float(cmd.velocity_ned_m_s[1])
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    forward, right = c * vn + s * ve, -s * vn + c * ve
    return np.array([forward, -right, 0.0]), np.zeros(3)


def open_backend(cfg: Config, clock: Clock, session: zenoh.Session) -> Ros2Carrier:
    """The ROS 2 robot of ``cfg.carrier.ros2`` on ``session``."""
    return Ros2Carrier(cfg, clock, session)


def describe(cfg: Config) -> str:
    t = ros2_topics(cfg.carrier.ros2)
    return f"ROS 2 robot, {cfg.carrier.ros2.key_form} keys odom {t.odom_sub}, cmd_vel {t.cmd_vel_pub}"


class Ros2Carrier:
    """The ROS 2 robot of ``cfg.carrier.ros2`` on an open Zenoh ``session`` (owned by the caller)."""

    name = "ros2"
    brakes_itself = True  # a base driver ramps its own wheels

    def __init__(self, cfg: Config, clock: Clock, session: zenoh.Session) -> None:
        self.clock = clock
        self.section = cfg.carrier.ros2
        self.topics = ros2_topics(cfg.carrier.ros2)
        self.holonomic = cfg.carrier.kinematics == "holonomic"
        self._offset = np.array(cfg.carrier.ros2.offset_ned_m, dtype=float)
        self._lock = threading.Lock()
        self._latest: tuple[CarrierState, float] | None = None
        self.dropped: dict[str, int] = {}
        self.received = 0  # odometry samples heard, taken or dropped
        self._attachment = AttachmentWriter(self.section.rmw_attachment) if self.topics.rmw_zenoh else None
        self.robot_attachment: str | None = None  # the form of the robot's rmw_zenoh attachments, once heard
        self._auth = bus_auth(cfg.zenoh, robot_link=True)
        self._signer = self._auth.signer() if self._auth is not None else None  # a robot that verifies (ros2-robot --signing-key)
        self._listeners: list[Callable[[Received], None]] = []
        self.graph: RosGraph | None = None
        self._pub = declare(f"publisher on {self.topics.cmd_vel_pub}", lambda: session.declare_publisher(
            self.topics.cmd_vel_pub, encoding=zenoh.Encoding.APPLICATION_CDR, congestion_control=congestion_for(clock)))
        try:
            self._sub = declare(f"subscriber on {self.topics.odom_sub}",
                                 lambda: session.declare_subscriber(self.topics.odom_sub, self._on_odom))
            if self.topics.rmw_zenoh:
                t = self.topics
                self.graph = RosGraph(session, t.domain_id, t.namespace, self.section.node_name,
                                      [("MP", t.cmd_vel_name, t.cmd_vel_type), ("MS", t.odom_name, ODOMETRY)],
                                      watch=(t.odom_name, ODOMETRY))
        except Exception:
            undeclare(getattr(self, "_sub", None), self._pub)
            raise
        log.info("ROS 2 carrier: odometry from %s, %s commands to %s", self.topics.odom_sub,
                 self.topics.cmd_vel_type.name, self.topics.cmd_vel_pub)

    def _drop(self, exc: WireError) -> None:
        with self._lock:
            first = exc.reason not in self.dropped
            self.dropped[exc.reason] = self.dropped.get(exc.reason, 0) + 1
        (log.warning if first else log.debug)("dropped an odometry sample (%s): %s", exc.reason, exc)

    def _on_odom(self, sample: zenoh.Sample) -> None:  # Zenoh's thread: cheap, never raises
        rx = self.clock.now()
        self.received += 1  # one subscriber callback thread writes it
        try:
            payload = sample.payload
            if len(payload) > MAX_ODOMETRY_BYTES:
                raise WireError("size", f"{len(payload)} bytes")
            attachment = read_attachment(sample.attachment) if self.topics.rmw_zenoh else None
            state = decode_odometry_cdr(payload.to_bytes())
        except WireError as exc:
            self._drop(exc)
            return
        except Exception as exc:  # noqa: BLE001 - whatever a peer's bytes do, this thread lives on
            self._drop(WireError("decode", f"{type(exc).__name__}: {exc}"))
            return
        with self._lock:
            self._latest = (state, rx)
        if attachment is None:
            return
        if attachment.form != self.robot_attachment:
            self.robot_attachment = attachment.form
            sent = self.section.rmw_attachment
            (log.info if attachment.form == sent else log.warning)(
                "the robot's odometry carries rmw_zenoh's %s attachment (we send %s: carrier.ros2.rmw_attachment)",
                attachment.form, sent)
        for callback in self._listeners:
            callback(Received(attachment.sequence_number - 1))

    def add_listener(self, callback: Callable[[Received], None]) -> None:
        """Call ``callback`` (Zenoh's thread) with each odometry sample taken that carries an
        rmw_zenoh sequence number (lockstep waits for the one the robot names)."""
        self._listeners.append(callback)

    @property
    def last_seq(self) -> int:
        """Index of the last cmd_vel sent (rmw_zenoh sequence number - 1; -1: none, or ros2dds)."""
        return self._attachment.seq - 1 if self._attachment is not None else -1

    def own_state(self) -> OwnState | None:
        with self._lock:
            latest = self._latest
        if latest is None:
            return None
        state, rx = latest
        return OwnState(rx, state.position + self._offset, state.velocity_ned_m_s, state.yaw_rad)

    def engage(self) -> None:
        pass

    def park(self) -> None:
        pass

    def lockstep_relay(self, session: zenoh.Session) -> Downstream | None:
        """In lockstep, a ROS-2-shaped robot with rmw_zenoh keys (``ros2-robot --lockstep``) steps
        with the carrier through its clock keys; a ros2dds robot carries no sequence numbers and
        runs on its own clock (None)."""
        if not self.topics.rmw_zenoh:
            log.warning("lockstep: a ros2dds robot carries no sequence numbers and cannot step with us; "
                        "it runs on its own clock")
            return None
        return ZenohRelay(session, robot_clock_keys(self.section), self, self, name="robot", auth=self._auth)

    def control_fault(self) -> str | None:
        """"robot gone" once the robot's odometry publisher token (rmw_zenoh) has been dropped."""
        return self.graph.gone if self.graph is not None else None

    def report(self) -> dict[str, object]:
        """For the summary: odometry samples heard and dropped by reason, the robot's attachment form, whether its
        publisher token was seen."""
        return {"received": self.received, "dropped": dict(self.dropped), "robot_attachment": self.robot_attachment,
                "sent_attachment": self.section.rmw_attachment if self.topics.rmw_zenoh else None,
                "cmd_vel_type": self.topics.cmd_vel_type.name,
                "robot_token_seen": self.graph.robot_seen if self.graph is not None else None}

    def advance(self, dt_s: float) -> None:
        pass

    def command(self, cmd: Tracked) -> None:
        with self._lock:
            latest = self._latest
        yaw = None if latest is None else latest[0].yaw_rad
        linear, angular = body_twist(cmd, yaw, self.holonomic)
        payload = encode_cmd_vel_cdr(linear, angular, self.topics.cmd_vel_type, time.time())
        attachment = self._attachment.next() if self._attachment is not None else None
        if self._signer is not None:  # our tag after rmw_zenoh's attachment (mission.bus.signing)
            attachment = self._signer.attachment(self.topics.cmd_vel_pub, payload, attachment or b"")
        try:
            self._pub.put(payload, attachment=attachment)
        except zenoh.ZError as exc:  # a closed session while stopping
            log.debug("cmd_vel not sent: %s", exc)

    def close(self) -> None:
        """Send one zero Twist (the robot stops), then undeclare."""
        try:
            self.command(Tracked(0.0, 0.0, 0.0, np.zeros(2), np.zeros(2)))
        finally:
            if self.graph is not None:
                self.graph.close()
            undeclare(self._sub, self._pub)
