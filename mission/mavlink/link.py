"""The controller's narrow MAVLink 2 link to one PX4 vehicle: the facade over :mod:`mission.mavlink`.

One :class:`VehicleLink` talks to one autopilot through a transport chosen by URL. It identifies
the vehicle (``target_system`` set: its first PX4 HEARTBEAT; unset: :data:`ADOPT_HEARTBEATS`
consistent PX4 HEARTBEATs from one system while no other PX4 is heard) and from then on accepts
telemetry and ACKs only from it, replying only to the address (and signing link id) it was
identified from (:class:`~mission.mavlink.receiver.ReplyPin`; foreign systems are counted in
``rejected_foreign``); unset, a second PX4 autopilot heard after the adoption makes
:meth:`VehicleLink.identity_problem` say so. It sends our 1 Hz HEARTBEAT as an onboard controller of the
vehicle's own system (default system 1, component 191: PX4 registers an onboard controller of its
own system only), commands with ACK, retry and HEARTBEAT confirmation (blocking, one at a time,
thread-safe; a non-ACCEPTED result raises :class:`~mission.errors.CommandRejected`), and setpoints
only when asked: there is no background resend, so a dead control loop lets PX4's offboard-loss
failsafe fire. Every timeout, wait and receive stamp reads the injected clock (the wall clock
only for the tlog's and signing's timestamps). With a signing key every incoming packet must be
signed with it, and the key appears in no log, ``repr`` or tlog. Threads, the tlog format and the
signing rules: docs/mavlink.md.
"""
from __future__ import annotations

import dataclasses
import logging
import threading
from pathlib import Path
from typing import Any, Callable

from mission.core.setpoint import Setpoint
from mission.flight_mode import FlightMode
from mission.mavlink import px4
from mission.passenger.target import LandingTarget
from mission.time.clock import Clock, ScaledClock
from mission.config.urls import DEFAULT_URL
from mission.errors import LinkError
from mission.mavlink.codec import link_codecs
from mission.mavlink.commander import CommandClient, ParamClient
from mission.mavlink.heartbeat import HeartbeatSender
from mission.mavlink.identity import ADOPT_HEARTBEATS, VEHICLE_TYPES, Adoption
from mission.mavlink.receiver import LIMITER, Receiver, install_limiter
from mission.mavlink.session import LinkCounters, LinkSession
from mission.mavlink.setpoints import encode
from mission.mavlink.telemetry import VehicleState
from mission.mavlink.transport import Tlog, Transport, open_transport
from mission.mavlink.env import mavlink

__all__ = ["VehicleLink", "VehicleState", "LinkCounters", "DEFAULT_URL", "VEHICLE_TYPES", "ADOPT_HEARTBEATS"]

log = logging.getLogger(__name__)


