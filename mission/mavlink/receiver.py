"""The receiving half of a link: bytes -> messages -> the vehicle's identity, telemetry, ACKs and
STATUSTEXTs in the :class:`~mission.mavlink.session.LinkSession`.

Identification: :class:`~mission.mavlink.identity.Adoption` decides which PX4 autopilot is the
vehicle; from then on only that system and component is applied (others are counted and
ignored). With ``mavlink.target_system`` unset, a HEARTBEAT of a second PX4 autopilot after
the adoption is an identity conflict (``session.identity_conflict``): the mission aborts.

The reply address (:class:`ReplyPin`) is the address the identifying HEARTBEAT came from, and
only the vehicle's packets that come over the same link count:

* signed link: the signing link id of the identifying HEARTBEAT is pinned with it. A packet of
  the vehicle with another link id (its GCS link's packets forwarded to our port, whose signing
  timestamps run on their own) is counted (``rx_other_link``) and ignored; one with the pinned
  link id moves the reply address if it comes from elsewhere (a valid signature and a fresh
  timestamp on our stream are proof enough; ``peer_moves``);
* unsigned link: anyone can claim the vehicle's ids, so the address itself is the link. A packet
  from another address is counted (``rx_other_address``) and ignored while the pinned address
  still talks; once it has been silent for :data:`PEER_SILENT_S`, the next one moves the reply
  address there (a restarted vehicle), with a warning.

Replay protection is pymavlink's: a signed packet's timestamp must exceed the last one seen on
its stream, keyed by (link id, system, component) as the MAVLink 2 signing spec says; a refused
packet leaves that state alone (:func:`mission.mavlink.codec.keep_replay_state_on_failure`).
On a signed link unsigned and badly signed packets are counted apart. The receiver never dies
on bad input: every parse or handler error is caught and counted.

Nor does bad input flood the log: pymavlink's generated dialect logs at INFO for every packet
whose signature it refuses ("new stream", "bad new stream", "old timestamp", "sig mismatch"),
and with ``-v`` a flood of badly signed packets became megabytes of log and stalled the
receiver. :data:`LIMITER` lets each distinct line (logger and message template) through
:data:`BURST` times, then at most once per :data:`PERIOD_S` of wall time; the first line let
through after a pause says how many like it were held back. :func:`install_limiter` puts it on
pymavlink's dialect logger and on the receiver's per-packet logger (:data:`packet_log`). The
refused packets themselves are counted (``rx_bad_signature``, ``rx_unsigned``); the held-back
lines by :meth:`LineLimiter.suppressed`.
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

from mission.mavlink import telemetry
from mission.mavlink.commander import received_param
from mission.mavlink.codec import reset_parser
from mission.mavlink.identity import Adoption
from mission.mavlink.session import LinkSession
from mission.mavlink.telemetry import StatusTextAssembler
from mission.mavlink.transport import Address, Transport
from mission.mavlink.env import mavlink

log = logging.getLogger("mission.mavlink.link")
packet_log = logging.getLogger("mission.mavlink.link.packets")  # lines about one packet: rate-limited (LIMITER)

WALL_SLICE_S = 0.05  # longest wall-clock block in the transport [s], so a stop is prompt
PEER_SILENT_S = 1.0  # unsigned link: the pinned address silent this long [s of link clock] before another may take over


BURST = 5
"""Lines of one kind let through before the limit starts."""
PERIOD_S = 1.0
"""Then at most one line of that kind per this much wall time [s]."""
MAX_KINDS = 256
"""Distinct kinds tracked; beyond it, new kinds share one budget."""


class LineLimiter(logging.Filter):
    """A :class:`logging.Filter` passing each kind of line (logger name, message template)
    :data:`BURST` times, then once per ``period_s`` [s] of ``now`` (a monotonic wall clock);
    thread-safe. The counts of what it held back are :meth:`suppressed`."""

    def __init__(self, burst: int = BURST, period_s: float = PERIOD_S,
                 now: Callable[[], float] = time.monotonic) -> None:
        super().__init__()
        self.burst, self.period_s, self.now = burst, period_s, now
        self._lock = threading.Lock()
        self._seen: dict[tuple[str, str], list[float]] = {}  # kind -> [lines passed, last passed [s], held since]
        self._held: dict[str, int] = {}

    def filter(self, record: logging.LogRecord) -> bool:
        kind = (record.name, str(record.msg))
        with self._lock:
            if kind not in self._seen and len(self._seen) >= MAX_KINDS:
                kind = (record.name, "*")
            entry = self._seen.setdefault(kind, [0.0, -float("inf"), 0.0])
            now = self.now()
            if entry[0] < self.burst or now - entry[1] >= self.period_s:
                held = int(entry[2])
                entry[0], entry[1], entry[2] = entry[0] + 1, now, 0.0
                if held:
                    record.msg = f"{record.msg} [{held} more like it held back]"
                return True
            entry[2] += 1
            label = f"{record.name}: {kind[1]}"
            self._held[label] = self._held.get(label, 0) + 1
            return False

    def suppressed(self) -> dict[str, int]:
        """Lines held back since the start, per kind (``"logger: message template"``)."""
        with self._lock:
            return dict(self._held)

    def suppressed_total(self) -> int:
        """All lines held back since the start."""
        with self._lock:
            return sum(self._held.values())


LIMITER = LineLimiter()
"""The process's limiter (one: the loggers it guards are process-wide)."""

