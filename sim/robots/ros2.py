"""``marsupial ros2-robot``: a small ROS-2-shaped ground robot over Zenoh, for testing the
``ros2`` carrier backend without ROS.

It does what a ROS 2 base driver does, on the keys of zenoh-bridge-ros2dds or rmw_zenoh
(:func:`mission.carrier.backends.ros2.ros2_topics`): it subscribes to ``geometry_msgs/msg/Twist``
or ``TwistStamped`` (one of them, as a ROS subscription has one type) on ``cmd_vel`` and publishes
``nav_msgs/msg/Odometry`` on ``odom`` (CDR, frame ``odom``, child ``base_link``, twist in the body
frame, stamps on its clock), at ``rate_hz``. With rmw_zenoh keys it sends rmw_zenoh's attachment
in the form asked and declares its node, publisher and subscription in the ROS graph
(liveliness tokens, :class:`mission.carrier.backends.ros2.RosGraph`).

Model (body FLU commands; state in NED): a unicycle (``linear.x`` forward speed, ``angular.z``
yaw rate, counter-clockwise positive) or a holonomic base (``linear.x, linear.y``), each speed
slewed at ``accel_m_s2``; commands older than ``cmd_timeout_s`` mean stop (as base drivers do).
Its odom frame's origin is ``odom_origin_ned`` [m] of the shared frame: it starts there at zero.
"""
from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable

import click
import numpy as np
import zenoh

from mission.carrier.backends.ros2 import (AttachmentWriter, Received, RosGraph, Ros2Topics, read_attachment,
                                           robot_clock_keys, ros2_topics)
from mission.core.geodesy import wrap_pi
from mission.bus.auth import BusAuth, bus_auth
from mission.bus.bridge import open_session
from mission.bus.session import close_session, congestion_for, undeclare
from mission.lifetime import on_stop_signals
from mission.time.clock import Clock, LockstepClock, Periodic, ScaledClock
from mission.config.schema import CarrierRos2Section, ZenohSection
from mission.bus.wire import CarrierState, WireError
from mission.bus.ros2 import ODOMETRY, decode_cmd_vel_cdr, encode_odometry_cdr

log = logging.getLogger(__name__)