class VehicleLink:
    """Narrow MAVLink 2 link to one PX4 vehicle: identify, read state, command, stream setpoints.

    Parameters
    ----------
    url:
        A link URL (:mod:`mission.mavlink.transport`): ``udpin:HOST:PORT`` (listen; the vehicle
        talks first; port 0 binds an ephemeral port, see :attr:`port`), ``udpout:``, ``tcp:``, or
        a serial device ``/dev/ttyACM0[:BAUD]``.
    clock:
        Injected clock for every timeout, period, wait and receive stamp [s].
    target_system, target_component:
        Accept only this vehicle (None: adopt one after consistent HEARTBEATs, see the module
        docstring; component 0: any).
    source_system, source_component:
        Our own ids: 1 (the vehicle's own system, see the module docstring) and 191 (onboard computer).
    tlog_path, signing_key:
        Write a ``.tlog`` of every packet sent and every valid packet received; a 32-byte MAVLink 2
        signing key (outgoing packets signed, incoming ones must be, HEARTBEAT included).
    heartbeat_timeout_s, heartbeat_period_s:
        The vehicle counts as lost after this long without a HEARTBEAT [s]; period of our own [s]
        (PX4 drops a peer 2.5 s after its last one).
    position_timeout_s, reason_grace_s:
        LOCAL_POSITION_NED older than this makes ``state.position_valid`` False [s]; after a
        refusal, how long to wait for the vehicle's STATUSTEXT reason [s].
    """

    def __init__(self, url: str = DEFAULT_URL, clock: Clock | None = None, *, target_system: int | None = None,
                 target_component: int = mavlink.MAV_COMP_ID_AUTOPILOT1, source_system: int = 1,
                 source_component: int = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER, tlog_path: str | Path | None = None,
                 signing_key: bytes | None = None, heartbeat_timeout_s: float = 3.0, heartbeat_period_s: float = 1.0,
                 position_timeout_s: float = 0.5, reason_grace_s: float = 1.0) -> None:
        _check_arguments(target_system, target_component, source_system, source_component, signing_key,
                         heartbeat_timeout_s=heartbeat_timeout_s, heartbeat_period_s=heartbeat_period_s,
                         position_timeout_s=position_timeout_s, reason_grace_s=reason_grace_s)
        self.url = url
        self._clock: Clock = clock if clock is not None else ScaledClock(1.0)
        self._target_system = None if target_system is None else int(target_system)
        self._target_component = int(target_component)
        self._source = (int(source_system), int(source_component))
        self._tlog_path = None if tlog_path is None else Path(tlog_path)
        self._signing_key = signing_key
        self.heartbeat_timeout_s, self.heartbeat_period_s = float(heartbeat_timeout_s), float(heartbeat_period_s)
        self.position_timeout_s, self.reason_grace_s = float(position_timeout_s), float(reason_grace_s)

        self._session = LinkSession(url, self._clock, self.position_timeout_s, signed=signing_key is not None)
        self._commander = CommandClient(self._session, self._send, self._require_vehicle, self.reason_grace_s)
        self._params = ParamClient(self._session, self._send, self._require_vehicle)
        self._tx_lock = threading.Lock()
        self._stop = threading.Event()
        self._heartbeat = HeartbeatSender(self._send, self._clock, self.heartbeat_period_s, self._flush_tlog)
        self._listeners: list[Callable[[Any], None]] = []
        self._threads: list[threading.Thread] = []
        self._transport: Transport | None = None
        self._opened = False
        self._tlog: Tlog | None = None
        self._tx_codec: Any = None

    def __repr__(self) -> str:
        state = "open" if self.is_open else "closed"
        return f"VehicleLink({self.url!r}, {state}, vehicle={self.vehicle_id}, signed={self._signing_key is not None})"

    # ---------------------------------------------------------------- lifetime

    @property
    def is_open(self) -> bool:
        return self._transport is not None

    def open(self) -> VehicleLink:
        """Bind/connect, start the receiver and the HEARTBEAT threads. Raises LinkError."""
        if self._opened:
            raise LinkError(f"link {self.url!r} was already opened; a VehicleLink opens once, make a new one")
        install_limiter()
        transport = open_transport(self.url)
        rx_codec, self._tx_codec = link_codecs(self._source, self._signing_key)
        try:
            self._tlog = None if self._tlog_path is None else Tlog(self._tlog_path, self._clock)
        except OSError as exc:
            transport.close()
            raise LinkError(f"cannot open tlog {self._tlog_path}: {exc}") from exc
        adoption = Adoption(self._target_system, self._target_component, self.heartbeat_timeout_s)
        receiver = Receiver(self._session, rx_codec, source_system=self._source[0], adoption=adoption,
                            signed=self._signing_key is not None, on_identified=self._heartbeat.announce,
                            on_packet=self._log_packet, listeners=self._listeners)
        self._transport, self._opened, self._session.closed = transport, True, False
        self._threads = [threading.Thread(target=receiver.run, args=(transport, self._stop), daemon=True,
                                          name=f"marsupial-link-rx:{self.url}"),
                         threading.Thread(target=self._heartbeat.run, name=f"marsupial-link-hb:{self.url}", daemon=True)]
        for thread in self._threads:
            thread.start()
        log.info("MAVLink link open on %s (local port %s, sysid %d compid %d%s)", self.url, self.port,
                 self._source[0], self._source[1], ", signed" if self._signing_key else "")
        return self

    def close(self) -> None:
        """Stop the threads, close the socket and the tlog. Idempotent; sends nothing."""
        self._stop.set()
        self._heartbeat.stop()
        for thread in self._threads:
            thread.join(timeout=2.0)
            if thread.is_alive():  # pragma: no cover - would be a bug in a loop
                log.error("link thread %s did not stop", thread.name)
        self._threads = []
        with self._tx_lock:
            transport, self._transport = self._transport, None
            tlog, self._tlog = self._tlog, None
        for resource in (transport, tlog):
            if resource is not None:
                resource.close()
        with self._session.changed:
            self._session.closed = True
            self._session.notify_locked()
        if transport is not None:
            log.info("MAVLink link %s closed: %s", self.url, self.counters)

    def __enter__(self) -> VehicleLink:
        return self if self.is_open else self.open()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @property
    def port(self) -> int | None:
        """The locally bound port (UDP/TCP), e.g. the ephemeral one of ``udpin:...:0``."""
        transport = self._transport
        return None if transport is None else transport.local_port()

    @property
    def clock(self) -> Clock:
        return self._clock

    # ---------------------------------------------------------------- identity and state

    @property
    def vehicle_id(self) -> tuple[int, int] | None:
        """(system id, component id) of the identified autopilot, or None."""
        with self._session.lock:
            return self._session.vehicle

    def wait_vehicle(self, timeout_s: float = 10.0) -> VehicleState:
        """Wait for a PX4 autopilot HEARTBEAT and lock onto its system [s of link clock].

        Raises LinkTimeout if none arrives in time.
        """
        return self.wait_until(lambda s: s.system_id is not None, timeout_s, "a PX4 autopilot HEARTBEAT")

    def wait_until(
        self, predicate: Callable[[VehicleState], bool], timeout_s: float, what: str = "condition"
    ) -> VehicleState:
        """Block until ``predicate(state)`` is true; return that state. Raises LinkTimeout."""
        return self._session.wait_until(predicate, timeout_s, what)

    @property
    def state(self) -> VehicleState:
        """Immutable snapshot of the vehicle's telemetry now."""
        with self._session.lock:
            return self._session.snapshot_locked()

    def heartbeat_age_s(self) -> float:
        """Clock seconds since the vehicle's last HEARTBEAT (inf before the first) [s]."""
        return self.state.heartbeat_age_s

    def vehicle_alive(self) -> bool:
        """True while the vehicle's HEARTBEAT is younger than ``heartbeat_timeout_s``."""
        return self.heartbeat_age_s() <= self.heartbeat_timeout_s

    @property
    def statustexts(self) -> list[tuple[float, int, str]]:
        """Reassembled vehicle STATUSTEXTs as (clock time [s], severity, text), oldest first."""
        with self._session.lock:
            return list(self._session.statustexts)

    def signing_problem(self) -> str | None:
        """Why no vehicle was identified on a signed link, if the reason is the key (a PX4
        autopilot heard only with another key's signatures); None otherwise."""
        return self._session.signing_problem()

    def identity_problem(self) -> str | None:
        """Why the identified vehicle is ambiguous: ``target_system`` unset and a second PX4
        autopilot heard after the adoption (:meth:`~mission.mavlink.identity.Adoption.rival`); None otherwise."""
        return self._session.identity_problem()

    @property
    def counters(self) -> LinkCounters:
        return dataclasses.replace(self._session.counters(), log_lines_held=LIMITER.suppressed_total())

    # ---------------------------------------------------------------- commands (mission.mavlink.commander)

    def command_long(self, command: int, *params: float, timeout_s: float = 0.5, retries: int = 3) -> int:
        """Send COMMAND_LONG and wait for its COMMAND_ACK (:meth:`CommandClient.command_long`)."""
        return self._commander.command_long(command, *params, timeout_s=timeout_s, retries=retries)

    def arm(self, timeout_s: float = 0.5, retries: int = 3, confirm_timeout_s: float = 2.5) -> None:
        """Arm and confirm it by HEARTBEAT (:meth:`CommandClient.arm`)."""
        self._commander.arm(timeout_s, retries, confirm_timeout_s)

    def disarm(self, force: bool = False, timeout_s: float = 0.5, retries: int = 3,
               confirm_timeout_s: float = 2.5) -> None:
        """Disarm (``force``: even in the air) and confirm it by HEARTBEAT (:meth:`CommandClient.disarm`)."""
        self._commander.disarm(force, timeout_s, retries, confirm_timeout_s)

    def set_mode(self, mode: str, timeout_s: float = 0.5, retries: int = 3, confirm_timeout_s: float = 2.5) -> None:
        """Switch the PX4 mode (a name of :data:`mission.mavlink.px4.MODES`) and confirm it by HEARTBEAT
        (:meth:`CommandClient.set_mode`: PX4's double ACK handled)."""
        self._commander.set_mode(mode, timeout_s, retries, confirm_timeout_s)

    def hold(self, timeout_s: float = 0.5, retries: int = 3, confirm_timeout_s: float = 2.5) -> None:
        """Switch to Hold (AUTO.LOITER), confirmed by HEARTBEAT (see :meth:`set_mode`)."""
        self.set_mode(px4.HOLD, timeout_s=timeout_s, retries=retries, confirm_timeout_s=confirm_timeout_s)

    def land(self, timeout_s: float = 0.5, retries: int = 3, confirm_timeout_s: float = 2.5) -> None:
        """Land where the vehicle is (AUTO.LAND, as for NAV_LAND), confirmed by HEARTBEAT (:meth:`set_mode`)."""
        self.set_mode(FlightMode.LAND, timeout_s=timeout_s, retries=retries, confirm_timeout_s=confirm_timeout_s)

    def takeoff(self, alt_m: float | None, timeout_s: float = 0.5, retries: int = 3) -> int:
        """MAV_CMD_NAV_TAKEOFF to ``alt_m`` [m] above the EKF origin (None: the vehicle's default),
        acknowledged only (:meth:`CommandClient.takeoff`)."""
        return self._commander.takeoff(alt_m, self.state.origin, timeout_s, retries)

    def set_home(self, home_ned_m: Any, timeout_s: float = 0.5, retries: int = 0) -> int:
        """Move PX4's home to ``home_ned_m`` [m] NED (:meth:`CommandClient.set_home`)."""
        return self._commander.set_home(home_ned_m, self.state.origin, timeout_s, retries)

    def get_param(self, name: str, timeout_s: float = 0.5, retries: int = 3) -> float:
        """The vehicle's parameter ``name`` (:meth:`ParamClient.get`)."""
        return self._params.get(name, timeout_s, retries).value

    def set_param(self, name: str, value: float, timeout_s: float = 0.5, retries: int = 3) -> float:
        """Set the vehicle's parameter ``name``; the value it kept (:meth:`ParamClient.set`)."""
        return self._params.set(name, value, timeout_s, retries).value

    def send(self, setpoint: Setpoint) -> None:
        """Send one setpoint as SET_POSITION_TARGET_LOCAL_NED (:func:`mission.mavlink.setpoints.encode`:
        velocity only or full, yaw or not, as the setpoint says; ``time_boot_ms`` is the link
        clock). Nothing is resent in the background. Raises ValueError for a non-finite (or
        float32-overflowing) value, before anything is sent."""
        msg = encode(setpoint, self._require_vehicle(), int(self._clock.now() * 1000.0))
        self._send(msg, "tx_setpoints")

    def send_landing_target(self, target: LandingTarget) -> None:
        """The deck's landing point as LANDING_TARGET (:func:`~mission.mavlink.px4.encode_landing_target`; ValueError beyond float32)."""
        self._send(px4.encode_landing_target(target), "tx_landing_targets")

    def _require_vehicle(self) -> tuple[int, int]:
        if self._transport is None:
            raise LinkError(f"link {self.url!r} is not open")
        vehicle = self.vehicle_id
        if vehicle is None:
            raise LinkError("no vehicle identified yet: call wait_vehicle() first")
        return vehicle

    def set_message_interval(self, message_id: int, rate_hz: float, timeout_s: float = 0.5, retries: int = 2) -> None:
        """Ask the vehicle to stream ``message_id`` at ``rate_hz`` [Hz] (:meth:`CommandClient.set_message_interval`);
        the rate that actually arrives is :meth:`message_rate_hz`."""
        self._commander.set_message_interval(message_id, rate_hz, timeout_s, retries)

    def message_rate_hz(self, kind: str = "LOCAL_POSITION_NED", window_s: float = 1.0) -> float:
        """Rate [Hz of link clock] at which ``kind`` arrived over the last ``window_s`` [s]
        (kept for LOCAL_POSITION_NED only); 0 when none."""
        return self._session.position_rate_hz(window_s)

    def send_message(self, msg: Any) -> bool:
        """Send any pymavlink message as is (e.g. the lockstep TIMESYNC answer); False if there
        is no peer yet. Raises LinkError on socket errors or a closed link."""
        return self._send(msg, None)

    def add_listener(self, callback: Callable[[Any], None]) -> None:
        """Call ``callback(msg)`` for every message from the identified vehicle, in the receiver
        thread, after the link has handled it (e.g. the lockstep clock reads SYSTEM_TIME)."""
        self._listeners.append(callback)

    def _send(self, msg: Any, counter: str | None) -> bool:
        """Encode (and sign), write and log one message. Returns False if there is no peer yet.

        Raises LinkError on socket errors or a closed link.
        """
        with self._tx_lock:
            transport = self._transport
            if transport is None:
                raise LinkError(f"link {self.url!r} is not open")
            buf = msg.pack(self._tx_codec)
            try:
                sent = transport.write(buf)
            except OSError as exc:
                self._session.count("tx_errors")
                raise LinkError(f"send {msg.get_type()} on {self.url}: {exc}") from exc
            if not sent:
                return False
            self._tx_codec.seq = (self._tx_codec.seq + 1) % 256
            self._log_packet(buf)
        self._session.count("tx_messages", counter)
        return True

    def _log_packet(self, packet: bytes | bytearray) -> None:
        if (tlog := self._tlog) is not None:
            tlog.write(packet)

    def _flush_tlog(self) -> None:
        if (tlog := self._tlog) is not None:
            tlog.flush()


def _check_arguments(target_system: int | None, target_component: int, source_system: int, source_component: int,
                     signing_key: bytes | None, **periods_s: float) -> None:
    """ValueError naming the first argument of :class:`VehicleLink` out of its range."""
    for name, value in (("source_system", source_system), ("source_component", source_component)):
        if not 1 <= int(value) <= 255:
            raise ValueError(f"{name} must be in 1..255, got {value!r}")
    if target_system is not None and not 1 <= int(target_system) <= 255:
        raise ValueError(f"target_system must be in 1..255 or None, got {target_system!r}")
    if not 0 <= int(target_component) <= 255:
        raise ValueError(f"target_component must be in 0..255, got {target_component!r}")
    if signing_key is not None and (not isinstance(signing_key, bytes) or len(signing_key) != 32):
        raise ValueError("signing_key must be 32 bytes")  # never echo the key
    for name, value in periods_s.items():
        if not value > 0:
            raise ValueError(f"{name} must be > 0, got {value!r}")
