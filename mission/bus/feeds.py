"""Receiving on the bus: the newest valid carrier state and passenger status (thin I/O).

A callback on Zenoh's thread checks the payload size before anything else
(:data:`MAX_PAYLOAD_BYTES`, drop reason "size"), decodes and validates each sample
(:mod:`mission.bus.wire`), stamps its receive time with the injected clock and keeps only the
newest accepted one under a lock (it never blocks and never calls Zenoh). A rejected sample is
dropped and counted per reason (``feed.counters``), never a crash and never returned.
Liveliness: only a token on exactly the sender's alive key is the sender's; a token on a key
expression that merely intersects it (``marsupial/**``, anyone's to declare) is ignored and
counted (``alive_foreign``), so its going away unbinds nothing.
:class:`CarrierFeed` binds to one source and gates each state (:mod:`mission.bus.gate`);
:class:`PassengerFeed` accepts only a strictly greater ``seq`` with a stamp not older. When the
sender's liveliness token goes away the ordering and the binding are forgotten (a restarted
sender counts from 0 again). ``latest()`` returns the newest accepted sample with its age
(``age_s``; a carrier state's since the carrier measured it, once its clock offset is known:
:class:`ReceivedCarrierState`; ``stale``: older than ``max_age_s``); the caller decides what
stale means.
More: docs/wire.md.
"""
from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from typing import Any, Callable, Generic, Protocol, TypeVar

import numpy as np
import zenoh

from mission.core.records import replace
from mission.time.clock import Clock
from mission.time.offset import DelayWatch, OffsetEstimate, sample_age
from mission.config.schema import ZenohSection
from mission.errors import BusError
from mission.bus.auth import BusAuth
from mission.bus.gate import ANONYMOUS, MAX_CANDIDATES, FeedGate, GateLimits, Sample, count_rejected
from mission.bus.encodings import decode_carrier
from mission.bus.wire import CarrierState, GeoOrigin, PassengerStatus, WireError, decode_passenger_json, to_local_ned
from mission.bus.session import Encoding, check_encoding, declare, keys, undeclare

log = logging.getLogger("mission.bus.bridge")  # one logger name for the whole bus

#: Largest sample a feed decodes [bytes]; a carrier state is ~200 B in JSON, ~750 B as CDR Odometry.
MAX_PAYLOAD_BYTES = 8192

T = TypeVar("T")


def checked_payload(sample: zenoh.Sample, verifier: Any) -> tuple[bytes, str]:
    """A received sample's bytes and its source, checked as every feed checks them before decoding:
    a PUT, at most :data:`MAX_PAYLOAD_BYTES`, and, with ``verifier`` (a :class:`BusAuth`'s), signed
    by a known key, whose signer is then the source (``source_info`` is not authenticated); without,
    Zenoh's ``source_info`` (:data:`ANONYMOUS` when absent). Raises :class:`WireError`."""
    if sample.kind != zenoh.SampleKind.PUT:
        raise WireError("decode", "DELETE sample")
    size = len(sample.payload)
    if size > MAX_PAYLOAD_BYTES:
        raise WireError("size", f"{size} bytes > {MAX_PAYLOAD_BYTES}")
    raw = sample.payload.to_bytes()
    if verifier is not None:
        source, _ = verifier.verify(sample, raw)
        return raw, source
    info = sample.source_info
    return raw, ANONYMOUS if info is None else f"{info.source_id.zid}/{info.source_id.eid}"


class OffsetSource(Protocol):
    """Where the carrier's clock offset comes from: ``estimate()`` now (None: not known yet) and
    ``snapshot()`` (counters for summary.json)."""

    def estimate(self) -> OffsetEstimate | None: ...

    def snapshot(self) -> dict[str, Any]: ...


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


#: [s] a carrier state whose measurement time, by the clock offset, is later than its arrival by
#: more than the offset's bound and this is aged by its arrival (``rx_age_s``), not by that time:
#: a state cannot be measured after it arrived, so the offset does not hold for it
FUTURE_SLACK_S = 0.05