class Ros2RobotSim:
    """The robot on an open ``session``: ``step(dt)`` integrates and publishes one Odometry."""

    def __init__(self, session: zenoh.Session, topics: Ros2Topics, clock: Clock, *, holonomic: bool = False,
                 start_ned: tuple[float, float, float] = (0.0, 0.0, 0.0), yaw_rad: float = 0.0,
                 accel_m_s2: float = 1.5, cmd_timeout_s: float = 0.5, max_speed_m_s: float = 3.0,
                 max_yaw_rate_rad_s: float = 1.5, auth: BusAuth | None = None, attachment_form: str = "current",
                 node_name: str = "base_driver") -> None:
        self.clock, self.topics, self.holonomic = clock, topics, holonomic
        self.position_m = np.array(start_ned, dtype=float)  # odom frame, NED [m]
        self.yaw_rad = float(yaw_rad)
        self.body_velocity = np.zeros(2)  # forward, right [m/s]
        self.yaw_rate_rad_s = 0.0
        self.accel_m_s2, self.cmd_timeout_s = accel_m_s2, cmd_timeout_s
        self.max_speed_m_s, self.max_yaw_rate_rad_s = max_speed_m_s, max_yaw_rate_rad_s
        self._lock = threading.Lock()
        self._cmd: tuple[np.ndarray, float, float] | None = None  # (forward, right), yaw rate NED, rx time
        self.commands, self.dropped, self.seq = 0, 0, 0
        self._attachment = AttachmentWriter(attachment_form) if topics.rmw_zenoh else None
        self._verifier = auth.verifier() if auth is not None else None  # commands must carry the pair's tag
        self._listeners: list[Callable[[Received], None]] = []
        self._pub = session.declare_publisher(topics.odom_pub, encoding=zenoh.Encoding.APPLICATION_CDR,
                                              congestion_control=congestion_for(clock))
        self._sub = session.declare_subscriber(topics.cmd_vel_sub, self._on_cmd)
        self.graph = RosGraph(session, topics.domain_id, topics.namespace, node_name,
                              [("MP", topics.odom_name, ODOMETRY), ("MS", topics.cmd_vel_name, topics.cmd_vel_type)]
                              ) if topics.rmw_zenoh else None

    def _on_cmd(self, sample: zenoh.Sample) -> None:  # Zenoh's thread: never raises
        attachment = sample.attachment
        try:
            raw = sample.payload.to_bytes()
            if self._verifier is not None:
                _, inner = self._verifier.verify(sample, raw)
                attachment = zenoh.ZBytes(inner) if inner else None
            read = read_attachment(attachment) if self._attachment is not None else None
            linear, angular = decode_cmd_vel_cdr(raw, self.topics.cmd_vel_type)
        except WireError as exc:
            self.dropped += 1
            (log.warning if self.dropped == 1 else log.debug)("dropped a cmd_vel (%s)", exc)
            return
        body = np.array([linear[0], -linear[1] if self.holonomic else 0.0])
        with self._lock:
            self._cmd = (body, -float(angular[2]), self.clock.now())
            self.commands += 1
        if read is not None:
            for callback in self._listeners:
                callback(Received(read.sequence_number - 1))

    def add_listener(self, callback: Callable[[Received], None]) -> None:
        """Call ``callback`` (Zenoh's thread) with each command taken that carries an rmw_zenoh
        sequence number (lockstep: a step waits for the command the carrier names)."""
        self._listeners.append(callback)

    @property
    def published_seq(self) -> int:
        """Index of the last odometry sent (rmw_zenoh sequence number - 1)."""
        return self._attachment.seq - 1 if self._attachment is not None else self.seq - 1

    def step(self, dt_s: float) -> CarrierState:
        now = self.clock.now()
        with self._lock:
            cmd = self._cmd
        if cmd is None or now - cmd[2] > self.cmd_timeout_s:
            wanted, rate = np.zeros(2), 0.0
        else:
            wanted, rate = cmd[0], cmd[1]
        speed = float(np.linalg.norm(wanted))
        if speed > self.max_speed_m_s:
            wanted = wanted * (self.max_speed_m_s / speed)
        change = wanted - self.body_velocity
        limit = self.accel_m_s2 * dt_s
        norm = float(np.linalg.norm(change))
        if norm > limit:
            change = change * (limit / norm)
        self.body_velocity = self.body_velocity + change
        self.yaw_rate_rad_s = min(max(rate, -self.max_yaw_rate_rad_s), self.max_yaw_rate_rad_s)
        mid = self.yaw_rad + 0.5 * self.yaw_rate_rad_s * dt_s
        c, s = math.cos(mid), math.sin(mid)
        fwd, right = self.body_velocity
        self.position_m = self.position_m + np.array([c * fwd - s * right, s * fwd + c * right, 0.0]) * dt_s
        self.yaw_rad = wrap_pi(self.yaw_rad + self.yaw_rate_rad_s * dt_s)
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        v_ned = np.array([c * fwd - s * right, s * fwd + c * right, 0.0])
        state = CarrierState(now, self.seq, "local_ned", self.position_m, v_ned, self.yaw_rad)
        attachment = self._attachment.next() if self._attachment is not None else None
        self._pub.put(encode_odometry_cdr(state), attachment=attachment)
        self.seq += 1
        return state

    def run(self, stop: threading.Event, rate_hz: float = 30.0) -> None:
        periodic = Periodic(self.clock, 1.0 / rate_hz)
        last = self.clock.now()
        while not stop.is_set():
            tick = periodic.wait()
            self.step(tick - last)
            last = tick

    def close(self) -> None:
        if self.graph is not None:
            self.graph.close()
        undeclare(self._sub, self._pub)


