"""Zenoh I/O between the carrier and the passenger (thin: knows nothing of the law).

Key expressions are namespaced per marsupial pair (:func:`keys`), so several pairs share one
Zenoh network without crosstalk::

    marsupial/<pair>/carrier/state      CarrierState (JSON, or CDR Odometry with --encoding cdr)
    marsupial/<pair>/carrier/alive      liveliness token of the carrier
    marsupial/<pair>/passenger/state    PassengerStatus (JSON)
    marsupial/<pair>/passenger/phase    the phase alone, UTF-8 text (for humans and tools)
    marsupial/<pair>/passenger/alive    liveliness token of the passenger

Receiving (:class:`CarrierFeed`, :class:`PassengerFeed`): a callback on Zenoh's thread checks
the payload size before anything else (:data:`MAX_PAYLOAD_BYTES`, drop reason "size": a 10 MB
sample costs a length read, not a copy and a parse), decodes and validates each sample, stamps
its receive time with the injected clock and keeps only the newest accepted one under a lock
(it never blocks and never calls Zenoh). A rejected sample is dropped and counted per reason
(``feed.counters``), never a crash and never returned.

- :class:`CarrierFeed` binds to one source and gates every state against the carrier's own
  limits (:mod:`mission.feed_gate`: source binding, sequence/stamp/position/velocity
  plausibility, resynchronisation); samples from other sources are counted per source.
- :class:`PassengerFeed`: samples must be newer than the last accepted one from the same key: a
  strictly greater sequence number and a stamp not older ("stale_seq", "stale_stamp").

When the sender's liveliness token goes away the ordering (and the carrier feed's binding) is
forgotten, so a restarted sender that counts from 0 again, from a new Zenoh session, is accepted.
Publishers put their Zenoh entity id and a sequence number in each sample's ``source_info``.

Staleness: ``latest()`` always returns the newest accepted state with its age on the local clock
(``age_s``) and ``stale = age_s > max_age_s``; it does not hide old data. The controller decides
what a stale or vanished carrier means (its failsafe), using ``age_s``, ``stale`` and ``alive``.
"""
from __future__ import annotations

import json
import logging
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Generic, Literal, TypeVar

import numpy as np
import zenoh

from mission.clock import Clock
from mission.config import ZenohSection
from mission.errors import BusError, BusPortInUse, ConfigError
from mission.feed_gate import ANONYMOUS, FeedGate, GateLimits, Sample
from mission.port_holder import port_in_use
from mission.wire import (
    CarrierState,
    GeoOrigin,
    PassengerStatus,
    WireError,
    decode_carrier,
    decode_passenger_json,
    encode_carrier,
    encode_passenger_json,
    to_local_ned,
)

log = logging.getLogger(__name__)

Encoding = Literal["json", "cdr"]
#: Largest sample a feed decodes [bytes]; a carrier state is ~200 B in JSON, ~750 B as CDR Odometry.
MAX_PAYLOAD_BYTES = 8192
_ZENOH_ENCODING = {"json": zenoh.Encoding.APPLICATION_JSON, "cdr": zenoh.Encoding.APPLICATION_CDR}


# --------------------------------------------------------------------------- session


def zenoh_config(section: ZenohSection) -> zenoh.Config:
    """The ``zenoh.Config`` a :class:`ZenohSection` describes.

    - ``config_file`` set: the file is the base and decides mode and scouting; non-empty
      ``listen``/``connect`` lists still replace its endpoints (command-line flags win).
    - otherwise: ``mode``; multicast scouting as ``multicast_scouting`` (off by default);
      endpoints loopback-only unless given: a router listens on ``tcp/127.0.0.1:7447``, a client
      connects there, a peer with no endpoints uses the loopback ``rendezvous`` (see
      ZenohSection) so two processes on one machine find each other with no router, or only an
      ephemeral loopback listener if ``rendezvous`` is None; a peer given only connect endpoints
      also listens on an ephemeral loopback port (not Zenoh's all-interfaces default). With
      multicast scouting on and no endpoints, Zenoh's own defaults apply (it listens on all
      interfaces: that is the point).

    Raises :class:`ConfigError` naming the field when Zenoh refuses a value.
    """
    if section.config_file:
        path = Path(section.config_file)
        if not path.is_file():
            raise ConfigError("zenoh.config_file", section.config_file, "file not found")
        try:
            conf = zenoh.Config.from_file(str(path))
        except zenoh.ZError as exc:
            raise ConfigError("zenoh.config_file", section.config_file, f"invalid Zenoh config: {exc}") from None
        listen, connect = section.listen, section.connect
    else:
        conf = zenoh.Config()
        _insert(conf, "mode", section.mode, "zenoh.mode")
        _insert(conf, "scouting/multicast/enabled", section.multicast_scouting, "zenoh.multicast_scouting")
        listen, connect, rendezvous = _default_endpoints(section)
        if rendezvous:
            _insert(conf, "listen/exit_on_failure", False, "zenoh.rendezvous")
    if listen:
        _insert(conf, "listen/endpoints", listen, "zenoh.listen")
    if connect:
        _insert(conf, "connect/endpoints", connect, "zenoh.connect")
    return conf


