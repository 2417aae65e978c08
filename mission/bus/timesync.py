"""The carrier's clock over the bus: signed pings and echoes (thin I/O; the estimate is
:mod:`mission.time.offset`).

The passenger (:class:`ClockPing`) puts ``"<seq>"`` on ``marsupial/<pair>/time/ping`` every
``period_s`` of its clock and keeps when it sent each; the carrier (:class:`ClockEcho`) answers
each ping at once on ``marsupial/<pair>/time/echo`` with ``"<seq> <its clock [s]>"``, the clock
that stamps its states. With the pair's key (``zenoh.signing_key_file``) both are signed as every
bus sample is (:mod:`mission.bus.auth`), and an unsigned, forged or replayed one is dropped and
counted. An echo that answers no ping of ours in flight is counted (``unknown``), never used.
The echo answers at most :data:`ECHO_RATE_HZ` pings per wall second (a flood of pings is not
echoed back). Layout and rules: docs/wire.md.
"""
from __future__ import annotations

import logging
import math
import secrets
import threading
import time
from typing import Any, Callable

import zenoh

from mission.bus.auth import BusAuth
from mission.bus.session import declare, keys, undeclare
from mission.bus.wire import WireError
from mission.time.clock import Clock
from mission.time.offset import OffsetEstimate, OffsetEstimator, RoundTrip

log = logging.getLogger("mission.bus.bridge")

MAX_MESSAGE_BYTES = 64  # a ping or an echo is ~30 B of text
PINGS_IN_FLIGHT = 16  # pings remembered until their echo (older ones are forgotten)
ECHO_RATE_HZ = 20.0  # most pings the carrier answers per wall second


def time_keys(pair: str) -> tuple[str, str]:
    """The (ping, echo) keys of pair ``pair``."""
    root = keys(pair).carrier_state.rsplit("/", 2)[0]
    return f"{root}/time/ping", f"{root}/time/echo"


class _Wire:
    """Signed text put on ``key`` (:meth:`put`); the verified words of the other side's samples
    (:meth:`read`), heard once :meth:`listen` declares their subscriber."""

    def __init__(self, session: zenoh.Session, key: str, auth: BusAuth | None) -> None:
        self.key, self._session = key, session
        self._signer = auth.signer() if auth is not None else None
        self._verifier = auth.verifier() if auth is not None else None
        self.pub = declare(f"publisher on {key}", lambda: session.declare_publisher(
            key, congestion_control=zenoh.CongestionControl.DROP, express=True))
        self.sub: Any = None

    def listen(self, key: str, on_sample: Callable[[zenoh.Sample], None]) -> None:
        """Hand the samples of ``key`` to ``on_sample`` (on Zenoh's thread); on failure the
        publisher is undeclared too."""
        try:
            self.sub = declare(f"subscriber on {key}", lambda: self._session.declare_subscriber(key, on_sample))
        except Exception:
            undeclare(self.pub)
            raise

    def close(self) -> None:
        undeclare(self.sub, self.pub)

    def put(self, text: str) -> None:
        payload = text.encode()
        self.pub.put(payload, attachment=None if self._signer is None else self._signer.attachment(self.key, payload))

    def read(self, sample: zenoh.Sample) -> list[str]:
        """The words of ``sample``; raises :class:`WireError` (size, unsigned, signature, replay, decode)."""
        if len(sample.payload) > MAX_MESSAGE_BYTES:
            raise WireError("size", f"{len(sample.payload)} bytes > {MAX_MESSAGE_BYTES}")
        raw = sample.payload.to_bytes()
        if self._verifier is not None:
            self._verifier.verify(sample, raw)
        try:
            return raw.decode("ascii").split()
        except UnicodeDecodeError:
            raise WireError("decode", "not ASCII text") from None


def _count(counters: dict[str, Any], reason: str) -> None:
    dropped = counters.setdefault("dropped", {})
    dropped[reason] = dropped.get(reason, 0) + 1


