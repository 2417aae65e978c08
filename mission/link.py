"""The controller's narrow MAVLink 2 link to one PX4 vehicle (pymavlink codec).

One :class:`VehicleLink` talks to one autopilot. It

* opens a transport chosen by URL (``udpin:HOST:PORT`` listen, the default and PX4 SITL's
  onboard link; ``udpout:HOST:PORT``; ``tcp:HOST:PORT``; a serial device ``/dev/ttyX[:BAUD]`` or
  ``serial:/dev/ttyX[:BAUD]``, passed to pymavlink's ``mavserial``);
* identifies the vehicle (see Vehicle identity below) and from then on accepts telemetry and
  COMMAND_ACKs only from that system and component; other systems are counted in
  ``counters.rejected_foreign`` and ignored. On ``udpin`` replies go only to the address the
  vehicle last sent from, and only a message that passed every check (signature, identity)
  moves it (pymavlink's ``mavudp`` would send to every address that ever talked to the port, a
  rogue sender included);
* sends its own 1 Hz (link clock) HEARTBEAT as an onboard controller (type 18, autopilot 8);
* sends commands with ACK, retry and timeout; a non-ACCEPTED result raises
  :class:`~mission.errors.CommandRejected` carrying the vehicle's STATUSTEXT reason;
* confirms mode changes and arming by HEARTBEAT, not by an ACK alone (PX4 of 2025 ACKs
  DO_SET_MODE twice: ACCEPTED from the MAVLink layer, then the real result);
* sends velocity setpoints (SET_POSITION_TARGET_LOCAL_NED, LOCAL_NED, velocity-only mask) only
  when asked: there is deliberately no background resend, so a dead control loop lets PX4's
  offboard-loss failsafe fire (REFERENCE lesson 4);
* writes a ``.tlog`` (8-byte big-endian microsecond stamp + raw packet) of every packet sent and
  every valid packet received, readable by ``mavlogdump.py``.

Vehicle identity. With ``target_system`` set (``mavlink.target_system``), the first HEARTBEAT
of a PX4 autopilot (autopilot 12) of a vehicle type (:data:`VEHICLE_TYPES`) from that system and
``target_component`` identifies it. Unset, a vehicle is adopted only after
:data:`ADOPT_HEARTBEATS` such HEARTBEATs from one system and component with the same type, none
older than ``heartbeat_timeout_s``, while no other PX4 autopilot is heard (two at once: neither
is adopted, a warning says to set ``mavlink.target_system``). What was adopted is logged. A
stray HEARTBEAT of another system (a rogue sysid 42 talking first) is counted in
``rejected_foreign`` and never becomes the vehicle.

Our identity. By default the link uses system id 1 and component 191 (MAV_COMP_ID_ONBOARD_COMPUTER):
a companion computer is a component of the UAV's own system, and PX4 only registers an
ONBOARD_CONTROLLER heartbeat that comes from its own system id (``mavlink_receiver.cpp``,
``same_system``). PX4's default MAV_SYS_ID is 1; set ``source_system`` if the vehicle's differs.

Blocking calls. ``command_long``, ``arm``, ``disarm``, ``set_mode``, ``hold``, ``land`` and
``takeoff`` block until ACKed (and confirmed by HEARTBEAT); they are thread-safe (one command at a
time). PX4 needs setpoints during and after a switch to OFFBOARD, so a control loop calls them
from a worker thread while it keeps calling ``send_velocity_ned``.

Threads. A receiver thread blocks in ``select`` (50 ms wall slices, so ``close`` is prompt) and
parses each datagram at once; a heartbeat thread sends HEARTBEAT and flushes the tlog. Telemetry
is kept under one lock; :attr:`VehicleLink.state` returns an immutable snapshot. The receiver
never dies on bad input: every parse or handler error is caught and counted.

Time. Every timeout, deadline and receive stamp reads the injected clock (``clock.now()``, in
seconds of simulated time); every wait goes through it (``clock.wait``, ``clock.notify``), so the
link runs the same on a scaled wall clock and in lockstep (:mod:`mission.lockstep`).
The wall clock is read once at ``open`` only where a format defines a wall time: the tlog's
epoch stamps and the MAVLink 2 signing timestamp.

Signing (optional, ``signing_key`` of 32 bytes). Outgoing packets are signed; every incoming
packet, HEARTBEAT included, counts only with a valid signature made with our key: an unsigned
one is dropped (``rx_unsigned``), one signed with another key or replayed is dropped
(``rx_bad_signature``); neither identifies a vehicle, changes its state or moves the reply
address. A PX4 HEARTBEAT signed with another key is remembered so that
:meth:`VehicleLink.signing_problem` can say "wrong key" rather than "no vehicle". A refused
packet never advances pymavlink's per-stream replay timestamp (pymavlink updates it before it
checks the signature, so one forged packet stamped in the future would lock the real vehicle
out). The key is never logged, never in ``repr`` and never in the tlog (signed packets carry
only a 6-byte truncated SHA-256).
"""
from __future__ import annotations

import collections
import errno
import logging
import math
import select
import socket
import struct
import threading
import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import IO, Any, Callable, Protocol

import numpy as np

from mission import px4
from mission.clock import Clock, ScaledClock
from mission.errors import CommandRejected, LinkError, LinkPortInUse, LinkTimeout, PortInUse
from mission.mavlink_env import mavlink, mavutil
from mission.port_holder import is_addr_in_use, port_in_use

__all__ = ["VehicleLink", "VehicleState", "LinkCounters", "DEFAULT_URL", "VEHICLE_TYPES", "ADOPT_HEARTBEATS"]

log = logging.getLogger(__name__)

DEFAULT_URL = "udpin:127.0.0.1:14540"
MAV_COMP_ID_AUTOPILOT1 = 1
MAV_COMP_ID_ONBOARD_COMPUTER = 191
MAV_AUTOPILOT_INVALID = 8
MAV_RESULT_IN_PROGRESS = 5
MAV_STATE_ACTIVE = 4
#: MAV_TYPEs of a vehicle (what PX4 flies or drives; the passenger UAV and a PX4 rover or boat
#: carrier share this link code): fixed wing 1, quadrotor 2, coaxial 3, helicopter 4, airship 7,
#: balloon 8, rocket 9, ground rover 10, surface boat 11, submarine 12, hexa 13, octo 14, tricopter
#: 15, flapping wing 16, kite 17, VTOLs 19-25, parafoil 28, dodeca 29, deca 35, generic multirotor
#: 43, quadruped 46, VTOL gyrodyne 47. Anything else (a GCS 6, an onboard controller 18, a gimbal,
#: a camera, an ADS-B receiver...) is never adopted as the vehicle.
VEHICLE_TYPES = frozenset({1, 2, 3, 4, *range(7, 18), *range(19, 26), 28, 29, 35, 43, 46, 47})
#: Consistent HEARTBEATs needed to adopt a vehicle when ``target_system`` is not configured.
ADOPT_HEARTBEATS = 3
_STATUSTEXT_CHUNK_LEN = 50
_SEVERITY_WARNING = 4  # MAV_SEVERITY_WARNING; EMERGENCY 0 .. DEBUG 7
_FLOAT32_MAX = float(np.finfo(np.float32).max)
_WALL_SLICE_S = 0.05  # longest wall-clock block of the receiver and of condition waits
_SIGNING_EPOCH_S = 1420070400  # 2015-01-01T00:00:00Z, MAVLink 2 signing epoch

Address = tuple[str, int]