def _floats(text: str, option: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(p) for p in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise click.BadParameter(f"expected 3 comma-separated numbers, got {text!r}", param_hint=option)
    return values  # type: ignore[return-value]


@click.command("ros2-robot", context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--key-form", type=click.Choice(["ros2dds", "rmw_zenoh"]), default="ros2dds", show_default=True)
@click.option("--namespace", default="", help="ROS namespace of the robot's topics.")
@click.option("--domain-id", type=click.IntRange(0, 232), default=0, show_default=True)
@click.option("--cmd-vel-type", type=click.Choice(["Twist", "TwistStamped"]), default="Twist", show_default=True,
              help="The velocity command type its cmd_vel subscription takes.")
@click.option("--rmw-attachment", type=click.Choice(["current", "legacy"]), default="current", show_default=True,
              help="rmw_zenoh attachment form it sends (rmw_zenoh keys).")
@click.option("--zenoh-mode", type=click.Choice(["peer", "client"]), default=None,
              help="Zenoh mode (client: through a router given by --zenoh-connect, as an rmw_zenoh node) [default: peer].")
@click.option("--kinematics", type=click.Choice(["diff_drive", "holonomic"]), default="diff_drive", show_default=True)
@click.option("--yaw-deg", type=float, default=0.0, show_default=True, help="Initial heading [deg] from north.")
@click.option("--rate", "rate_hz", type=click.FloatRange(1.0, 200.0), default=30.0, show_default=True)
@click.option("--speed", type=click.FloatRange(min=0, min_open=True), default=1.0, show_default=True)
@click.option("--lockstep", is_flag=True, help="Simulation: step on the ros2 carrier's lockstep clock (carrier "
              "--lockstep) instead of a scaled wall clock; rmw_zenoh keys only (their sequence numbers order the "
              "steps). --speed is then the pace once the carrier falls silent.")
@click.option("--zenoh-connect", "connect", multiple=True, metavar="ENDPOINT")
@click.option("--zenoh-listen", "listen", multiple=True, metavar="ENDPOINT")
@click.option("--signing-key", "signing_key_file", type=click.Path(dir_okay=False), default=None,
              help="Bus signing key file of the pair (zenoh.signing_key_file): take only commands (and lockstep clock "
                   "messages) signed with it.")
@click.option("--pair", default="pair0", show_default=True, help="The pair whose key signs (with --signing-key).")
def ros2_robot(key_form: str, namespace: str, domain_id: int, cmd_vel_type: str, rmw_attachment: str,
               zenoh_mode: str | None, kinematics: str, yaw_deg: float, rate_hz: float,
               speed: float, lockstep: bool, connect: tuple[str, ...], listen: tuple[str, ...],
               signing_key_file: str | None, pair: str) -> int:
    """Run a ROS-2-shaped robot: Twist on cmd_vel in, Odometry on odom out (CDR over Zenoh).

    Its odometry starts at zero (the odom frame's origin is where it starts). SIGINT/SIGTERM stop it.
    """
    if lockstep and key_form != "rmw_zenoh":
        raise click.BadParameter("lockstep needs --key-form rmw_zenoh (its sequence numbers order the steps)",
                                 param_hint="--lockstep")
    ros2 = CarrierRos2Section(key_form=key_form, namespace=namespace, domain_id=domain_id,  # type: ignore[arg-type]
                              cmd_vel_type=cmd_vel_type, rmw_attachment=rmw_attachment)  # type: ignore[arg-type]
    topics = ros2_topics(ros2)
    section = ZenohSection(listen=list(listen), connect=list(connect), rendezvous=None if (listen or connect) else "tcp/127.0.0.1:7448",
                           pair=pair, signing_key_file=signing_key_file, **({"mode": zenoh_mode} if zenoh_mode else {}))
    auth = bus_auth(section)
    stop = threading.Event()
    clock: Clock = LockstepClock(speed=speed, name="robot-lockstep") if lockstep else ScaledClock(speed)

    def on_signal(signum: int) -> None:
        stop.set()
        if isinstance(clock, LockstepClock):
            clock.close()  # a lockstep sleep ends now

    with on_stop_signals(on_signal):
        session = open_session(section)
        try:
            robot = Ros2RobotSim(session, topics, clock, holonomic=kinematics == "holonomic",
                                 yaw_rad=math.radians(yaw_deg), auth=auth, attachment_form=rmw_attachment)
            upstream = None
            if isinstance(clock, LockstepClock):
                from mission.bus.lockstep import ZenohUpstream

                upstream = ZenohUpstream(clock, session, robot_clock_keys(ros2), robot, published=lambda: robot.published_seq,
                                         auth=auth)
            log.info("ROS 2 robot: %s in, %s out%s", topics.cmd_vel_sub, topics.odom_pub, " (lockstep)" if lockstep else "")
            try:
                robot.run(stop, rate_hz)
            finally:
                if upstream is not None:
                    upstream.close()
                if isinstance(clock, LockstepClock):
                    clock.close()
                robot.close()
        finally:
            close_session(session)
    return 0
