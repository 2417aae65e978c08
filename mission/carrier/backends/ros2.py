"""``carrier.backend = "ros2"``: a ROS 2 robot through Zenoh.

It subscribes to the robot's ``nav_msgs/msg/Odometry`` and publishes ``geometry_msgs/msg/Twist``
on its ``cmd_vel``, both CDR (rosbags), under either key form (:func:`ros2_topics`):

- zenoh-bridge-ros2dds: the ROS topic ``/<ns>/odom`` is the key ``<ns>/odom`` (no leading slash);
- rmw_zenoh: ``<domain>/<ns>/<topic>/<dds type>/<type hash>``; we subscribe with ``*`` for the
  hash and publish ``cmd_vel`` with the Twist's RIHS01 hash and rmw_zenoh's attachment
  (sequence number, source timestamp [ns], a 16-byte source gid), which its subscribers read.

With ``zenoh.signing_key_file`` each Twist also carries the pair's authentication tag after that
attachment (:mod:`mission.bus.signing`), for a robot that checks it (``marsupial ros2-robot
--signing-key``, or a bridge of your own); the odometry of a ROS 2 robot is not signed.

Frames: Odometry is ENU (REP 103) with a body FLU twist; :func:`mission.bus.ros2.decode_odometry_cdr`
turns it into NED. The odom frame's origin sits at ``carrier.ros2.offset_ned_m`` [m] in the
shared frame (a robot's odometry usually starts at zero where it booted). The Twist is body FLU:
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
from typing import Any

import numpy as np
import zenoh
import zenoh.ext

from mission.carrier.controller import OwnState
from mission.carrier.tracking import Tracked
from mission.bus.auth import bus_auth
from mission.bus.session import congestion_for, declare, undeclare
from mission.time.clock import Clock, Downstream
from mission.time.lockstep import ZenohRelay
from mission.config.schema import CarrierRos2Section, Config
from mission.bus.wire import CarrierState, WireError
from mission.bus.ros2 import decode_odometry_cdr, encode_twist_cdr

log = logging.getLogger(__name__)

ODOMETRY_DDS = "nav_msgs::msg::dds_::Odometry_"
TWIST_DDS = "geometry_msgs::msg::dds_::Twist_"
# RIHS01 type hashes of ROS 2 Jazzy (rmw_zenoh keys carry them).
TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
ODOMETRY_HASH = "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
MAX_ODOMETRY_BYTES = 4096  # an Odometry is ~700 bytes; anything far larger is refused undecoded


@dataclass(frozen=True)
class Ros2Topics:
    """The Zenoh keys of one robot: odom_sub / cmd_vel_pub (the controller's side) and odom_pub /
    cmd_vel_sub (the robot's side; equal to the others under zenoh-bridge-ros2dds)."""

    odom_sub: str
    odom_pub: str
    cmd_vel_sub: str
    cmd_vel_pub: str
    rmw_zenoh: bool


def ros2_topics(section: CarrierRos2Section) -> Ros2Topics:
    """Keys of ``section.odom_topic`` and ``section.cmd_vel_topic`` in ``section.key_form``."""
    ns = section.namespace.strip("/")
    odom = "/".join(p for p in (ns, section.odom_topic.strip("/")) if p)
    cmd = "/".join(p for p in (ns, section.cmd_vel_topic.strip("/")) if p)
    if section.key_form == "ros2dds":
        return Ros2Topics(odom, odom, cmd, cmd, False)
    d = section.domain_id
    return Ros2Topics(f"{d}/{odom}/{ODOMETRY_DDS}/*", f"{d}/{odom}/{ODOMETRY_DDS}/{ODOMETRY_HASH}",
                      f"{d}/{cmd}/{TWIST_DDS}/*", f"{d}/{cmd}/{TWIST_DDS}/{TWIST_HASH}", True)


def robot_clock_keys(section: CarrierRos2Section) -> tuple[str, str]:
    """The (time, ready) lockstep keys of the robot of ``section`` (simulation only: the ros2
    carrier brings a ROS-2-shaped robot along, :class:`mission.time.lockstep.ZenohRelay`)."""
    ns = section.namespace.strip("/") or "-"
    root = f"marsupial/robot_clock/{section.domain_id}/{ns}"
    return f"{root}/time", f"{root}/ready"


class RmwAttachment:
    """rmw_zenoh's per-message attachment: sequence number (from 1), source timestamp [ns], gid (16 bytes)."""

    def __init__(self) -> None:
        self.gid = os.urandom(16)
        self.seq = 0

    def next(self) -> bytes:
        self.seq += 1
        return zenoh.ext.z_serialize(("sequence_number", zenoh.ext.Int64(self.seq), "source_timestamp",
                                      zenoh.ext.Int64(time.time_ns()), "source_gid", self.gid)).to_bytes()


_RMW_ATTACHMENT: Any = tuple[str, zenoh.ext.Int64, str, zenoh.ext.Int64, str, bytes]


def rmw_sequence(attachment: zenoh.ZBytes | None) -> int | None:
    """The sequence number of an rmw_zenoh attachment, or None (none, or not rmw_zenoh's)."""
    if attachment is None:
        return None
    try:
        fields: Any = zenoh.ext.z_deserialize(_RMW_ATTACHMENT, attachment)
    except Exception:  # noqa: BLE001 - a foreign attachment is no sequence number
        return None
    return int(fields[1]) if fields[0] == "sequence_number" else None


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
        self._attachment = RmwAttachment() if self.topics.rmw_zenoh else None
        self._auth = bus_auth(cfg.zenoh, robot_link=True)
        self._signer = self._auth.signer() if self._auth is not None else None  # a robot that verifies (ros2-robot --signing-key)
        self._listeners: list[Callable[[Received], None]] = []
        self._pub = declare(f"publisher on {self.topics.cmd_vel_pub}", lambda: session.declare_publisher(
            self.topics.cmd_vel_pub, encoding=zenoh.Encoding.APPLICATION_CDR, congestion_control=congestion_for(clock)))
        try:
            self._sub = declare(f"subscriber on {self.topics.odom_sub}",
                                 lambda: session.declare_subscriber(self.topics.odom_sub, self._on_odom))
        except Exception:
            self._pub.undeclare()
            raise
        log.info("ROS 2 carrier: odometry from %s, commands to %s", self.topics.odom_sub, self.topics.cmd_vel_pub)

    def _on_odom(self, sample: zenoh.Sample) -> None:  # Zenoh's thread: cheap, never raises
        rx = self.clock.now()
        try:
            payload = sample.payload
            if len(payload) > MAX_ODOMETRY_BYTES:
                raise WireError("size", f"{len(payload)} bytes")
            state = decode_odometry_cdr(payload.to_bytes())
        except WireError as exc:
            with self._lock:
                first = exc.reason not in self.dropped
                self.dropped[exc.reason] = self.dropped.get(exc.reason, 0) + 1
            (log.warning if first else log.debug)("dropped an odometry sample (%s): %s", exc.reason, exc)
            return
        with self._lock:
            self._latest = (state, rx)
        seq = rmw_sequence(sample.attachment)
        if seq is not None:
            for callback in self._listeners:
                callback(Received(seq - 1))

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
        return None

    def advance(self, dt_s: float) -> None:
        pass

    def command(self, cmd: Tracked) -> None:
        with self._lock:
            latest = self._latest
        yaw = None if latest is None else latest[0].yaw_rad
        linear, angular = body_twist(cmd, yaw, self.holonomic)
        payload = encode_twist_cdr(linear, angular)
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
            undeclare(self._sub, self._pub)