def _default_endpoints(section: ZenohSection) -> tuple[list[str], list[str], bool]:
    """The listen and connect endpoints of a section without a config file, our loopback defaults
    filled in (see :func:`zenoh_config`), and whether they are the peer rendezvous pair."""
    listen, connect = list(section.listen), list(section.connect)
    if section.mode == "router" and not listen:
        return ["tcp/127.0.0.1:7447"], connect, False
    if section.mode == "client" and not connect:
        return listen, ["tcp/127.0.0.1:7447"], False
    if section.mode == "peer" and not listen and not section.multicast_scouting:
        if not connect and section.rendezvous:
            return [section.rendezvous, "tcp/127.0.0.1:0"], [section.rendezvous], True
        # A peer given only connect endpoints would otherwise get Zenoh's default listener,
        # tcp/[::]:0 on every interface; keep it on loopback like every other default.
        return ["tcp/127.0.0.1:0"], connect, False
    return listen, connect, False


def _insert(conf: zenoh.Config, key: str, value: Any, field: str) -> None:
    try:
        conf.insert_json5(key, json.dumps(value))
    except zenoh.ZError as exc:
        raise ConfigError(field, value, f"refused by Zenoh: {exc}") from None


def describe_endpoints(section: ZenohSection) -> str:
    """One line for a user: the Zenoh mode and the endpoints this section listens on and connects
    to (as :func:`zenoh_config` resolves them)."""
    if section.config_file:
        base = f"config file {section.config_file}"
        extra = [f"listen {', '.join(section.listen)}"] if section.listen else []
        extra += [f"connect {', '.join(section.connect)}"] if section.connect else []
        return f"Zenoh {base}" + (f" ({'; '.join(extra)})" if extra else "")
    listen, connect, rendezvous = _default_endpoints(section)
    if rendezvous:
        return f"Zenoh peer, loopback rendezvous {section.rendezvous} (zenoh.rendezvous)"
    if section.mode == "peer" and not listen and not connect:
        return "Zenoh peer, multicast scouting (all interfaces)"
    parts = [f"listen {', '.join(listen)}"] if listen else []
    parts += [f"connect {', '.join(connect)}"] if connect else []
    return f"Zenoh {section.mode}, " + ("; ".join(parts) or "ephemeral loopback listener")


def _listen_in_use(section: ZenohSection, text: str) -> Exception | None:
    """A :class:`PortInUse` naming the listen endpoint (and its holder) when Zenoh's error says
    a listen address is taken, else None."""
    if "Address already in use" not in text:
        return None
    for endpoint in section.listen:
        proto, _, address = endpoint.partition("/")
        host, _, port = address.partition("?")[0].rpartition(":")
        if port.isdigit() and address.split("?")[0] in text:
            return port_in_use(f"Zenoh listen endpoint {endpoint}", host, int(port), "udp" if proto == "udp" else "tcp",
                               cls=BusPortInUse)
    return None


def open_session(section: ZenohSection) -> zenoh.Session:
    """Open a Zenoh session for ``section`` (see :func:`zenoh_config`); raises :class:`BusError`
    when Zenoh cannot open it (e.g. a listen port already taken). Close it with ``close()`` or a
    ``with`` block, after undeclaring what was declared on it."""
    conf = zenoh_config(section)
    try:
        session = zenoh.open(conf)
    except zenoh.ZError as exc:
        taken = _listen_in_use(section, str(exc))
        if taken is not None:
            raise taken from None
        raise BusError(f"cannot open Zenoh session ({section.mode}, listen={section.listen}, "
                       f"connect={section.connect}): {exc}") from None
    log.info("zenoh session %s open (%s)", session.zid(), section.mode)
    return session