class ClockEcho:
    """The carrier's side: answers every ping of pair ``pair`` with ``clock``'s time."""

    def __init__(self, session: zenoh.Session, pair: str, clock: Clock, auth: BusAuth | None = None) -> None:
        ping_key, echo_key = time_keys(pair)
        self.clock = clock
        self._lock = threading.Lock()
        self.counters: dict[str, Any] = {"pings": 0, "echoes": 0, "dropped": {}}
        self._window: tuple[float, int] = (time.monotonic(), 0)  # (wall second began, echoes in it)
        self._wire = _Wire(session, echo_key, auth)
        self._wire.listen(ping_key, self._on_ping)

    def _on_ping(self, sample: zenoh.Sample) -> None:
        now = self.clock.now()
        with self._lock:
            self.counters["pings"] += 1
            try:
                words = self._wire.read(sample)
                if len(words) != 1 or not words[0].isdigit() or len(words[0]) > 19:
                    raise WireError("decode", "a ping is one sequence number")
            except WireError as exc:
                _count(self.counters, exc.reason)
                return
            start, n = self._window
            wall = time.monotonic()
            if wall - start >= 1.0:
                start, n = wall, 0
            if n >= ECHO_RATE_HZ:
                _count(self.counters, "rate")
                return
            self._window = (start, n + 1)
            self.counters["echoes"] += 1
        try:
            self._wire.put(f"{words[0]} {now!r}")
        except zenoh.ZError as exc:
            log.debug("echo not sent: %s", exc)

    def close(self) -> None:
        self._wire.close()


class ClockPing:
    """The passenger's side: pings the carrier of pair ``pair`` every ``period_s`` [s] of
    ``clock`` (a thread), turns each echo into a :class:`~mission.time.offset.RoundTrip` for
    ``estimator``; :meth:`estimate` is the carrier's clock offset now, or None."""

    def __init__(self, session: zenoh.Session, pair: str, clock: Clock, auth: BusAuth | None = None, *,
                 period_s: float = 0.5, estimator: OffsetEstimator | None = None) -> None:
        ping_key, echo_key = time_keys(pair)
        self.clock, self.period_s = clock, period_s
        self.estimator = estimator or OffsetEstimator()
        self._lock = threading.Lock()
        self._sent: dict[int, float] = {}
        self._seq = secrets.randbelow(10**15)  # several passengers ping one echo: their numbers never meet
        self.counters: dict[str, Any] = {"pings": 0, "echoes": 0, "dropped": {}}
        self._wire = _Wire(session, ping_key, auth)
        self._wire.listen(echo_key, self._on_echo)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="mission-clock-ping", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                self._seq += 1
                seq = self._seq
                self._sent[seq] = self.clock.now()
                if len(self._sent) > PINGS_IN_FLIGHT:
                    del self._sent[min(self._sent)]
                self.counters["pings"] += 1
            try:
                self._wire.put(str(seq))
            except zenoh.ZError as exc:
                log.debug("ping not sent: %s", exc)
            self._stop.wait(self.period_s / float(self.clock.speed))

    def _on_echo(self, sample: zenoh.Sample) -> None:
        received = self.clock.now()
        with self._lock:
            try:
                words = self._wire.read(sample)
                if len(words) != 2 or not words[0].isdigit() or len(words[0]) > 19:
                    raise WireError("decode", "an echo is a sequence number and a time")
                remote = float(words[1])
                if not math.isfinite(remote):
                    raise WireError("nonfinite", "echo time")
            except (WireError, ValueError) as exc:
                _count(self.counters, exc.reason if isinstance(exc, WireError) else "decode")
                return
            sent = self._sent.pop(int(words[0]), None)
            if sent is None:
                _count(self.counters, "unknown")
                return
            self.counters["echoes"] += 1
            why = self.estimator.add(RoundTrip(sent, remote, received))
            if why is not None:
                _count(self.counters, why)

    def estimate(self) -> OffsetEstimate | None:
        """The carrier's clock minus ours now, with its bound, or None (no round trip yet)."""
        now = self.clock.now()
        with self._lock:
            return self.estimator.estimate(now)

    def snapshot(self) -> dict[str, Any]:
        """The counters and the estimate now, for summary.json."""
        est = self.estimate()
        with self._lock:
            out = {**self.counters, "dropped": dict(self.counters["dropped"])}
        out["offset_s"] = None if est is None else round(est.offset_s, 6)
        out["bound_s"] = None if est is None else round(est.bound_s, 6)
        return out

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._wire.close()