@dataclass(frozen=True)
class ReceivedCarrierState(Received[CarrierState]):
    """A carrier state, always in local NED (``value.frame == "local_ned"``); ``untrusted``: why
    the feed does not trust it yet (just bound, a resync, a contested source:
    :meth:`mission.bus.gate.FeedGate.distrust`), None when it does.

    With the carrier's clock offset known (the feed's ``offset``), ``age_s`` [s] is the time since
    the carrier *measured* the state (``now - (stamp - offset)``, :func:`mission.time.offset.sample_age`),
    good to ``age_bound_s`` [s]; ``rx_age_s`` [s] is always the time since it arrived. Without it
    (no round trip yet), or when the offset would put the measurement after the arrival (beyond
    its bound and :data:`FUTURE_SLACK_S`: the offset does not hold for this carrier's clock, counted
    ``future_stamps``), ``age_s`` is the receive age and ``age_bound_s`` is None: the measurement
    time is unknown."""

    untrusted: str | None = None
    rx_age_s: float = 0.0
    age_bound_s: float | None = None

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

    def __init__(self, session: zenoh.Session, key: str, alive_key: str | None, clock: Clock, max_age_s: float,
                 auth: BusAuth | None = None) -> None:
        if not max_age_s > 0:
            raise ValueError(f"max_age_s must be > 0, got {max_age_s!r}")
        self.key, self.alive_key, self.clock, self.max_age_s = key, alive_key, clock, float(max_age_s)
        self._verifier = auth.verifier() if auth is not None else None
        self._lock = threading.Lock()
        self._latest: tuple[T, str, float] | None = None
        self._received = 0
        self._accepted = 0
        self._dropped: dict[str, int] = {}
        self._contest: str | None = None  # why the feed refuses its sender for good (two signers, two passengers)
        self._alive: bool | None = None
        self._went_unseen = False  # the token went since the last alive_over_interval()
        self._alive_foreign = 0  # liveliness samples of another key expression (ignored)
        self._closed = False
        self._listeners: list[Callable[[T], None]] = []
        self._sub = declare(f"subscriber on {key}", lambda: session.declare_subscriber(key, self._on_sample))
        self._alive_sub = None
        if alive_key is not None:
            try:
                self._alive_sub = declare(
                    f"liveliness subscriber on {alive_key}",
                    lambda: session.liveliness().declare_subscriber(alive_key, self._on_alive, history=True),
                )
            except BusError:
                undeclare(self._sub)
                raise

    # -- on Zenoh's thread: never block, never call Zenoh
    def _decode(self, payload: bytes) -> T:
        raise NotImplementedError

    def _order_of(self, value: T) -> tuple[int, float]:
        raise NotImplementedError

    def _admit(self, value: T, key: str, source: str, rx: float) -> str | None:
        """Lock held: the drop reason for ``value`` from ``source``, or None to accept it."""
        raise NotImplementedError

    def _notifies(self, reason: str | None, value: T) -> bool:
        """Whether the listeners hear a sample dropped for ``reason`` (None: accepted)."""
        return reason != "source"

    def _on_sample(self, sample: zenoh.Sample) -> None:
        rx = self.clock.now()
        key = str(sample.key_expr)
        with self._lock:
            self._received += 1
        try:
            raw, source = checked_payload(sample, self._verifier)
            value = self._decode(raw)
        except WireError as exc:
            if exc.reason == "contest":
                with self._lock:
                    first = self._contest is None
                    self._contest = self._contest or exc.detail
                if first:
                    log.error("two signers with the peer's key on %s: %s; its samples are refused from now on", key,
                              exc.detail)
            self._drop(exc.reason, key, str(exc))
            return
        except Exception:  # a bug, not a bad sample: keep Zenoh's thread alive, say it loudly
            log.exception("unexpected error decoding a sample on %s", key)
            self._drop("internal", key, "unexpected error")
            return
        with self._lock:
            reason = self._admit(value, key, source, rx)
            if reason is None:
                self._latest = (value, key, rx)
                self._accepted += 1
        if reason is not None:
            seq, stamp = self._order_of(value)
            self._drop(reason, key, f"seq {seq} stamp {stamp} rx {rx:.3f} from {source}{self._describe(value)}")
        if not self._notifies(reason, value):
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
        key = str(sample.key_expr)
        if key != self.alive_key:
            # a token on a wildcard that intersects the alive key (``marsupial/**``, ``**``): the
            # subscriber hears it come and go while the sender's own token stays; not the sender's
            with self._lock:
                self._alive_foreign += 1
                first = self._alive_foreign == 1
            (log.warning if first else log.debug)(
                "%s: ignored the liveliness %s of a token on %s (another key expression, not the sender's)",
                self.alive_key, "PUT" if alive else "DELETE", key)
            return
        with self._lock:
            changed = alive != self._alive
            self._alive = alive
            if not alive:
                self._went_unseen = True
                self._forget_sender()  # a restarted sender is a new source that may count from 0 again
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
        now = self.clock.now()
        with self._lock:
            item = self._latest
            extra = self._received_extra(now)
        if item is None:
            return None
        value, key, rx = item
        age = now - rx
        return self._received_type(value=value, key=key, rx_time_s=rx, age_s=age, stale=age > self.max_age_s, **extra)

    def newest(self) -> tuple[T, float] | None:
        """The newest accepted message and its receive time [s] on the feed's clock (what
        :meth:`latest` answers, without its age and trust), or None if none was accepted yet."""
        with self._lock:
            item = self._latest
        return None if item is None else (item[0], item[2])

    def _received_extra(self, now: float) -> dict[str, Any]:
        """Lock held: more fields of :meth:`latest`'s answer at clock time ``now`` [s]."""
        return {}

    @property
    def alive(self) -> bool | None:
        """The sender's liveliness token: True present, False gone, None never seen."""
        with self._lock:
            return self._alive

    def alive_over_interval(self) -> bool | None:
        """The sender's liveliness since the previous call: False if the token went at any
        moment in between, even if it is back now (a brief outage, or one while a lockstep
        clock stood still, is still an outage); else :attr:`alive`. Each call starts a new
        interval, so a feed has one such caller (its controller's tick)."""
        with self._lock:
            went, self._went_unseen = self._went_unseen, False
            return False if went else self._alive

    @property
    def counters(self) -> dict[str, Any]:
        """Snapshot: ``{"received": n, "accepted": n, "dropped": {reason: n}, "alive_foreign": n, ...}``
        (``alive_foreign``: liveliness samples of a token on another key expression, ignored)."""
        with self._lock:
            return {"received": self._received, "accepted": self._accepted, "dropped": dict(self._dropped),
                    "signed": self._verifier is not None, "contest": self._contest,
                    "alive_foreign": self._alive_foreign, **self._extra_counters()}

    def _extra_counters(self) -> dict[str, Any]:
        return {}

    def close(self) -> None:
        """Undeclare the subscribers (idempotent)."""
        if self._closed:
            return
        self._closed = True
        undeclare(self._sub, self._alive_sub)

    def __enter__(self) -> "_Feed[T]":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class CarrierFeed(_Feed[CarrierState]):
    """The newest valid carrier state of pair ``pair``, in local NED.

    encoding: "json" (default) or "cdr" (ROS 2 Odometry); key: override of the state key (e.g.
    :func:`mission.bus.ros2.ros2dds_odom_key`); origin: the vehicle's geodetic origin, needed to
    accept wgs84 states (drop reason "origin" without it; see :meth:`set_origin`); max_age_s
    [s] on ``clock``; limits: the carrier's own limits for the plausibility gate (default: 3 m/s
    top speed). The liveliness of ``marsupial/<pair>/carrier/alive`` gives ``alive``; when it
    goes away the feed unbinds its source. ``counters`` add ``bound_source``,
    ``rejected_sources`` ({source: n}), ``resyncs``, ``jumps``, ``settles`` and ``contests`` (the gate's);
    ``latest().untrusted`` says why the newest state is not trusted yet (the gate's trust).
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
        auth: BusAuth | None = None,
        offset: OffsetSource | None = None,
    ) -> None:
        check_encoding(encoding)
        self._offset = offset
        self.delay = DelayWatch()  # the states' transit [s], once the offset is known
        self.encoding = encoding
        self._use_seq = encoding == "json"  # Odometry has no sequence number: order by stamp
        self.gate = FeedGate(limits or GateLimits(max_speed_m_s=3.0), use_seq=self._use_seq)
        self._origin = origin
        self._cdr_count = 0
        self._future_stamps = 0  # states measured, by the offset, after they arrived (see latest)
        k = keys(pair)
        super().__init__(session, key or k.carrier_state, k.carrier_alive, clock, max_age_s, auth)

    @classmethod
    def from_section(
        cls, session: zenoh.Session, section: ZenohSection, clock: Clock, *, max_age_s: float,
        origin: GeoOrigin | None = None, limits: GateLimits | None = None, auth: BusAuth | None = None,
        offset: OffsetSource | None = None,
    ) -> "CarrierFeed":
        """The feed a :class:`ZenohSection` describes (pair, encoding, carrier_key); ``auth``: the
        pair's signing key (:func:`mission.bus.auth.bus_auth`), None for unsigned; ``offset``: where
        the carrier's clock offset comes from (:class:`mission.bus.timesync.ClockPing`, or
        :class:`mission.time.offset.SharedClock` in lockstep), None: ages are receive ages."""
        return cls(session, section.pair, clock, encoding=section.encoding, key=section.carrier_key,
                   origin=origin, max_age_s=max_age_s, limits=limits, auth=auth, offset=offset)

    def _admit(self, value: CarrierState, key: str, source: str, rx: float) -> str | None:
        was = self.gate.bound
        reason = self.gate.offer(source, Sample(value.seq, value.stamp_s, value.position, value.velocity_ned_m_s, rx))
        if self.gate.bound != was:
            log.info("carrier feed bound to source %s on %s", self.gate.bound, key)
        estimate = self._offset.estimate() if reason is None and self._offset is not None else None
        if estimate is not None:
            growing = self.delay.add(rx, sample_age(rx, value.stamp_s, estimate))
            if growing is not None:
                log.warning("carrier feed on %s: %s (a relay holding them? a congested link?)", key, growing)
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
                "resyncs": self.gate.resyncs, "jumps": self.gate.jumps, "settles": self.gate.settles,
                "contests": self.gate.contests,
                "clock_offset": None if self._offset is None else self._offset.snapshot(),
                "delay_growths": self.delay.growths, "delay_growth_last": self.delay.last or None,
                "future_stamps": self._future_stamps}

    def _received_extra(self, now: float) -> dict[str, Any]:
        return {"untrusted": f"signer contest: {self._contest}" if self._contest else self.gate.distrust(now)}

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
        """The newest accepted carrier state (local NED) with its age (measurement age once the
        carrier's clock offset is known; see :class:`ReceivedCarrierState`), or None."""
        got: ReceivedCarrierState | None = super().latest()  # type: ignore[assignment]
        if got is None:
            return None
        estimate = self._offset.estimate() if self._offset is not None else None
        if estimate is None:
            return replace(got, rx_age_s=got.age_s)
        age = sample_age(got.rx_time_s + got.age_s, got.value.stamp_s, estimate)
        if age < got.age_s - estimate.bound_s - FUTURE_SLACK_S:
            # measured after it arrived: the offset does not hold for this carrier's clock (a
            # carrier that left the lockstep, a clock that jumped); aged by its arrival instead
            with self._lock:
                self._future_stamps += 1
                first = self._future_stamps == 1
            if first:
                log.warning("carrier feed on %s: a state stamped %.3f s after it arrived (offset %.3f +- %.3f s): "
                            "aged by its arrival instead", got.key, got.age_s - age, estimate.offset_s, estimate.bound_s)
            return replace(got, rx_age_s=got.age_s)
        return replace(got, age_s=age, rx_age_s=got.age_s, age_bound_s=estimate.bound_s,
                                   stale=age + estimate.bound_s > self.max_age_s)


class PassengerFeed(_Feed[PassengerStatus]):
    """The newest valid passenger status of pair ``pair`` (for the carrier), with liveliness;
    ``passenger``: the name of one passenger of a team, heard on its own keys (None: the pair's).

    Source binding: the feed binds to the first source (the verified signer with ``auth``, else
    Zenoh's ``source_info``) that sends ``bind_samples`` statuses in order (sequence number
    rising, stamp not falling) whose phase is in ``bind_phases`` (None: any): the carrier passes
    the phases before riding, so a source that starts by claiming RIDING (a passenger that never
    stood on the deck) never binds. Until then statuses are dropped as ``unbound``; once bound,
    every other source's as ``source`` (counted per source in ``counters["rejected_sources"]``),
    so a flood from elsewhere can neither pass for the passenger nor make its statuses stale. A
    status of another source in one of ``bind_phases`` while bound is a second passenger standing
    on the deck: a contest (``counters["contest"]`` says why), and the feed trusts no status from
    then on (``contest``), so the carrier stops rather than serve either.
    The bound source's statuses must be newer than its last accepted one (``stale_seq``,
    ``stale_stamp``). When the passenger's liveliness token goes away the feed unbinds (a
    restarted passenger is a new source); the source it was bound to may bind again in any phase
    (a brief outage of the token while it rides).
    """

    _received_type = ReceivedPassengerStatus

    def __init__(self, session: zenoh.Session, pair: str, clock: Clock, *, max_age_s: float = 1.0,
                 auth: BusAuth | None = None, bind_phases: frozenset[str] | None = None, bind_samples: int = 1,
                 passenger: str | None = None) -> None:
        if bind_samples < 1:
            raise ValueError(f"bind_samples must be >= 1, got {bind_samples!r}")
        self.bind_phases, self.bind_samples = bind_phases, bind_samples
        self.bound: str | None = None
        self.rejected_sources: dict[str, int] = {}
        self._candidates: dict[str, tuple[int, float, int]] = {}  # source -> (seq, stamp, statuses in order)
        self._last: tuple[int, float] | None = None  # the bound source's last (seq, stamp)
        self._previous: str | None = None  # the source bound before the token went
        k = keys(pair, passenger)  # a team's passenger: its own keys, bound on its own
        super().__init__(session, k.passenger_state, k.passenger_alive, clock, max_age_s, auth)

    def _admit(self, value: PassengerStatus, key: str, source: str, rx: float) -> str | None:
        order = (value.seq, value.stamp_s)
        if self._contest is not None:
            return "contest"
        if self.bound is None:
            if self.bind_phases is not None and value.phase not in self.bind_phases and source != self._previous:
                return "unbound"
            last = self._candidates.get(source)
            if last is None and len(self._candidates) >= MAX_CANDIDATES:
                return "unbound"
            count = last[2] + 1 if last is not None and order[0] > last[0] and order[1] >= last[1] else 1
            self._candidates[source] = (*order, count)
            if count < self.bind_samples:
                return "unbound"
            self.bound, self._last = source, order
            self._candidates.clear()
            log.info("passenger feed bound to source %s on %s", source, key)
            return None
        if source != self.bound:
            count_rejected(self.rejected_sources, source)
            if self.bind_phases is not None and value.phase in self.bind_phases:
                self._contest = (f"a second passenger {source} says {value.phase} (before riding) while bound to "
                                 f"{self.bound}")
                self._latest = None
                log.error("passenger feed on %s: %s; no passenger is trusted from now on", key, self._contest)
                return "contest"
            return "source"
        assert self._last is not None
        if order[0] <= self._last[0]:
            return "stale_seq"
        if order[1] < self._last[1]:
            return "stale_stamp"
        self._last = order
        return None

    def _notifies(self, reason: str | None, value: PassengerStatus) -> bool:
        # the bound passenger's statuses, and a candidate's while none is bound (the lockstep
        # clock waits for the status a step names); never a stranger's
        return reason is None or (reason == "unbound" and (self.bind_phases is None or value.phase in self.bind_phases
                                                            or self._previous is not None))

    def _forget_sender(self) -> None:
        if self.bound is not None:
            log.warning("passenger feed: source %s unbound (liveliness token gone)", self.bound)
            self._previous = self.bound
        self.bound, self._last = None, None
        self._candidates.clear()

    def _extra_counters(self) -> dict[str, Any]:
        return {"bound_source": self.bound, "rejected_sources": dict(self.rejected_sources)}

    def _decode(self, payload: bytes) -> PassengerStatus:
        return decode_passenger_json(payload)

    def _order_of(self, value: PassengerStatus) -> tuple[int, float]:
        return value.seq, value.stamp_s

    def latest(self) -> ReceivedPassengerStatus | None:  # type: ignore[override]
        """The newest accepted passenger status with its age, or None."""
        return super().latest()  # type: ignore[return-value]