@dataclass(frozen=True)
class Keys:
    """Key expressions of one marsupial pair (see the module docstring)."""

    carrier_state: str
    carrier_alive: str
    passenger_state: str
    passenger_phase: str
    passenger_alive: str


def keys(pair: str) -> Keys:
    """The keys of pair ``pair`` (letters, digits, ``_`` and ``-`` only)."""
    if not pair or any(not (ch.isalnum() or ch in "_-") for ch in pair):
        raise ConfigError("zenoh.pair", pair, "must be letters, digits, '_' or '-'")
    root = f"marsupial/{pair}"
    return Keys(
        carrier_state=f"{root}/carrier/state",
        carrier_alive=f"{root}/carrier/alive",
        passenger_state=f"{root}/passenger/state",
        passenger_phase=f"{root}/passenger/phase",
        passenger_alive=f"{root}/passenger/alive",
    )


def _declare(what: str, fn: Callable[[], Any]) -> Any:
    try:
        return fn()
    except zenoh.ZError as exc:
        raise BusError(f"cannot declare {what}: {exc}") from None


# --------------------------------------------------------------------------- receiving

T = TypeVar("T")


@dataclass(frozen=True)
class Received(Generic[T]):
    """The newest accepted message with its receive time.

    value: the decoded message; key: the key expression it came on; rx_time_s [s] receive time
    on the local injected clock; age_s [s] ``clock.now() - rx_time_s`` when ``latest()`` was
    called; stale: ``age_s > max_age_s`` (the caller decides what that means).
    """

    value: T
    key: str
    rx_time_s: float
    age_s: float
    stale: bool


@dataclass(frozen=True)
class ReceivedCarrierState(Received[CarrierState]):
    """A carrier state, always in local NED (``value.frame == "local_ned"``)."""

    @property
    def state(self) -> CarrierState:
        return self.value


@dataclass(frozen=True)
class ReceivedPassengerStatus(Received[PassengerStatus]):
    """A passenger status."""

    @property
    def status(self) -> PassengerStatus:
        return self.value