GUARDED = (mavlink.__name__, "mission.mavlink.link.packets")
"""The loggers that may speak per received packet: pymavlink's dialect, and the receiver's
lines about one packet (:mod:`mission.mavlink.receiver`)."""


def install_limiter(limiter: LineLimiter = LIMITER) -> None:
    """Put ``limiter`` on each logger of :data:`GUARDED` (idempotent)."""
    for name in GUARDED:
        logger = logging.getLogger(name)
        if limiter not in logger.filters:
            logger.addFilter(limiter)


class ReplyPin:
    """Which of the identified vehicle's packets count and where replies go (module docstring).

    ``signed``: the link checks signatures. :meth:`admit` decides for each packet of the vehicle
    (the first one pins); it returns None when the packet counts, else the counter that refuses it.
    :attr:`moved` is the new address when the last admitted packet moved the pin (else None).
    """

    def __init__(self, signed: bool, silent_s: float = PEER_SILENT_S) -> None:
        self.signed, self.silent_s = signed, silent_s
        self.address: Address | None = None
        self.link_id: int | None = None
        self.pinned = False
        self.last_rx_s = float("-inf")
        self.moved: Address | None = None
        self._warned: set[str] = set()

    def admit(self, msg: Any, address: Address | None, t_rx: float) -> str | None:
        self.moved = None
        if not self.pinned:
            self.pinned, self.address, self.last_rx_s = True, address, t_rx
            self.link_id = msg.get_link_id() if self.signed else None
            self.moved = address
            return None
        if self.signed and msg.get_link_id() != self.link_id:
            self._warn_once("link", "vehicle packets with signing link id %s (ours: %s) from %s ignored: another link of "
                            "the vehicle, forwarded", msg.get_link_id(), self.link_id, address)
            return "rx_other_link"
        if address is not None and address != self.address:
            if not self.signed and t_rx - self.last_rx_s <= self.silent_s:
                self._warn_once("address", "vehicle packets from %s ignored: the vehicle talks from %s (unsigned link: "
                                "set mavlink.signing_key_file to tell them apart)", address, self.address)
                return "rx_other_address"
            log.log(logging.INFO if self.signed else logging.WARNING, "vehicle reply address moved from %s to %s (%s)",
                    self.address, address, f"signed, link id {self.link_id}" if self.signed
                    else f"the old one silent for {t_rx - self.last_rx_s:.1f} s")
            self.address = self.moved = address
        self.last_rx_s = t_rx
        return None

    def _warn_once(self, key: str, text: str, *args: Any) -> None:
        if key not in self._warned:
            self._warned.add(key)
            log.warning(text, *args)