# --------------------------------------------------------------------------------------------
# Public data
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class VehicleState:
    """Immutable snapshot of the vehicle's telemetry, as the link last heard it.

    Times are link-clock seconds [s]. Positions and velocities are PX4's local NED frame
    (x north, y east, z down) relative to the EKF origin; arrays are read-only.
    """

    t_s: float
    """Clock time the snapshot was taken [s]."""
    system_id: int | None
    """Identified vehicle system id (None before identification)."""
    component_id: int | None
    """Identified autopilot component id (None before identification)."""
    position_ned_m: np.ndarray | None
    """Position [m] NED, shape (3,), from LOCAL_POSITION_NED; None before the first one."""
    velocity_ned_m_s: np.ndarray | None
    """Velocity [m/s] NED, shape (3,), from LOCAL_POSITION_NED; None before the first one."""
    position_rx_s: float | None
    """Clock time the last LOCAL_POSITION_NED was received [s]."""
    heartbeat_rx_s: float | None
    """Clock time the last vehicle HEARTBEAT was received [s]."""
    armed: bool
    """HEARTBEAT base_mode has MAV_MODE_FLAG_SAFETY_ARMED."""
    mode: str
    """PX4 mode name (:func:`mission.px4.mode_name`), e.g. ``"OFFBOARD"``; ``""`` before a HEARTBEAT."""
    custom_mode: int
    """Raw HEARTBEAT custom_mode."""
    base_mode: int
    """Raw HEARTBEAT base_mode."""
    system_status: int
    """HEARTBEAT system_status (MAV_STATE: 3 STANDBY, 4 ACTIVE, 5 CRITICAL...)."""
    landed_state: int | None
    """EXTENDED_SYS_STATE landed_state (1 ON_GROUND, 2 IN_AIR, 3 TAKEOFF, 4 LANDING) or None."""
    position_valid: bool
    """A fresh, finite LOCAL_POSITION_NED (age <= the link's position_timeout_s) and, when
    SYS_STATUS reports the AHRS/estimator as present and enabled, that it is healthy."""
    origin: tuple[float, float, float] | None
    """EKF origin (lat [deg], lon [deg], alt [m] AMSL) from GPS_GLOBAL_ORIGIN, or None."""
    last_statustext: str
    """Text of the latest (reassembled) STATUSTEXT from the vehicle, ``""`` if none."""
    yaw_rad: float | None = None
    """Heading [rad] from north towards east, from ATTITUDE; None before the first (or non-finite)."""
    position_t_s: float | None = None
    """Clock time the vehicle took that sample [s]: its ``time_boot_ms`` mapped onto the link
    clock (:class:`_VehicleClock`); earlier than ``position_rx_s`` by the transport delay and
    by however long the sample waited to be read (a stalled process reads a burst of old
    samples at once)."""

    @property
    def heartbeat_age_s(self) -> float:
        """Seconds since the last vehicle HEARTBEAT at snapshot time (inf if none) [s]."""
        return math.inf if self.heartbeat_rx_s is None else self.t_s - self.heartbeat_rx_s

    @property
    def position_age_s(self) -> float:
        """Seconds since the last LOCAL_POSITION_NED at snapshot time (inf if none) [s]."""
        return math.inf if self.position_rx_s is None else self.t_s - self.position_rx_s


@dataclass(frozen=True)
class LinkCounters:
    """Snapshot of the link's packet counters (monotonic since ``open``)."""

    rx_bytes: int = 0
    rx_messages: int = 0
    """Valid packets decoded (any sender, unknown ids included)."""
    rx_bad: int = 0
    """Garbage, CRC, length, signature and parse errors (the receiver survived each)."""
    rx_bad_signature: int = 0
    """Subset of rx_bad: signed packets refused (another key, or a replayed timestamp)."""
    rx_unsigned: int = 0
    """Subset of rx_bad: unsigned packets refused by a signed link (HEARTBEAT included)."""
    rx_unknown: int = 0
    """Valid packets whose message id is not in the dialect (e.g. PX4's 380, 410, 411)."""
    rx_ignored: int = 0
    """Valid packets not applied: before identification, or from another component."""
    rejected_foreign: int = 0
    """Valid packets from a system other than the identified vehicle, and HEARTBEATs of other
    autopilots heard while none was adopted yet."""
    rx_errors: int = 0
    """Socket errors and unexpected handler exceptions in the receiver."""
    tx_messages: int = 0
    tx_heartbeats: int = 0
    tx_setpoints: int = 0
    tx_commands: int = 0
    """COMMAND_LONG packets sent, retries included."""
    tx_errors: int = 0
    command_retries: int = 0
    command_timeouts: int = 0
    command_rejections: int = 0


# --------------------------------------------------------------------------------------------
# Transports: bytes in and out, nothing MAVLink-specific
# --------------------------------------------------------------------------------------------


class _Transport(Protocol):
    datagram: bool
    """True if every read is one whole datagram (the parser is reset after each)."""

    def read(self, timeout_wall_s: float) -> tuple[bytes, Address | None]: ...

    def write(self, buf: bytes) -> bool: ...

    def set_peer(self, address: Address) -> None: ...

    def local_port(self) -> int | None: ...

    def close(self) -> None: ...


def _split_host_port(spec: str, url: str) -> tuple[str, int]:
    host, sep, port = spec.rpartition(":")
    if not sep or not host:
        raise LinkError(f"link url {url!r}: expected HOST:PORT")
    try:
        number = int(port)
    except ValueError:
        raise LinkError(f"link url {url!r}: port {port!r} is not an integer") from None
    if not 0 <= number <= 65535:
        raise LinkError(f"link url {url!r}: port {number} out of range")
    return host, number


class _UdpTransport:
    """UDP socket. ``listen``: bind HOST:PORT and answer the latest vehicle address;
    otherwise send to HOST:PORT from an ephemeral port."""

    datagram = True

    def __init__(self, host: str, port: int, listen: bool) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            if listen:
                self._sock.bind((host, port))
                self._peer: Address | None = None
            else:
                self._peer = (socket.gethostbyname(host), port)
                self._sock.bind(("0.0.0.0", 0))
        except OSError as exc:
            self._sock.close()
            if listen and is_addr_in_use(exc):
                raise port_in_use(f"MAVLink link udpin:{host}:{port}", host, port, cls=LinkPortInUse) from None
            raise
        self._listen = listen

    def read(self, timeout_wall_s: float) -> tuple[bytes, Address | None]:
        ready, _, _ = select.select([self._sock], [], [], timeout_wall_s)
        if not ready:
            return b"", None
        try:
            data, address = self._sock.recvfrom(65535)
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.ECONNREFUSED):
                return b"", None
            raise
        return data, address

    def write(self, buf: bytes) -> bool:
        peer = self._peer
        if peer is None:
            return False
        self._sock.sendto(buf, peer)
        return True

    def set_peer(self, address: Address) -> None:
        if self._listen:
            self._peer = address

    def local_port(self) -> int | None:
        return int(self._sock.getsockname()[1])

    def close(self) -> None:
        self._sock.close()


class _TcpTransport:
    """TCP client connection to HOST:PORT (a byte stream)."""

    datagram = False

    def __init__(self, host: str, port: int, connect_timeout_s: float = 3.0) -> None:
        self._sock = socket.create_connection((host, port), timeout=connect_timeout_s)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock.settimeout(None)
        self._address: Address = (host, port)
        self._write_lock = threading.Lock()

    def read(self, timeout_wall_s: float) -> tuple[bytes, Address | None]:
        ready, _, _ = select.select([self._sock], [], [], timeout_wall_s)
        if not ready:
            return b"", None
        data = self._sock.recv(65535)
        if not data:
            raise ConnectionResetError(errno.ECONNRESET, "TCP peer closed the connection")
        return data, self._address

    def write(self, buf: bytes) -> bool:
        with self._write_lock:
            self._sock.sendall(buf)
        return True

    def set_peer(self, address: Address) -> None:
        return None

    def local_port(self) -> int | None:
        return int(self._sock.getsockname()[1])

    def close(self) -> None:
        self._sock.close()