class _Feed(Generic[T]):
    """Newest-sample subscriber with validation, ordering, drop counters and liveliness."""

    _received_type: type[Received[Any]] = Received
    _use_seq = True

    def __init__(self, session: zenoh.Session, key: str, alive_key: str | None, clock: Clock, max_age_s: float) -> None:
        if not max_age_s > 0:
            raise ValueError(f"max_age_s must be > 0, got {max_age_s!r}")
        self.key, self.alive_key, self.clock, self.max_age_s = key, alive_key, clock, float(max_age_s)
        self._lock = threading.Lock()
        self._latest: tuple[T, str, float] | None = None
        self._last_order: dict[str, tuple[int, float]] = {}
        self._received = 0
        self._accepted = 0
        self._dropped: dict[str, int] = {}
        self._alive: bool | None = None
        self._closed = False
        self._listeners: list[Callable[[T], None]] = []
        self._sub = _declare(f"subscriber on {key}", lambda: session.declare_subscriber(key, self._on_sample))
        self._alive_sub = None
        if alive_key is not None:
            try:
                self._alive_sub = _declare(
                    f"liveliness subscriber on {alive_key}",
                    lambda: session.liveliness().declare_subscriber(alive_key, self._on_alive, history=True),
                )
            except BusError:
                self._sub.undeclare()
                raise

    # -- on Zenoh's thread: never block, never call Zenoh
    def _decode(self, payload: bytes) -> T:
        raise NotImplementedError

    def _order_of(self, value: T) -> tuple[int, float]:
        raise NotImplementedError

    def _admit(self, value: T, key: str, source: str, rx: float) -> str | None:
        """Lock held: the drop reason for ``value``, or None to accept it. Default: newer than
        the last accepted sample on the same key (sequence number and stamp)."""
        seq, stamp = self._order_of(value)
        last = self._last_order.get(key)
        if last is not None:
            if self._use_seq and seq <= last[0]:
                return "stale_seq"
            if stamp < last[1] or (stamp == last[1] and not self._use_seq):
                return "stale_stamp"
        self._last_order[key] = (seq, stamp)
        return None

    def _on_sample(self, sample: zenoh.Sample) -> None:
        rx = self.clock.now()
        key = str(sample.key_expr)
        with self._lock:
            self._received += 1
        try:
            if sample.kind != zenoh.SampleKind.PUT:
                raise WireError("decode", "DELETE sample")
            size = len(sample.payload)
            if size > MAX_PAYLOAD_BYTES:
                raise WireError("size", f"{size} bytes > {MAX_PAYLOAD_BYTES}")
            value = self._decode(sample.payload.to_bytes())
        except WireError as exc:
            self._drop(exc.reason, key, str(exc))
            return
        except Exception:  # a bug, not a bad sample: keep Zenoh's thread alive, say it loudly
            log.exception("unexpected error decoding a sample on %s", key)
            self._drop("internal", key, "unexpected error")
            return
        info = sample.source_info
        source = ANONYMOUS if info is None else f"{info.source_id.zid}/{info.source_id.eid}"
        with self._lock:
            reason = self._admit(value, key, source, rx)
            if reason is None:
                self._latest = (value, key, rx)
                self._accepted += 1
        if reason is not None:
            seq, stamp = self._order_of(value)
            self._drop(reason, key, f"seq {seq} stamp {stamp} rx {rx:.3f} from {source}{self._describe(value)}")
            if reason == "source":
                return
        for listener in self._listeners:
            listener(value)

    def add_listener(self, callback: Callable[[T], None]) -> None:
        """Call ``callback(value)`` on Zenoh's thread after each valid sample of the sender (it
        must not block); e.g. the lockstep relay waits for the sample of a step. Valid: decoded
        and not from a foreign source, whether the ordering or plausibility check accepted it or
        not (a carrier binding, or one the gate doubts, still steps)."""
        self._listeners.append(callback)

    def _drop(self, reason: str, key: str, detail: str) -> None:
        with self._lock:
            first = reason not in self._dropped
            self._dropped[reason] = self._dropped.get(reason, 0) + 1
        (log.warning if first else log.debug)("dropped a sample on %s (%s): %s", key, reason, detail)

    def _on_alive(self, sample: zenoh.Sample) -> None:
        alive = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            changed = alive != self._alive
            self._alive = alive
            if not alive:
                self._last_order.clear()  # a restarted sender may count from 0 again
                self._forget_sender()
        if changed:
            (log.info if alive else log.warning)("%s is %s", self.alive_key, "alive" if alive else "gone")

    def _forget_sender(self) -> None:
        """Lock held: the sender's liveliness token went away."""

    def _describe(self, value: T) -> str:
        """More of a dropped sample for the log (default nothing)."""
        return ""

    # -- caller's thread
    def latest(self) -> Received[T] | None:
        """The newest accepted message with its age, or None if none was accepted yet."""
        with self._lock:
            item = self._latest
        if item is None:
            return None
        value, key, rx = item
        age = self.clock.now() - rx
        return self._received_type(value=value, key=key, rx_time_s=rx, age_s=age, stale=age > self.max_age_s)

    @property
    def alive(self) -> bool | None:
        """The sender's liveliness token: True present, False gone, None never seen."""
        with self._lock:
            return self._alive

    @property
    def counters(self) -> dict[str, Any]:
        """Snapshot: ``{"received": n, "accepted": n, "dropped": {reason: n}}``."""
        with self._lock:
            return {"received": self._received, "accepted": self._accepted, "dropped": dict(self._dropped),
                    **self._extra_counters()}

    def _extra_counters(self) -> dict[str, Any]:
        return {}

    def close(self) -> None:
        """Undeclare the subscribers (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for sub in (self._sub, self._alive_sub):
            if sub is not None:
                try:
                    sub.undeclare()
                except zenoh.ZError as exc:  # the session may be closed already
                    log.debug("undeclare: %s", exc)

    def __enter__(self) -> "_Feed[T]":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class CarrierFeed(_Feed[CarrierState]):
    """The newest valid carrier state of pair ``pair``, in local NED.

    encoding: "json" (default) or "cdr" (ROS 2 Odometry); key: override of the state key (e.g.
    :func:`mission.wire.ros2dds_odom_key`); origin: the vehicle's geodetic origin, needed to
    accept wgs84 states (drop reason "origin" without it; see :meth:`set_origin`); max_age_s
    [s] on ``clock``; limits: the carrier's own limits for the plausibility gate (default: 3 m/s
    top speed). The liveliness of ``marsupial/<pair>/carrier/alive`` gives ``alive``; when it
    goes away the feed unbinds its source. ``counters`` add ``bound_source``,
    ``rejected_sources`` ({source: n}) and ``resyncs``.
    """

    _received_type = ReceivedCarrierState

    def __init__(
        self,
        session: zenoh.Session,
        pair: str,
        clock: Clock,
        *,
        encoding: Encoding = "json",
        key: str | None = None,
        origin: GeoOrigin | None = None,
        max_age_s: float = 0.5,
        limits: GateLimits | None = None,
    ) -> None:
        if encoding not in _ZENOH_ENCODING:
            raise ConfigError("zenoh.encoding", encoding, "must be 'json' or 'cdr'")
        self.encoding = encoding
        self._use_seq = encoding == "json"  # Odometry has no sequence number: order by stamp
        self.gate = FeedGate(limits or GateLimits(max_speed_m_s=3.0), use_seq=self._use_seq)
        self._origin = origin
        self._cdr_count = 0
        k = keys(pair)
        super().__init__(session, key or k.carrier_state, k.carrier_alive, clock, max_age_s)

    @classmethod
    def from_section(
        cls, session: zenoh.Session, section: ZenohSection, clock: Clock, *, max_age_s: float,
        origin: GeoOrigin | None = None, limits: GateLimits | None = None,
    ) -> "CarrierFeed":
        """The feed a :class:`ZenohSection` describes (pair, encoding, carrier_key)."""
        return cls(session, section.pair, clock, encoding=section.encoding, key=section.carrier_key,
                   origin=origin, max_age_s=max_age_s, limits=limits)

    def _admit(self, value: CarrierState, key: str, source: str, rx: float) -> str | None:
        was = self.gate.bound
        reason = self.gate.offer(source, Sample(value.seq, value.stamp_s, value.position, value.velocity_ned_m_s, rx))
        if self.gate.bound != was:
            log.info("carrier feed bound to source %s on %s", self.gate.bound, key)
        return reason

    def _describe(self, value: CarrierState) -> str:
        return f" at {np.round(value.position, 2).tolist()} m, {np.round(value.velocity_ned_m_s, 2).tolist()} m/s; " \
               f"reference {self.gate.describe_reference()}"

    def _forget_sender(self) -> None:
        if self.gate.bound is not None:
            log.warning("carrier feed: source %s unbound (liveliness token gone)", self.gate.bound)
        self.gate.unbind()

    def _extra_counters(self) -> dict[str, Any]:
        return {"bound_source": self.gate.bound, "rejected_sources": dict(self.gate.rejected_sources),
                "resyncs": self.gate.resyncs}

    def set_origin(self, origin: GeoOrigin | None) -> None:
        """Set the geodetic origin used for wgs84 states from now on."""
        with self._lock:
            self._origin = origin

    def _decode(self, payload: bytes) -> CarrierState:
        with self._lock:
            self._cdr_count += 1
            seq, origin = self._cdr_count, self._origin
        return to_local_ned(decode_carrier(payload, self.encoding, seq=seq), origin)

    def _order_of(self, value: CarrierState) -> tuple[int, float]:
        return value.seq, value.stamp_s

    def latest(self) -> ReceivedCarrierState | None:  # type: ignore[override]
        """The newest accepted carrier state (local NED) with its age, or None."""
        return super().latest()  # type: ignore[return-value]


class PassengerFeed(_Feed[PassengerStatus]):
    """The newest valid passenger status of pair ``pair`` (for the carrier), with liveliness."""

    _received_type = ReceivedPassengerStatus

    def __init__(self, session: zenoh.Session, pair: str, clock: Clock, *, max_age_s: float = 1.0) -> None:
        k = keys(pair)
        super().__init__(session, k.passenger_state, k.passenger_alive, clock, max_age_s)

    def _decode(self, payload: bytes) -> PassengerStatus:
        return decode_passenger_json(payload)

    def _order_of(self, value: PassengerStatus) -> tuple[int, float]:
        return value.seq, value.stamp_s

    def latest(self) -> ReceivedPassengerStatus | None:  # type: ignore[override]
        """The newest accepted passenger status with its age, or None."""
        return super().latest()  # type: ignore[return-value]


# --------------------------------------------------------------------------- publishing


class _Publisher:
    """Publishers plus one liveliness token; closing undeclares them all (idempotent).

    States are streams where the newest wins: puts are express (not batched) and use congestion
    control DROP, so a congested link drops a sample instead of stalling the sender's loop.
    Publish at a steady rate, not only on change: a receiver treats silence as loss.
    """

    def __init__(self, session: zenoh.Session, alive_key: str) -> None:
        self._session = session
        self._entities: list[Any] = []
        self._closed = False
        self._sn = 0
        self._token = _declare(f"liveliness token {alive_key}", lambda: session.liveliness().declare_token(alive_key))
        self._entities.append(self._token)

    def _publisher(self, key: str, encoding: zenoh.Encoding) -> zenoh.Publisher:
        pub = _declare(f"publisher on {key}", lambda: self._session.declare_publisher(
            key, encoding=encoding, congestion_control=zenoh.CongestionControl.DROP, express=True))
        self._entities.append(pub)
        return pub

    def _put(self, pub: zenoh.Publisher, payload: bytes) -> None:
        """Put with our identity in ``source_info`` (the receiver binds to it)."""
        self._sn += 1
        try:
            pub.put(payload, source_info=zenoh.SourceInfo(pub.id, self._sn))
        except zenoh.ZError as exc:
            raise BusError(f"cannot publish on {pub.key_expr}: {exc}") from None

    def close(self) -> None:
        """Undeclare the publishers and the liveliness token (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for entity in reversed(self._entities):
            try:
                entity.undeclare()
            except zenoh.ZError as exc:
                log.debug("undeclare: %s", exc)

    def __enter__(self) -> "_Publisher":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class CarrierPublisher(_Publisher):
    """Publishes the carrier's state on pair ``pair`` and holds the carrier's liveliness token.

    encoding "json" or "cdr" (Odometry, ENU, twist in ``base_link``); key overrides the state key.
    """

    def __init__(self, session: zenoh.Session, pair: str, encoding: Encoding = "json", *, key: str | None = None) -> None:
        if encoding not in _ZENOH_ENCODING:
            raise ConfigError("zenoh.encoding", encoding, "must be 'json' or 'cdr'")
        k = keys(pair)
        super().__init__(session, k.carrier_alive)
        self.encoding = encoding
        self.key = key or k.carrier_state
        try:
            self._pub = self._publisher(self.key, _ZENOH_ENCODING[encoding])
        except BusError:
            self.close()
            raise

    @property
    def matched(self) -> bool:
        """True when a subscriber somewhere matches the state key (a put would be delivered)."""
        return bool(self._pub.matching_status.matching)

    def publish(self, state: CarrierState) -> None:
        """Send ``state``; raises :class:`BusError` if Zenoh refuses."""
        self._put(self._pub, encode_carrier(state, self.encoding))


class PassengerPublisher(_Publisher):
    """Publishes the passenger's status (state key, JSON) and phase (phase key, text) on pair
    ``pair`` and holds the passenger's liveliness token."""

    def __init__(self, session: zenoh.Session, pair: str) -> None:
        k = keys(pair)
        super().__init__(session, k.passenger_alive)
        self.last_seq = -1  # seq of the last status sent
        try:
            self._state = self._publisher(k.passenger_state, zenoh.Encoding.APPLICATION_JSON)
            self._phase = self._publisher(k.passenger_phase, zenoh.Encoding.TEXT_PLAIN)
        except BusError:
            self.close()
            raise

    @property
    def matched(self) -> bool:
        """True when a subscriber somewhere matches the state key (a put would be delivered)."""
        return bool(self._state.matching_status.matching)

    def publish(self, status: PassengerStatus) -> None:
        """Send ``status`` on the state key and its phase on the phase key."""
        self._put(self._state, encode_passenger_json(status))
        self.last_seq = status.seq
        self._put(self._phase, status.phase.encode())