def statustext_level(severity: int) -> int:
    """Python log level of a MAV_SEVERITY (EMERGENCY 0 .. DEBUG 7)."""
    if severity <= mavlink.MAV_SEVERITY_ERROR:
        return logging.ERROR
    if severity == mavlink.MAV_SEVERITY_WARNING:
        return logging.WARNING
    return logging.INFO if severity <= mavlink.MAV_SEVERITY_INFO else logging.DEBUG


class Receiver:
    """Parses what ``transport`` delivers with ``codec`` into ``session``.

    ``source_system``: ours (ACKs for other clients are ignored). ``on_identified(source)`` runs
    once, before the vehicle shows as identified (the link says hello with a HEARTBEAT);
    ``on_packet(raw)`` gets every valid packet (the tlog); each of ``listeners`` is called with
    every message from the identified vehicle after it was applied (outside the lock).
    """

    def __init__(self, session: LinkSession, codec: Any, *, source_system: int, adoption: Adoption, signed: bool,
                 on_identified: Callable[[tuple[int, int]], None],
                 on_packet: Callable[[bytes], None], listeners: list[Callable[[Any], None]] | None = None) -> None:
        self.session, self.codec = session, codec
        self.source_system, self.adoption, self.signed = source_system, adoption, signed
        self.on_identified, self.on_packet = on_identified, on_packet
        self.listeners = listeners if listeners is not None else []
        self._assembler = StatusTextAssembler()
        self.pin = ReplyPin(signed)

    def run(self, transport: Transport, stop: threading.Event) -> None:
        """Receiver thread: block on the transport, parse every datagram, never die."""
        failures = 0
        while not stop.is_set():
            try:
                data, address = transport.read(WALL_SLICE_S)
            except OSError as exc:
                if stop.is_set():
                    return
                self.session.count("rx_errors")
                failures += 1
                if failures == 1:  # log once per outage, count every time
                    log.warning("receive error on %s: %s", self.session.name, exc)
                stop.wait(0.1)
                continue
            failures = 0
            if data:
                try:
                    self.handle_bytes(data, address, transport)
                except Exception:  # pragma: no cover - handle_bytes already guards each message
                    self.session.count("rx_errors")
                    packet_log.exception("receiver error")

    def handle_bytes(self, data: bytes, address: Address | None, transport: Transport) -> None:
        """One datagram (or stream chunk) received now. Each message is stamped with the clock's time
        when it is handled: a lockstep vehicle's SYSTEM_TIME moves the clock for those after it in
        the same datagram."""
        clock = self.session.clock
        self.session.count("rx_bytes", amount=len(data))
        codec = self.codec
        chunk: bytes = data
        while True:
            try:
                msg = codec.parse_char(chunk)
            except Exception as exc:  # a parser error: drop what is buffered and go on
                self.session.count("rx_bad")
                packet_log.debug("parse error: %s", exc)
                reset_parser(codec)
                break
            chunk = b""
            if msg is None:
                break
            try:
                self.handle_message(msg, clock.now(), address, transport)
            except Exception:
                self.session.count("rx_errors")
                packet_log.exception("error handling %s", msg.get_type())
        if transport.datagram and codec.buf_len() > 0:
            self.session.count("rx_bad")  # a truncated packet; it cannot continue in the next datagram
            reset_parser(codec)

    def handle_message(self, msg: Any, t_rx: float, address: Address | None, transport: Transport) -> None:
        s = self.session
        kind = msg.get_type()
        if kind == "BAD_DATA":
            s.count("rx_bad", self._bad_packet(msg))
            return
        s.count("rx_messages", "rx_unknown" if kind.startswith("UNKNOWN_") else None)
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        self.on_packet(bytes(msg.get_msgbuf()))
        with s.changed:
            vehicle, found = s.vehicle, False
            if vehicle is None:
                if not (kind == "HEARTBEAT" and self.adoption.offer(msg.type, msg.autopilot, source, t_rx, address)):
                    s.counts["rx_ignored"] += 1
                    return
                s.counts["rejected_foreign"] += self.adoption.foreign_heartbeats
                vehicle, found = source, True
            elif source != vehicle:
                s.counts["rejected_foreign" if source[0] != vehicle[0] else "rx_ignored"] += 1
                if kind == "HEARTBEAT" and s.identity_conflict is None:
                    s.identity_conflict = self.adoption.rival(msg.type, msg.autopilot, source, vehicle)
                return
            refused = self.pin.admit(msg, address, t_rx)
            if refused is not None:
                s.counts[refused] += 1
                return
            if self.pin.moved is not None and not found:
                s.counts["peer_moves"] += 1
        if self.pin.moved is not None:
            transport.set_peer(self.pin.moved)
        if found:
            log.info("vehicle identified: PX4 autopilot sysid %d compid %d", *source)
            self.on_identified(source)
        with s.changed:
            if found:
                s.vehicle = source
            self._apply(msg, kind, t_rx)
            s.notify_locked()
        for listener in self.listeners:
            listener(msg)

    def _apply(self, msg: Any, kind: str, t_rx: float) -> None:
        """Lock held: what a message from the vehicle changes."""
        s = self.session
        if kind in telemetry.KINDS:
            if kind == "LOCAL_POSITION_NED":
                s.note_position(t_rx)
            before = s.telemetry.mode
            s.telemetry = telemetry.reduce(s.telemetry, msg, t_rx)
            if s.telemetry.mode != before:
                log.info("vehicle mode %s -> %s (armed %s)", before or "-", s.telemetry.mode,
                         bool(s.telemetry.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED))
        elif kind == "STATUSTEXT":
            text = self._assembler.feed(str(msg.text), int(getattr(msg, "id", 0)), int(getattr(msg, "chunk_seq", 0)))
            if text is not None:
                text = text.rstrip()
                s.statustexts.append((t_rx, int(msg.severity), text))
                s.telemetry = telemetry.with_statustext(s.telemetry, text)
                log.log(statustext_level(int(msg.severity)), "vehicle: %s", text)
        elif kind == "COMMAND_ACK" and msg.target_system in (0, self.source_system):  # else: another client's
            s.acks.add(t_rx, msg.command, msg.result)
        elif kind == "PARAM_VALUE":
            value = received_param(msg, t_rx)
            s.params[value.name] = value

    def _bad_packet(self, msg: Any) -> str | None:
        """The counter of a refused packet (BAD_DATA): unsigned, badly signed, or neither; a PX4
        HEARTBEAT signed with another key is remembered (``session.wrong_key``)."""
        if not self.signed or "signature" not in str(getattr(msg, "reason", "")):
            return None
        raw = bytes(getattr(msg, "data", b""))
        if len(raw) < 10 or raw[0] != mavlink.PROTOCOL_MARKER_V2 or not raw[2] & mavlink.MAVLINK_IFLAG_SIGNED:
            return "rx_unsigned"
        msg_id = raw[7] | raw[8] << 8 | raw[9] << 16
        if msg_id == mavlink.MAVLINK_MSG_ID_HEARTBEAT and len(raw) > 15 and raw[15] == mavlink.MAV_AUTOPILOT_PX4:
            s = self.session
            with s.lock:  # HEARTBEAT payload: custom_mode u32, type u8, autopilot u8 (byte 15)
                wrong = s.wrong_key
                seen = wrong[2] if wrong is not None and wrong[:2] == (raw[5], raw[6]) else 0
                s.wrong_key = (raw[5], raw[6], seen + 1)
        return "rx_bad_signature"