class _SerialTransport:
    """Serial device through pymavlink's ``mavserial`` (a byte stream)."""

    datagram = False

    def __init__(self, device: str, baud: int) -> None:
        self._conn: Any = mavutil.mavlink_connection(device, baud=baud, autoreconnect=False)

    def read(self, timeout_wall_s: float) -> tuple[bytes, Address | None]:
        if not self._conn.select(timeout_wall_s):
            return b"", None
        data = self._conn.recv(4096)
        return (data.encode("latin-1") if isinstance(data, str) else bytes(data)), None

    def write(self, buf: bytes) -> bool:
        self._conn.write(buf)
        return True

    def set_peer(self, address: Address) -> None:
        return None

    def local_port(self) -> int | None:
        return None

    def close(self) -> None:
        self._conn.close()


def _open_transport(url: str) -> _Transport:
    """Open the transport a URL names; foreign errors become :class:`LinkError`."""
    scheme, sep, rest = url.partition(":")
    try:
        if sep and scheme in ("udpin", "udp"):
            return _UdpTransport(*_split_host_port(rest, url), listen=True)
        if sep and scheme == "udpout":
            return _UdpTransport(*_split_host_port(rest, url), listen=False)
        if sep and scheme == "tcp":
            return _TcpTransport(*_split_host_port(rest, url))
        device = rest if scheme == "serial" else url
        if device.startswith("/") or device.upper().startswith("COM"):
            path, _, baud = device.replace(",", ":").partition(":")
            return _SerialTransport(path, int(baud) if baud else 57600)
    except (LinkError, PortInUse):
        raise
    except (OSError, ValueError, ImportError) as exc:
        raise LinkError(f"cannot open MAVLink link {url!r}: {exc}") from exc
    except Exception as exc:  # serial.SerialException and other foreign errors
        raise LinkError(f"cannot open MAVLink link {url!r}: {exc}") from exc
    raise LinkError(
        f"link url {url!r}: expected udpin:HOST:PORT, udpout:HOST:PORT, tcp:HOST:PORT or a serial device"
    )


# --------------------------------------------------------------------------------------------
# Small helpers
# --------------------------------------------------------------------------------------------


def _new_codec(source_system: int, source_component: int) -> Any:
    """A pymavlink MAVLink 2 (``common`` dialect) encoder/decoder with robust parsing."""
    codec = mavlink.MAVLink(None, srcSystem=source_system, srcComponent=source_component)
    codec.robust_parsing = True
    return codec


def _reset_parser(codec: Any) -> None:
    """Drop a partial packet left in the parser (a datagram never continues in the next)."""
    codec.buf = bytearray()
    codec.buf_index = 0
    codec.expected_length = mavlink.HEADER_LEN_V1 + 2


def _refuse_unsigned(_codec: Any, _msg_id: int) -> bool:
    """Signing policy: nothing may arrive unsigned (HEARTBEAT included)."""
    return False


def _keep_replay_state_on_failure(codec: Any) -> None:
    """Make ``codec``'s signature check leave its per-stream replay timestamp alone when the
    check fails (pymavlink stores a packet's timestamp before verifying its signature)."""
    check = codec.check_signature

    def check_signature(msgbuf: bytearray, src_system: int, src_component: int) -> bool:
        streams = codec.signing.stream_timestamps
        stream = (msgbuf[-13], src_system, src_component)
        before = streams.get(stream)
        ok = bool(check(msgbuf, src_system, src_component))
        if not ok:
            if before is None:
                streams.pop(stream, None)
            else:
                streams[stream] = before
        return ok

    codec.check_signature = check_signature


def _statustext_level(severity: int) -> int:
    if severity <= 3:
        return logging.ERROR
    if severity == 4:
        return logging.WARNING
    return logging.INFO if severity <= 6 else logging.DEBUG


def _readonly_vector(x: float, y: float, z: float) -> np.ndarray:
    v = np.array([x, y, z], dtype=float)
    v.setflags(write=False)
    return v


class _StatusTextAssembler:
    """Reassembles chunked STATUSTEXT (MAVLink 2 ``id``/``chunk_seq``); a chunk shorter than
    50 characters ends a text. Keeps at most a few texts pending."""

    def __init__(self, max_pending: int = 4) -> None:
        self._pending: collections.OrderedDict[int, dict[int, str]] = collections.OrderedDict()
        self._max_pending = max_pending

    def feed(self, text: str, text_id: int, chunk_seq: int) -> str | None:
        """Add one chunk; return the whole text when complete, else None."""
        if text_id == 0:
            return text
        parts = self._pending.setdefault(text_id, {})
        parts[chunk_seq] = text
        if len(text) < _STATUSTEXT_CHUNK_LEN:
            del self._pending[text_id]
            return "".join(parts[k] for k in sorted(parts))
        while len(self._pending) > self._max_pending:
            self._pending.popitem(last=False)
        return None


@dataclass(frozen=True)
class _Ack:
    seq: int
    t_s: float
    command: int
    result: int


class _VehicleClock:
    """Maps the vehicle's ``time_boot_ms`` [s] onto the link clock [s].

    The offset ``t_link - t_vehicle`` is the smallest one seen (the least-delayed sample), allowed
    to grow by ``drift`` seconds per second so a vehicle clock running slower than ours (PX4 SITL
    at 0.9x) is followed; a vehicle reboot (time going backwards) starts afresh.
    """

    def __init__(self, drift: float = 0.1) -> None:
        self.drift = drift
        self._offset: float | None = None
        self._last: tuple[float, float] | None = None  # (vehicle time, link time) of the last sample

    def to_link(self, t_vehicle_s: float, t_rx_s: float) -> float:
        offset = t_rx_s - t_vehicle_s
        if self._offset is None or self._last is None or t_vehicle_s < self._last[0]:
            self._offset = offset
        else:
            self._offset = min(self._offset + self.drift * max(t_rx_s - self._last[1], 0.0), offset)
        self._last = (t_vehicle_s, t_rx_s)
        return t_vehicle_s + self._offset


class _Telemetry:
    """Mutable telemetry behind the link's lock (the receiver writes, snapshots read)."""

    def __init__(self) -> None:
        self.position_ned_m: np.ndarray | None = None
        self.velocity_ned_m_s: np.ndarray | None = None
        self.position_finite = False  # position and velocity all finite (checked once per message)
        self.position_rx_s: float | None = None
        self.position_t_s: float | None = None
        self.vehicle_clock = _VehicleClock()
        self.heartbeat_rx_s: float | None = None
        self.base_mode = 0
        self.custom_mode = 0
        self.mode = ""
        self.system_status = 0
        self.landed_state: int | None = None
        self.ahrs_healthy: bool | None = None
        self.origin: tuple[float, float, float] | None = None
        self.yaw_rad: float | None = None
        self.last_statustext = ""


# --------------------------------------------------------------------------------------------
# The link
# --------------------------------------------------------------------------------------------


class VehicleLink:
    """Narrow MAVLink 2 link to one PX4 vehicle: identify, read state, command, stream setpoints.

    Parameters
    ----------
    url:
        ``udpin:HOST:PORT`` (listen; the vehicle talks first; port 0 binds an ephemeral port, see
        :attr:`port`), ``udpout:HOST:PORT``, ``tcp:HOST:PORT``, or a serial device
        ``/dev/ttyACM0[:BAUD]`` / ``serial:/dev/ttyACM0[:BAUD]`` (default 57600 baud).
    clock:
        Injected clock for every timeout, period and receive stamp [s].
    target_system, target_component:
        Accept only this vehicle. ``target_system=None`` adopts a PX4 autopilot after
        :data:`ADOPT_HEARTBEATS` consistent HEARTBEATs (see the module docstring);
        ``target_component`` is the autopilot's component id (1; 0 accepts any).
    source_system, source_component:
        Our own ids: default 1 (the vehicle's own system, see the module docstring) and 191
        (MAV_COMP_ID_ONBOARD_COMPUTER).
    tlog_path:
        Write a ``.tlog`` of every packet sent and every valid packet received.
    signing_key:
        32-byte MAVLink 2 signing key; outgoing packets are signed, incoming ones must be
        (HEARTBEAT included).
    heartbeat_timeout_s:
        The vehicle counts as lost after this long without a HEARTBEAT [s] (:meth:`vehicle_alive`).
    heartbeat_period_s:
        Period of our own HEARTBEAT [s] (PX4 drops a peer 2.5 s after its last one).
    position_timeout_s:
        LOCAL_POSITION_NED older than this makes ``state.position_valid`` False [s].
    reason_grace_s:
        After a refusal, how long to wait for the vehicle's STATUSTEXT reason if it has not
        come yet [s] (spent only on refusals without a WARNING-or-worse text).
    """

    def __init__(
        self,
        url: str = DEFAULT_URL,
        clock: Clock | None = None,
        *,
        target_system: int | None = None,
        target_component: int = MAV_COMP_ID_AUTOPILOT1,
        source_system: int = 1,
        source_component: int = MAV_COMP_ID_ONBOARD_COMPUTER,
        tlog_path: str | Path | None = None,
        signing_key: bytes | None = None,
        heartbeat_timeout_s: float = 3.0,
        heartbeat_period_s: float = 1.0,
        position_timeout_s: float = 0.5,
        reason_grace_s: float = 1.0,
    ) -> None:
        for name, value in (("source_system", source_system), ("source_component", source_component)):
            if not 1 <= int(value) <= 255:
                raise ValueError(f"{name} must be in 1..255, got {value!r}")
        if target_system is not None and not 1 <= int(target_system) <= 255:
            raise ValueError(f"target_system must be in 1..255 or None, got {target_system!r}")
        if not 0 <= int(target_component) <= 255:
            raise ValueError(f"target_component must be in 0..255, got {target_component!r}")
        if signing_key is not None and (not isinstance(signing_key, bytes) or len(signing_key) != 32):
            raise ValueError("signing_key must be 32 bytes")  # never echo the key
        for name, value in (
            ("heartbeat_timeout_s", heartbeat_timeout_s),
            ("heartbeat_period_s", heartbeat_period_s),
            ("position_timeout_s", position_timeout_s),
            ("reason_grace_s", reason_grace_s),
        ):
            if not value > 0:
                raise ValueError(f"{name} must be > 0, got {value!r}")
        self.url = url
        self._clock: Clock = clock if clock is not None else ScaledClock(1.0)
        self._target_system = None if target_system is None else int(target_system)
        self._target_component = int(target_component)
        self._source = (int(source_system), int(source_component))
        self._tlog_path = None if tlog_path is None else Path(tlog_path)
        self._signing_key = signing_key
        self.heartbeat_timeout_s = float(heartbeat_timeout_s)
        self.heartbeat_period_s = float(heartbeat_period_s)
        self.position_timeout_s = float(position_timeout_s)
        self.reason_grace_s = float(reason_grace_s)

        self._lock = threading.RLock()  # re-entrant: wait_until predicates may read link.state
        self._changed = threading.Condition(self._lock)
        self._tx_lock = threading.Lock()
        self._command_lock = threading.Lock()
        self._stop = threading.Event()
        self._heartbeat_cond = threading.Condition()
        self._listeners: list[Callable[[Any], None]] = []
        self._threads: list[threading.Thread] = []
        self._transport: _Transport | None = None
        self._opened = False
        self._tlog: IO[bytes] | None = None
        self._tlog_epoch_us = 0
        self._rx_codec: Any = None
        self._tx_codec: Any = None
        self._vehicle: tuple[int, int] | None = None
        self._telemetry = _Telemetry()
        self._position_stamps: collections.deque[float] = collections.deque(maxlen=256)
        self._statustexts: collections.deque[tuple[float, int, str]] = collections.deque(maxlen=500)
        self._assembler = _StatusTextAssembler()
        self._acks: collections.deque[_Ack] = collections.deque(maxlen=64)
        self._ack_seq = 0
        self._counts: dict[str, int] = {f.name: 0 for f in fields(LinkCounters)}
        self._ignored_autopilots: set[tuple[int, int]] = set()
        # unidentified PX4 autopilots heard: (sysid, compid) -> [heartbeats, last rx [s], MAV_TYPE]
        self._candidates: dict[tuple[int, int], list[Any]] = {}
        self._ambiguous_warned = False
        self._heard: dict[tuple[int, int], int] = {}  # PX4 HEARTBEATs heard before adoption, per source
        self._wrong_key: tuple[int, int, int] | None = None  # (sysid, compid, HEARTBEATs) signed with another key

    def __repr__(self) -> str:
        state = "open" if self.is_open else "closed"
        return f"VehicleLink({self.url!r}, {state}, vehicle={self._vehicle}, signed={self._signing_key is not None})"

    # ---------------------------------------------------------------- lifetime

    @property
    def is_open(self) -> bool:
        return self._transport is not None

    def open(self) -> VehicleLink:
        """Bind/connect, start the receiver and the HEARTBEAT threads. Raises LinkError."""
        if self._opened:
            raise LinkError(f"link {self.url!r} was already opened; a VehicleLink opens once, make a new one")
        transport = _open_transport(self.url)
        try:
            self._setup_codecs()
            if self._tlog_path is not None:
                self._tlog = open(self._tlog_path, "wb")
                self._tlog_epoch_us = time.time_ns() // 1000 - int(self._clock.now() * 1e6)
        except OSError as exc:
            transport.close()
            raise LinkError(f"cannot open tlog {self._tlog_path}: {exc}") from exc
        self._transport, self._opened = transport, True
        self._threads = [
            threading.Thread(target=self._receive_loop, name=f"marsupial-link-rx:{self.url}", daemon=True),
            threading.Thread(target=self._heartbeat_loop, name=f"marsupial-link-hb:{self.url}", daemon=True),
        ]
        for thread in self._threads:
            thread.start()
        log.info("MAVLink link open on %s (local port %s, sysid %d compid %d%s)", self.url, self.port,
                 self._source[0], self._source[1], ", signed" if self._signing_key else "")
        return self

    def close(self) -> None:
        """Stop the threads, close the socket and the tlog. Idempotent; sends nothing."""
        self._stop.set()
        with self._heartbeat_cond:
            self._clock.notify(self._heartbeat_cond)
        for thread in self._threads:
            thread.join(timeout=2.0)
            if thread.is_alive():  # pragma: no cover - would be a bug in a loop
                log.error("link thread %s did not stop", thread.name)
        self._threads = []
        transport, self._transport = self._transport, None
        if transport is not None:
            transport.close()
        with self._tx_lock:
            tlog, self._tlog = self._tlog, None
            if tlog is not None:
                tlog.close()
        with self._changed:
            self._clock.notify(self._changed)
        if transport is not None:
            log.info("MAVLink link %s closed: %s", self.url, self.counters)

    def __enter__(self) -> VehicleLink:
        if not self.is_open:
            self.open()
        return self

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
        with self._lock:
            return self._vehicle

    def wait_vehicle(self, timeout_s: float = 10.0) -> VehicleState:
        """Wait for a PX4 autopilot HEARTBEAT and lock onto its system [s of link clock].

        Raises LinkTimeout if none arrives in time.
        """
        return self.wait_until(lambda s: s.system_id is not None, timeout_s, "a PX4 autopilot HEARTBEAT")

    def wait_until(
        self, predicate: Callable[[VehicleState], bool], timeout_s: float, what: str = "condition"
    ) -> VehicleState:
        """Block until ``predicate(state)`` is true; return that state. Raises LinkTimeout."""
        deadline = self._clock.now() + timeout_s
        with self._changed:
            while True:
                snapshot = self._snapshot_locked()
                if predicate(snapshot):
                    return snapshot
                if not self._wait_locked(deadline):
                    raise LinkTimeout(f"{what} not seen within {timeout_s:g} s on {self.url}")

    @property
    def state(self) -> VehicleState:
        """Immutable snapshot of the vehicle's telemetry now."""
        with self._lock:
            return self._snapshot_locked()

    def heartbeat_age_s(self) -> float:
        """Clock seconds since the vehicle's last HEARTBEAT (inf before the first) [s]."""
        with self._lock:
            rx = self._telemetry.heartbeat_rx_s
        return math.inf if rx is None else self._clock.now() - rx

    def vehicle_alive(self) -> bool:
        """True while the vehicle's HEARTBEAT is younger than ``heartbeat_timeout_s``."""
        return self.heartbeat_age_s() <= self.heartbeat_timeout_s

    @property
    def statustexts(self) -> list[tuple[float, int, str]]:
        """Reassembled vehicle STATUSTEXTs as (clock time [s], severity, text), oldest first."""
        with self._lock:
            return list(self._statustexts)

    @property
    def counters(self) -> LinkCounters:
        with self._lock:
            return LinkCounters(**self._counts)

    def _snapshot_locked(self) -> VehicleState:
        tm, now = self._telemetry, self._clock.now()
        fresh = (
            tm.position_rx_s is not None
            and now - tm.position_rx_s <= self.position_timeout_s
            and tm.position_finite
        )
        return VehicleState(
            t_s=now,
            system_id=None if self._vehicle is None else self._vehicle[0],
            component_id=None if self._vehicle is None else self._vehicle[1],
            position_ned_m=tm.position_ned_m,
            velocity_ned_m_s=tm.velocity_ned_m_s,
            position_rx_s=tm.position_rx_s,
            position_t_s=tm.position_t_s,
            heartbeat_rx_s=tm.heartbeat_rx_s,
            armed=bool(tm.base_mode & px4.MAV_MODE_FLAG_SAFETY_ARMED),
            mode=tm.mode,
            custom_mode=tm.custom_mode,
            base_mode=tm.base_mode,
            system_status=tm.system_status,
            landed_state=tm.landed_state,
            position_valid=bool(fresh) and tm.ahrs_healthy is not False,
            origin=tm.origin,
            yaw_rad=tm.yaw_rad,
            last_statustext=tm.last_statustext,
        )

    def _wait_locked(self, deadline_s: float) -> bool:
        """Wait on the condition (lock held) for at most one wall slice; False once past deadline."""
        remaining = deadline_s - self._clock.now()
        if remaining <= 0:
            return False
        if self._transport is None:
            raise LinkError(f"link {self.url!r} is closed")
        self._clock.wait(self._changed, remaining)
        return True

    # ---------------------------------------------------------------- commands

    def command_long(self, command: int, *params: float, timeout_s: float = 0.5, retries: int = 3) -> int:
        """Send COMMAND_LONG to the vehicle and wait for its COMMAND_ACK.

        ``params`` are param1..param7 (missing ones are 0). Each attempt waits ``timeout_s``
        [s of link clock]; up to ``retries`` resends follow (``confirmation`` counts them).
        IN_PROGRESS extends the wait. Returns MAV_RESULT_ACCEPTED (0).

        Raises CommandRejected (result code, STATUSTEXT reason) for any other result,
        LinkTimeout when no ACK came after all attempts, LinkError if the link is not ready.
        """
        if len(params) > 7:
            raise ValueError(f"COMMAND_LONG has 7 params, got {len(params)}")
        if retries < 0 or not timeout_s > 0:
            raise ValueError("retries must be >= 0 and timeout_s > 0")
        padded = [float(p) for p in params] + [0.0] * (7 - len(params))
        target = self._require_vehicle()
        with self._command_lock:
            t_start = self._clock.now()
            after = self._current_ack_seq()
            for attempt in range(retries + 1):
                msg = mavlink.MAVLink_command_long_message(target[0], target[1], int(command), min(attempt, 255), *padded)
                self._send(msg, "tx_commands")
                if attempt:
                    self._count("command_retries")
                ack = self._await_final_ack(int(command), after, timeout_s)
                if ack is None:
                    log.debug("no ACK for command %d (attempt %d of %d)", command, attempt + 1, retries + 1)
                    continue
                if ack.result == px4.MAV_RESULT_ACCEPTED:
                    return ack.result
                self._count("command_rejections")
                reason = self._reason_since(t_start)
                log.warning("command %d rejected with MAV_RESULT %d: %s", command, ack.result, reason or "(no reason)")
                raise CommandRejected(int(command), ack.result, reason)
            self._count("command_timeouts")
        raise LinkTimeout(f"no COMMAND_ACK for command {command} after {retries + 1} attempts of {timeout_s:g} s")

    def arm(self, timeout_s: float = 0.5, retries: int = 3, confirm_timeout_s: float = 2.5) -> None:
        """Arm (MAV_CMD_COMPONENT_ARM_DISARM 1) and confirm it by HEARTBEAT."""
        self._command_confirmed(
            "arm", lambda s: s.armed, confirm_timeout_s, px4.MAV_CMD_COMPONENT_ARM_DISARM, 1.0,
            timeout_s=timeout_s, retries=retries,
        )

    def disarm(self, force: bool = False, timeout_s: float = 0.5, retries: int = 3,
               confirm_timeout_s: float = 2.5) -> None:
        """Disarm and confirm by HEARTBEAT; ``force`` adds 21196 (disarms even in the air)."""
        self._command_confirmed(
            "disarm", lambda s: not s.armed, confirm_timeout_s, px4.MAV_CMD_COMPONENT_ARM_DISARM, 0.0,
            float(px4.ARM_FORCE_MAGIC) if force else 0.0, timeout_s=timeout_s, retries=retries,
        )

    def set_mode(self, mode: str, timeout_s: float = 0.5, retries: int = 3, confirm_timeout_s: float = 2.5) -> None:
        """Switch the PX4 mode (name as in :data:`mission.px4.MODES`) and confirm it by HEARTBEAT.

        Sends MAV_CMD_DO_SET_MODE(CUSTOM_MODE_ENABLED, main, sub). A first ACCEPTED ACK is not
        trusted: a later non-ACCEPTED ACK of the same command (PX4's double ACK) raises
        CommandRejected, and only a HEARTBEAT received after the command and showing the mode
        confirms it (LinkTimeout after ``confirm_timeout_s`` [s]).
        """
        if mode not in px4.MODES:
            raise ValueError(f"unknown PX4 mode {mode!r}; known: {sorted(px4.MODES)}")
        main, sub = px4.MODES[mode]
        self._command_confirmed(
            f"mode {mode}", lambda s: s.mode == mode, confirm_timeout_s, px4.MAV_CMD_DO_SET_MODE,
            float(px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(main), float(sub),
            timeout_s=timeout_s, retries=retries,
        )

    def hold(self, timeout_s: float = 0.5, retries: int = 3, confirm_timeout_s: float = 2.5) -> None:
        """Switch to Hold (AUTO.LOITER), confirmed by HEARTBEAT (see :meth:`set_mode`)."""
        self.set_mode(px4.HOLD, timeout_s=timeout_s, retries=retries, confirm_timeout_s=confirm_timeout_s)

    def land(self, timeout_s: float = 0.5, retries: int = 3, confirm_timeout_s: float = 2.5) -> None:
        """Land where the vehicle is (AUTO.LAND, which PX4 also enters for NAV_LAND), confirmed
        by HEARTBEAT (see :meth:`set_mode`)."""
        self.set_mode("AUTO.LAND", timeout_s=timeout_s, retries=retries, confirm_timeout_s=confirm_timeout_s)

    def takeoff(self, alt_m: float | None, timeout_s: float = 0.5, retries: int = 3) -> int:
        """MAV_CMD_NAV_TAKEOFF to ``alt_m`` [m] above the EKF origin (None: the vehicle's default).

        PX4 reads param7 as altitude AMSL, so the origin altitude from GPS_GLOBAL_ORIGIN is added;
        without a known origin a numeric ``alt_m`` raises LinkError. Acknowledged only (the
        vehicle must already be armed; PX4 shows AUTO.TAKEOFF next).
        """
        nan = math.nan
        if alt_m is None:
            param7 = nan
        else:
            if not math.isfinite(alt_m):
                raise ValueError(f"takeoff altitude must be finite, got {alt_m!r}")
            origin = self.state.origin
            if origin is None:
                raise LinkError("takeoff altitude needs the EKF origin (no GPS_GLOBAL_ORIGIN received)")
            param7 = origin[2] + float(alt_m)
        return self.command_long(px4.MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, 0.0, nan, nan, nan, param7,
                                 timeout_s=timeout_s, retries=retries)

    def _command_confirmed(
        self, what: str, confirmed: Callable[[VehicleState], bool], confirm_timeout_s: float,
        command: int, *params: float, timeout_s: float, retries: int,
    ) -> None:
        """Send a command, then wait for a HEARTBEAT after it that satisfies ``confirmed``.

        A later non-ACCEPTED ACK of the same command during the wait raises CommandRejected.
        A lost ACK is forgiven if the HEARTBEAT confirms.
        """
        t_sent = self._clock.now()
        after = self._current_ack_seq()
        ack_lost: LinkTimeout | None = None
        try:
            self.command_long(command, *params, timeout_s=timeout_s, retries=retries)
        except LinkTimeout as exc:
            ack_lost = exc
        deadline = self._clock.now() + confirm_timeout_s
        with self._changed:
            while True:
                late = [a for a in self._acks if a.seq > after and a.command == command
                        and a.result not in (px4.MAV_RESULT_ACCEPTED, MAV_RESULT_IN_PROGRESS)]
                if late:
                    break
                snapshot = self._snapshot_locked()
                if snapshot.heartbeat_rx_s is not None and snapshot.heartbeat_rx_s >= t_sent and confirmed(snapshot):
                    log.info("%s confirmed by HEARTBEAT", what)
                    return
                if not self._wait_locked(deadline):
                    if ack_lost is not None:
                        raise ack_lost
                    raise LinkTimeout(f"{what}: ACCEPTED but not confirmed by HEARTBEAT within {confirm_timeout_s:g} s")
        self._count("command_rejections")
        reason = self._reason_since(t_sent)
        log.warning("%s: late ACK rejected it with MAV_RESULT %d: %s", what, late[0].result, reason or "(no reason)")
        raise CommandRejected(command, late[0].result, reason)

    def _current_ack_seq(self) -> int:
        with self._lock:
            return self._ack_seq

    def _await_final_ack(self, command: int, after: int, timeout_s: float) -> _Ack | None:
        """First ACK of ``command`` newer than ``after``; IN_PROGRESS restarts the wait."""
        deadline = self._clock.now() + timeout_s
        with self._changed:
            while True:
                for ack in self._acks:
                    if ack.seq > after and ack.command == command:
                        if ack.result != MAV_RESULT_IN_PROGRESS:
                            return ack
                        after, deadline = ack.seq, self._clock.now() + timeout_s
                if not self._wait_locked(deadline):
                    return None

    def _reason_since(self, t_from_s: float) -> str:
        """The vehicle's reason for a refusal: the latest STATUSTEXT of severity WARNING or
        worse received since ``t_from_s`` (the command's first send). PX4 may send it just
        before or just after the ACK, so this waits up to ``reason_grace_s`` for one; failing
        that, the latest text of any severity since ``t_from_s``, else ``""``."""
        deadline = self._clock.now() + self.reason_grace_s
        with self._changed:
            while True:
                texts = [(sev, text) for t, sev, text in self._statustexts if t >= t_from_s]
                serious = [text for sev, text in texts if sev <= _SEVERITY_WARNING]
                if serious:
                    return serious[-1]
                if self._transport is None or not self._wait_locked(deadline):
                    return texts[-1][1] if texts else ""

    # ---------------------------------------------------------------- setpoints

    def send_velocity_ned(self, v_ned_m_s: np.ndarray, yaw_rad: float | None = None) -> None:
        """Send one velocity setpoint [m/s] in LOCAL_NED (frame 1), optionally with yaw [rad].

        Type mask 3527 (velocity only) or 2503 (velocity + yaw); ``time_boot_ms`` is the link
        clock. Nothing is resent in the background. Raises ValueError for a wrong shape or a
        non-finite (or float32-overflowing) value, before anything is sent.
        """
        v = np.asarray(v_ned_m_s, dtype=float)
        if v.shape != (3,):
            raise ValueError(f"velocity must have shape (3,), got {v.shape}")
        vn, ve, vd = v.tolist()  # three Python floats: checked faster than with numpy reductions
        if not all(math.isfinite(c) and abs(c) <= _FLOAT32_MAX for c in (vn, ve, vd)):
            raise ValueError(f"refusing non-finite velocity setpoint {[vn, ve, vd]}")
        if yaw_rad is not None and not (math.isfinite(yaw_rad) and abs(yaw_rad) <= _FLOAT32_MAX):
            raise ValueError(f"refusing non-finite yaw {yaw_rad!r}")
        target = self._require_vehicle()
        mask = px4.TYPE_MASK_VELOCITY if yaw_rad is None else px4.TYPE_MASK_VELOCITY_YAW
        time_boot_ms = int(self._clock.now() * 1000.0) & 0xFFFFFFFF
        msg = mavlink.MAVLink_set_position_target_local_ned_message(
            time_boot_ms, target[0], target[1], px4.MAV_FRAME_LOCAL_NED, mask,
            0.0, 0.0, 0.0, vn, ve, vd, 0.0, 0.0, 0.0,
            0.0 if yaw_rad is None else float(yaw_rad), 0.0,
        )
        self._send(msg, "tx_setpoints")

    def send_message(self, msg: Any) -> bool:
        """Send any pymavlink message as is (e.g. the lockstep TIMESYNC answer); False if there
        is no peer yet. Raises LinkError on socket errors or a closed link."""
        return self._send(msg, None)

    def send_setpoint_ned(self, position_ned_m: np.ndarray, velocity_ned_m_s: np.ndarray,
                          acceleration_ned_m_s2: np.ndarray) -> None:
        """Send one full setpoint in LOCAL_NED: position [m], velocity [m/s] and acceleration
        [m/s^2] (type_mask 3072: yaw and yaw rate ignored; PX4 closes position itself and takes
        velocity and acceleration as feed-forward). Bit 512 is never set: PX4 reads it as
        *force* and drops the setpoint. ValueError for a wrong shape or a non-finite value,
        before anything is sent."""
        values: list[float] = []
        for name, vec in (("position", position_ned_m), ("velocity", velocity_ned_m_s), ("acceleration", acceleration_ned_m_s2)):
            v = np.asarray(vec, dtype=float)
            if v.shape != (3,):
                raise ValueError(f"{name} must have shape (3,), got {v.shape}")
            parts = v.tolist()
            if not all(math.isfinite(c) and abs(c) <= _FLOAT32_MAX for c in parts):
                raise ValueError(f"refusing non-finite {name} setpoint {parts}")
            values += parts
        target = self._require_vehicle()
        time_boot_ms = int(self._clock.now() * 1000.0) & 0xFFFFFFFF
        msg = mavlink.MAVLink_set_position_target_local_ned_message(
            time_boot_ms, target[0], target[1], px4.MAV_FRAME_LOCAL_NED, px4.TYPE_MASK_POSITION_VELOCITY_ACCELERATION,
            *values, 0.0, 0.0)
        self._send(msg, "tx_setpoints")

    def set_message_interval(self, message_id: int, rate_hz: float, timeout_s: float = 0.5, retries: int = 2) -> None:
        """Ask the vehicle to stream ``message_id`` at ``rate_hz`` [Hz] (MAV_CMD_SET_MESSAGE_INTERVAL).
        Raises CommandRejected or LinkTimeout like :meth:`command_long`; the rate that actually
        arrives is :meth:`message_rate_hz`."""
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz!r}")
        self.command_long(px4.MAV_CMD_SET_MESSAGE_INTERVAL, float(message_id), 1e6 / rate_hz,
                          timeout_s=timeout_s, retries=retries)

    def message_rate_hz(self, kind: str = "LOCAL_POSITION_NED", window_s: float = 1.0) -> float:
        """Rate [Hz of link clock] at which ``kind`` arrived over the last ``window_s`` [s]
        (kept for LOCAL_POSITION_NED only); 0 when none."""
        now = self._clock.now()
        with self._lock:
            stamps = [t for t in self._position_stamps if now - t <= window_s]
        return 0.0 if len(stamps) < 2 else (len(stamps) - 1) / max(stamps[-1] - stamps[0], 1e-9)

    # ---------------------------------------------------------------- transmit

    def _require_vehicle(self) -> tuple[int, int]:
        if self._transport is None:
            raise LinkError(f"link {self.url!r} is not open")
        with self._lock:
            vehicle = self._vehicle
        if vehicle is None:
            raise LinkError("no vehicle identified yet: call wait_vehicle() first")
        return vehicle

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
                self._count("tx_errors")
                raise LinkError(f"send {msg.get_type()} on {self.url}: {exc}") from exc
            if not sent:
                return False
            self._tx_codec.seq = (self._tx_codec.seq + 1) % 256
            self._write_tlog(buf)
        self._count("tx_messages", counter)
        return True

    def _write_tlog(self, buf: bytes | bytearray) -> None:
        """Append one packet to the tlog (caller holds the tx lock)."""
        if self._tlog is None:
            return
        usec = (self._tlog_epoch_us + int(self._clock.now() * 1e6)) & ~3
        self._tlog.write(struct.pack(">Q", usec) + bytes(buf))

    @property
    def _heartbeat_msg(self) -> Any:
        """Our HEARTBEAT: an onboard controller (18), no autopilot (8), active."""
        return mavlink.MAVLink_heartbeat_message(
            px4.MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, MAV_STATE_ACTIVE, 3
        )

    def _heartbeat_loop(self) -> None:
        """Send our HEARTBEAT every heartbeat_period_s of the link clock (until close)."""
        msg = self._heartbeat_msg
        while not self._stop.is_set():
            try:
                self._send(msg, "tx_heartbeats")
                with self._tx_lock:
                    if self._tlog is not None:
                        self._tlog.flush()
            except LinkError as exc:
                if not self._stop.is_set():
                    log.warning("heartbeat not sent: %s", exc)
            except Exception:  # pragma: no cover - the heartbeat must keep beating
                log.exception("heartbeat thread error")
            deadline = self._clock.now() + self.heartbeat_period_s
            with self._heartbeat_cond:
                while not self._stop.is_set() and (remaining := deadline - self._clock.now()) > 0:
                    self._clock.wait(self._heartbeat_cond, remaining)

    # ---------------------------------------------------------------- receive

    def _setup_codecs(self) -> None:
        self._rx_codec = _new_codec(*self._source)
        self._tx_codec = _new_codec(*self._source)
        if self._signing_key is None:
            return
        stamp = int((time.time_ns() / 1e9 - _SIGNING_EPOCH_S) * 1e5)  # 10 us units since 2015
        for codec, outgoing in ((self._rx_codec, False), (self._tx_codec, True)):
            signing = codec.signing
            signing.secret_key = self._signing_key
            signing.sign_outgoing = outgoing
            signing.allow_unsigned_callback = _refuse_unsigned
            signing.link_id = 0
            signing.timestamp = stamp
        _keep_replay_state_on_failure(self._rx_codec)

    def _receive_loop(self) -> None:
        """Receiver thread: block on the transport, parse every datagram, never die."""
        failures = 0
        while not self._stop.is_set():
            transport = self._transport
            if transport is None:
                return
            try:
                data, address = transport.read(_WALL_SLICE_S)
            except OSError as exc:
                if self._stop.is_set():
                    return
                self._count("rx_errors")
                failures += 1
                if failures == 1:  # log once per outage, count every time
                    log.warning("receive error on %s: %s", self.url, exc)
                self._stop.wait(0.1)
                continue
            failures = 0
            if data:
                try:
                    self._handle_bytes(data, address, transport)
                except Exception:  # pragma: no cover - _handle_bytes already guards each message
                    self._count("rx_errors")
                    log.exception("receiver error")

    def _handle_bytes(self, data: bytes, address: Address | None, transport: _Transport) -> None:
        t_rx = self._clock.now()
        self._count("rx_bytes", amount=len(data))
        codec = self._rx_codec
        chunk: bytes = data
        while True:
            try:
                msg = codec.parse_char(chunk)
            except Exception as exc:  # a parser error: drop what is buffered and go on
                self._count("rx_bad")
                log.debug("parse error: %s", exc)
                _reset_parser(codec)
                break
            chunk = b""
            if msg is None:
                break
            try:
                self._handle_message(msg, t_rx, address, transport)
            except Exception:
                self._count("rx_errors")
                log.exception("error handling %s", msg.get_type())
        if transport.datagram and codec.buf_len() > 0:
            self._count("rx_bad")  # a truncated packet; it cannot continue in the next datagram
            _reset_parser(codec)

    def _handle_message(self, msg: Any, t_rx: float, address: Address | None, transport: _Transport) -> None:
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self._count("rx_bad", self._bad_signature(msg))
            return
        self._count("rx_messages", "rx_unknown" if kind.startswith("UNKNOWN_") else None)
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        self._log_rx(msg)
        with self._changed:
            vehicle, found = self._vehicle, False
            if vehicle is None:
                if not (kind == "HEARTBEAT" and self._is_our_autopilot(msg, source) and self._adopt(msg, source, t_rx)):
                    self._counts["rx_ignored"] += 1
                    return
                vehicle, found = source, True
            elif source[0] != vehicle[0]:
                self._counts["rejected_foreign"] += 1
                return
            elif source[1] != vehicle[1]:
                self._counts["rx_ignored"] += 1
                return
        if address is not None:
            transport.set_peer(address)
        if found:
            self._announce(source)
        with self._changed:
            if found:
                self._vehicle = source
            handler = self._HANDLERS.get(kind)
            if handler is not None:
                handler(self, msg, t_rx)
            self._clock.notify(self._changed)
        for listener in self._listeners:
            listener(msg)

    def add_listener(self, callback: Callable[[Any], None]) -> None:
        """Call ``callback(msg)`` for every message from the identified vehicle, in the receiver
        thread, after the link has handled it (e.g. the lockstep clock reads SYSTEM_TIME)."""
        self._listeners.append(callback)

    def _log_rx(self, msg: Any) -> None:
        with self._tx_lock:
            self._write_tlog(msg.get_msgbuf())

    def _is_our_autopilot(self, msg: Any, source: tuple[int, int]) -> bool:
        """Is this HEARTBEAT from the PX4 autopilot we are to fly (lock held)?"""
        if msg.type not in VEHICLE_TYPES:
            return False
        if self._target_system is not None and source[0] != self._target_system:
            return False
        if self._target_component and source[1] != self._target_component:
            return False
        if msg.autopilot != px4.MAV_AUTOPILOT_PX4:
            if source not in self._ignored_autopilots:
                self._ignored_autopilots.add(source)
                log.warning("ignoring non-PX4 autopilot %d at sysid %d compid %d", msg.autopilot, *source)
            return False
        return True

    def _adopt(self, msg: Any, source: tuple[int, int], t_rx: float) -> bool:
        """Lock held, ``msg`` a PX4 vehicle HEARTBEAT from ``source``: adopt it now? A configured
        ``target_system`` is adopted at once; otherwise after ADOPT_HEARTBEATS consistent ones
        while no other autopilot is heard (the module docstring)."""
        if self._target_system is not None:
            log.info("vehicle adopted (mavlink.target_system): PX4 autopilot sysid %d compid %d, MAV_TYPE %d",
                     source[0], source[1], msg.type)
            return True
        if len(self._heard) < 64 or source in self._heard:
            self._heard[source] = self._heard.get(source, 0) + 1
        fresh = {k: c for k, c in self._candidates.items() if t_rx - c[1] <= self.heartbeat_timeout_s}
        cand = fresh.get(source)
        if cand is None or cand[2] != msg.type:
            cand = [0, t_rx, msg.type]
        cand[0], cand[1] = cand[0] + 1, t_rx
        fresh[source] = cand
        self._candidates = fresh
        if cand[0] < ADOPT_HEARTBEATS:
            return False
        others = sorted(k for k in fresh if k != source)
        if others:
            if not self._ambiguous_warned:
                self._ambiguous_warned = True
                log.warning("several PX4 autopilots heard (%s and %s): adopting none while both talk; "
                            "set mavlink.target_system", source, ", ".join(map(str, others)))
            return False
        self._candidates.clear()
        self._counts["rejected_foreign"] += sum(n for k, n in self._heard.items() if k[0] != source[0])
        log.info("vehicle adopted after %d consistent HEARTBEATs: PX4 autopilot sysid %d compid %d, MAV_TYPE %d",
                 cand[0], source[0], source[1], msg.type)
        return True

    def _bad_signature(self, msg: Any) -> str | None:
        """The counter of a refused packet (BAD_DATA): unsigned, badly signed, or neither; a PX4
        HEARTBEAT signed with another key is remembered for :meth:`signing_problem`."""
        if self._signing_key is None or "signature" not in str(getattr(msg, "reason", "")):
            return None
        raw = bytes(getattr(msg, "data", b""))
        if len(raw) < 10 or raw[0] != mavlink.PROTOCOL_MARKER_V2 or not raw[2] & mavlink.MAVLINK_IFLAG_SIGNED:
            return "rx_unsigned"
        msg_id = raw[7] | raw[8] << 8 | raw[9] << 16
        if msg_id == mavlink.MAVLINK_MSG_ID_HEARTBEAT and len(raw) > 15 and raw[15] == px4.MAV_AUTOPILOT_PX4:
            with self._lock:  # HEARTBEAT payload: custom_mode u32, type u8, autopilot u8 (byte 15)
                wrong = self._wrong_key
                seen = wrong[2] if wrong is not None and wrong[:2] == (raw[5], raw[6]) else 0
                self._wrong_key = (raw[5], raw[6], seen + 1)
        return "rx_bad_signature"

    def signing_problem(self) -> str | None:
        """Why no vehicle was identified on a signed link, if the reason is the key: a PX4
        autopilot was heard, but only with signatures made with another key. None otherwise."""
        with self._lock:
            wrong, vehicle = self._wrong_key, self._vehicle
        if vehicle is not None or wrong is None:
            return None
        return (f"PX4 autopilot sysid {wrong[0]} compid {wrong[1]} signs with another key "
                f"({wrong[2]} HEARTBEATs refused): check mavlink.signing_key_file")

    def _announce(self, source: tuple[int, int]) -> None:
        """Send our HEARTBEAT before the vehicle becomes visible as identified, so it knows us
        before any command (PX4 sends STATUSTEXT reasons only to peers that sent a HEARTBEAT)."""
        log.info("vehicle identified: PX4 autopilot sysid %d compid %d", *source)
        try:
            self._send(self._heartbeat_msg, "tx_heartbeats")
        except LinkError as exc:
            log.warning("heartbeat not sent: %s", exc)

    # Handlers run in the receiver thread with the lock held.

    def _on_heartbeat(self, msg: Any, t_rx: float) -> None:
        tm = self._telemetry
        tm.heartbeat_rx_s = t_rx
        tm.base_mode, tm.custom_mode, tm.system_status = int(msg.base_mode), int(msg.custom_mode), int(msg.system_status)
        mode = px4.mode_name(tm.custom_mode)
        if mode != tm.mode:
            log.info("vehicle mode %s -> %s (armed %s)", tm.mode or "-", mode, bool(tm.base_mode & 128))
        tm.mode = mode

    def _on_local_position(self, msg: Any, t_rx: float) -> None:
        tm = self._telemetry
        tm.position_ned_m = _readonly_vector(msg.x, msg.y, msg.z)
        tm.velocity_ned_m_s = _readonly_vector(msg.vx, msg.vy, msg.vz)
        tm.position_finite = bool(np.isfinite(tm.position_ned_m).all() and np.isfinite(tm.velocity_ned_m_s).all())
        tm.position_rx_s = t_rx
        tm.position_t_s = tm.vehicle_clock.to_link(msg.time_boot_ms * 1e-3, t_rx)
        self._position_stamps.append(t_rx)

    def _on_extended_sys_state(self, msg: Any, t_rx: float) -> None:
        self._telemetry.landed_state = int(msg.landed_state)

    def _on_sys_status(self, msg: Any, t_rx: float) -> None:
        bit = mavlink.MAV_SYS_STATUS_AHRS
        if msg.onboard_control_sensors_present & bit and msg.onboard_control_sensors_enabled & bit:
            self._telemetry.ahrs_healthy = bool(msg.onboard_control_sensors_health & bit)
        else:
            self._telemetry.ahrs_healthy = None

    def _on_origin(self, msg: Any, t_rx: float) -> None:
        self._telemetry.origin = (msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)

    def _on_attitude(self, msg: Any, t_rx: float) -> None:
        yaw = float(msg.yaw)
        self._telemetry.yaw_rad = yaw if math.isfinite(yaw) else None

    def _on_statustext(self, msg: Any, t_rx: float) -> None:
        text = self._assembler.feed(str(msg.text), int(getattr(msg, "id", 0)), int(getattr(msg, "chunk_seq", 0)))
        if text is None:
            return
        text = text.rstrip()
        self._statustexts.append((t_rx, int(msg.severity), text))
        self._telemetry.last_statustext = text
        log.log(_statustext_level(int(msg.severity)), "vehicle: %s", text)

    def _on_command_ack(self, msg: Any, t_rx: float) -> None:
        if msg.target_system not in (0, self._source[0]):
            return  # an ACK meant for another client of the vehicle
        self._ack_seq += 1
        self._acks.append(_Ack(self._ack_seq, t_rx, int(msg.command), int(msg.result)))

    _HANDLERS: dict[str, Callable[[VehicleLink, Any, float], None]] = {
        "HEARTBEAT": _on_heartbeat,
        "LOCAL_POSITION_NED": _on_local_position,
        "EXTENDED_SYS_STATE": _on_extended_sys_state,
        "SYS_STATUS": _on_sys_status,
        "GPS_GLOBAL_ORIGIN": _on_origin,
        "ATTITUDE": _on_attitude,
        "STATUSTEXT": _on_statustext,
        "COMMAND_ACK": _on_command_ack,
    }

    # ---------------------------------------------------------------- counters

    def _count(self, *names: str | None, amount: int = 1) -> None:
        with self._lock:
            for name in names:
                if name is not None:
                    self._counts[name] += amount
