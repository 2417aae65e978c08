"""Lockstep simulated time over Zenoh, and the protocol (the wire side of :class:`~mission.time.clock.LockstepClock`).

The mock vehicle owns simulated time; the controller and the carrier step on it, and their code is
the same as in real time (only the injected clock differs). Messages (times in [ns]):

- vehicle -> controller, MAVLink: ``SYSTEM_TIME`` (time_boot_ms ``t``: what follows was sampled at
  ``t``), then a barrier ``TIMESYNC(tc1 0, ts1 t)``: integrated to ``t``, no further until answered;
- controller -> vehicle: ``TIMESYNC(tc1 wake, ts1 t)``: step ``t`` done (its setpoint and commands
  sent before, on the same socket), next needed at ``wake`` (``wake < 0``: leaving the lockstep;
  ``wake == t``: still working on it, waiting for a slow carrier);
- controller -> carrier, Zenoh ``marsupial/<pair>/clock/time`` ``"t seq"``: step to ``t`` once you
  have passenger status ``seq`` (``t < 0``: the controller left the lockstep); carrier ->
  controller, ``clock/ready`` ``"t wake seq"``: done at ``t``, next at ``wake``, its last state
  sample is ``seq``. Zenoh does not order samples across keys, so each side waits for the sample
  named, not only for the clock message.

The MAVLink side (the vehicle's clock, and :class:`~mission.mavlink.lockstep.MavlinkRelay`, which
brings a carrier's own lockstep vehicle, the mock rover, along the same way) is
:mod:`mission.mavlink.lockstep`. Watchdogs (``*_WATCHDOG_WALL_S``, wall seconds, with the other
limits in :mod:`mission.time.clock`) drop a silent participant, a carrier whose liveliness token
is present gets longer; an unanswered call is resent every :data:`RESEND_WALL_S`, and a named
sample that never comes is given up after :data:`LOST_WALL_S` and :data:`LOST_AFTER_REPEATS`
repeats (``samples_lost``: the run is no longer deterministic).
Why each rule, and what was measured: docs/lockstep.md. With ``zenoh.signing_key_file`` the clock
messages carry the pair's authentication tag (:mod:`mission.bus.signing`); an unsigned or badly
signed one is dropped like a malformed one.
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

import zenoh

from mission.bus.auth import BusAuth
from mission.bus.bridge import keys, undeclare
from mission.bus.wire import WireError
from mission.time.clock import (
    CARRIER_WATCHDOG_WALL_S,
    HELLO_WALL_S,
    LOST_AFTER_REPEATS,
    LOST_WALL_S,
    RESEND_WALL_S,
    LockstepClock,
    Silence,
)

log = logging.getLogger(__name__)


def clock_keys(pair: str, passenger: str | None = None) -> tuple[str, str]:
    """The (time, ready) keys of pair ``pair``; ``passenger``: the clock on which a team's carrier
    brings passenger NAME along (every passenger of a team but the first, whose vehicle owns the
    time: docs/team.md), ``marsupial/<pair>/clock/<name>/...``."""
    root = keys(pair, passenger).carrier_state.rsplit("/", 2)[0]
    clock = "clock" if passenger is None else f"clock/{passenger}"
    return f"{root}/{clock}/time", f"{root}/{clock}/ready"


class Downstreams:
    """Several :class:`~mission.time.clock.Downstream` relays as one: each brought to a step in
    turn, the earliest wake of any (a team's carrier brings its robot and its later passengers)."""

    def __init__(self, relays: list[Any]) -> None:
        self.relays = [r for r in relays if r is not None]

    def run(self, t_ns: int) -> None:
        for relay in self.relays:
            relay.run(t_ns)

    def wake_ns(self) -> int | None:
        wakes = [w for w in (r.wake_ns() for r in self.relays) if w is not None]
        return min(wakes) if wakes else None

    def leave(self) -> None:
        for relay in self.relays:
            relay.leave()


class LastSeq:
    """``last_seq``: the seq of the last sample a sender published, as ``published()`` tells
    (the carrier's state, for a :class:`ZenohRelay` to a later passenger of its team)."""

    def __init__(self, published: Callable[[], int]) -> None:
        self._published = published

    @property
    def last_seq(self) -> int:
        return self._published()


class _ClockWire:
    """One side's clock messages: puts text on ``key`` and reads the integers of the other
    side's; with ``auth`` (the pair's bus key) both signed, and an unsigned, badly signed or
    replayed message is dropped and counted (:attr:`rejected`) like a malformed one."""

    def __init__(self, session: zenoh.Session, key: str, auth: BusAuth | None) -> None:
        # Reliable and blocking: a clock message must never be dropped; express keeps it in order
        # with the (express) state samples of the same session.
        self.key = key
        self.pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK, express=True)
        self._signer = auth.signer() if auth is not None else None
        self._verifier = auth.verifier() if auth is not None else None
        self.rejected = 0

    def put(self, text: str) -> None:
        payload = text.encode()
        self.pub.put(payload, attachment=None if self._signer is None else self._signer.attachment(self.key, payload))

    def read(self, sample: zenoh.Sample, count: int) -> list[int] | None:
        """The ``count`` integers of ``sample``, or None (dropped, logged)."""
        raw = sample.payload.to_bytes()
        try:
            if self._verifier is not None:
                self._verifier.verify(sample, raw)
            values = [int(v) for v in raw.decode("ascii").split()]
            if len(values) != count:
                raise ValueError(f"{len(values)} numbers, not {count}")
        except (WireError, UnicodeDecodeError, ValueError) as exc:
            self.rejected += 1
            (log.warning if self.rejected == 1 else log.debug)("lockstep: clock message on %s dropped: %s",
                                                               sample.key_expr, exc)
            return None
        return values


class ZenohRelay:
    """The controller brings the pair's carrier simulator along (a :class:`~mission.time.clock.Downstream`),
    on the ``keys`` (time, ready) of :func:`clock_keys`; ``feed`` calls back with each sample it
    receives (``.seq``), ``publisher.last_seq`` is the seq of the last sample sent. The same relay
    brings a ROS-2-shaped robot along for the ros2 carrier (``name`` "robot", keys
    :func:`mission.carrier.backends.ros2.robot_clock_keys`, rmw_zenoh sequence numbers).

    Before the first barrier completes it calls the carrier every :data:`HELLO_WALL_S` until it
    answers (for at most ``join_wall_s``); later it waits ``watchdog_wall_s`` at most, or
    ``alive_watchdog_wall_s`` (default: the same; ``sim.lockstep_carrier_wait_wall_s`` in a
    mission) while ``alive()`` (the carrier's liveliness token) is True, calling ``keepalive()``
    meanwhile (the controller's clock tells the vehicle it still works on the step), and not at
    all once it is False; then it drops the carrier until it answers again (a late or restarted
    carrier rejoins at the first later step it answers: :attr:`rejoined`; the waits leave out
    this process's own stalls, :class:`~mission.time.clock.Silence`). Once joined it calls again
    every :data:`RESEND_WALL_S` while unanswered, and gives up a state sample a ready names after ``lost_wall_s`` (default
    :data:`LOST_WALL_S`) and :data:`LOST_AFTER_REPEATS` readies naming it (the calls then repeated
    every ``lost_wall_s / LOST_AFTER_REPEATS`` if that is shorter). :attr:`dropped` counts the
    drops, :attr:`missed` the samples given up.
    """

    def __init__(self, session: zenoh.Session, keys: tuple[str, str], feed: Any, publisher: Any, *,
                 alive: Callable[[], bool | None] | None = None,
                 watchdog_wall_s: float = CARRIER_WATCHDOG_WALL_S, alive_watchdog_wall_s: float | None = None,
                 join_wall_s: float = 30.0, name: str = "carrier", auth: BusAuth | None = None,
                 lost_wall_s: float = LOST_WALL_S, keepalive: Callable[[], None] | None = None) -> None:
        time_key, ready_key = keys
        self.watchdog_wall_s, self.join_wall_s, self.name = watchdog_wall_s, join_wall_s, name
        self.lost_wall_s = lost_wall_s
        self._resend_wall_s = min(RESEND_WALL_S, lost_wall_s / LOST_AFTER_REPEATS)
        self.alive_watchdog_wall_s = max(alive_watchdog_wall_s or watchdog_wall_s, watchdog_wall_s)
        self._alive, self._keepalive = alive, keepalive
        self._publisher = publisher  # PassengerPublisher: last_seq
        self._cv = threading.Condition()
        self._ready: tuple[int, int, int] | None = None
        self._seen_seq = -1  # newest carrier state seq received
        self._state = "joining"  # -> joined -> dropped -> joined ...
        self._wake_ns = 0
        self._step_ns, self._step_readies = 0, 0  # the step run() waits for, readies for it so far
        self.dropped = 0
        self.rejoined = 0  # drops after which the carrier answered again (and steps with us again)
        self.missed = 0  # state samples given up (lost in an outage)
        self._dropped_ns: int | None = None  # the step the last drop came at
        self._closed = False
        self._wire = _ClockWire(session, time_key, auth)
        self._sub = session.declare_subscriber(ready_key, self._on_ready)
        feed.add_listener(self._on_state)

    def _call(self, call: str) -> bool:
        """Put the clock call; False once :meth:`close` undeclared the publisher (a step still in
        flight while the process shuts down ends there)."""
        try:
            self._wire.put(call)
            return True
        except zenoh.ZError:
            if self._closed:
                return False
            raise

    def _on_state(self, state: Any) -> None:
        with self._cv:
            self._seen_seq = max(self._seen_seq, int(state.seq))
            self._cv.notify_all()

    def _on_ready(self, sample: zenoh.Sample) -> None:
        values = self._wire.read(sample, 3)
        if values is None:
            return
        with self._cv:
            self._ready = (values[0], values[1], values[2])
            if values[0] >= self._step_ns:
                self._step_readies += 1
            if values[1] < 0:  # it left
                if self._state != "dropped":
                    log.info("lockstep: the %s left at t = %.3f s", self.name, values[0] / 1e9)
                self._state = "dropped"
            elif self._state == "dropped":
                self._state, self._wake_ns = "joined", values[1]
                if self._dropped_ns is not None:
                    self.rejoined += 1
                log.warning("lockstep: the %s is back (ready at t = %.3f s): it steps with us again from its next "
                            "step; the run was not lockstep %s", self.name, values[0] / 1e9,
                            "before" if self._dropped_ns is None else f"from t = {self._dropped_ns / 1e9:.3f} s")
            self._cv.notify_all()

    def wake_ns(self) -> int | None:
        with self._cv:
            return self._wake_ns if self._state == "joined" else None

    def leave(self) -> None:
        """Tell the carrier that this clock left the lockstep (``"-1 seq"``): it goes on in real
        time now, rather than after its watchdog (the run's end is not its controller's silence)."""
        with self._cv:
            state = self._state
        if state == "joined":
            self._call(f"-1 {self._publisher.last_seq}")

    def run(self, t_ns: int) -> None:
        with self._cv:
            state, wake = self._state, self._wake_ns
        call = f"{t_ns} {self._publisher.last_seq}"
        if state == "dropped":
            self._call(call)  # lets a restarted carrier find the clock
            return
        if state == "joined" and wake > t_ns:
            return
        start = last_put = time.monotonic()
        silence = Silence()  # the carrier's, without this process's own stalls
        slow_logged = False
        with self._cv:
            self._step_ns, self._step_readies = t_ns, 0
        if not self._call(call):
            return
        with self._cv:
            while not (self._ready is not None and self._ready[0] >= t_ns and self._seen_seq >= self._ready[2]):
                if self._closed:
                    return
                now, waited = time.monotonic(), silence.elapsed()
                if (self._ready is not None and self._ready[0] >= t_ns and now - start > self.lost_wall_s
                        and self._step_readies >= LOST_AFTER_REPEATS):
                    self.missed += 1
                    log.warning("lockstep: the %s's state sample %d never came (step t = %.3f s, %d readies in "
                                "%.1f s, wall); going on without it", self.name, self._ready[2], t_ns / 1e9,
                                self._step_readies, now - start)
                    break
                token = None if self._alive is None or state == "joining" else self._alive()
                limit = self.join_wall_s if state == "joining" else (
                    self.alive_watchdog_wall_s if token else self.watchdog_wall_s)
                if token is False or waited > limit:
                    self._state, self._dropped_ns = "dropped", t_ns
                    self.dropped += 1
                    why = "its liveliness token is gone" if token is False else f"no answer within {limit:.1f} s (wall)"
                    log.warning("lockstep: the %s dropped at step t = %.3f s (%s); going on without it: the run is "
                                "no longer lockstep (it rejoins at the next step it answers)", self.name,
                                t_ns / 1e9, why)
                    return
                if token and not slow_logged and waited > self.watchdog_wall_s:
                    slow_logged = True
                    log.warning("lockstep: the %s has not finished step t = %.3f s after %.1f s (wall), but its "
                                "liveliness token is present: waiting up to %.1f s", self.name, t_ns / 1e9,
                                waited, limit)
                if now - last_put > (HELLO_WALL_S if self._state == "joining" else self._resend_wall_s):
                    self._cv.release()
                    try:
                        sent = self._call(call)
                        if token and self._keepalive is not None:
                            self._keepalive()  # our upstream (the vehicle) waits for us meanwhile
                    finally:
                        self._cv.acquire()
                    if not sent:
                        return
                    last_put = now
                self._cv.wait(HELLO_WALL_S)
            self._state, self._wake_ns = "joined", self._ready[1]

    def close(self) -> None:
        with self._cv:
            self._closed = True
            self._cv.notify_all()
        undeclare(self._sub, self._wire.pub)


class ZenohUpstream:
    """The carrier simulator's side: steps on ``clock/time`` once the passenger status it names
    has arrived on ``feed`` (a PassengerFeed: callbacks with ``.seq``), answers on ``clock/ready``
    with the seq of its last state sample (``published()``). ``keys``: (time, ready) of
    :func:`clock_keys` (the ROS-2-shaped robot steps on the ros2 carrier's the same way).

    A status that never comes (lost in an outage) is given up after :data:`LOST_WALL_S` and
    :data:`LOST_AFTER_REPEATS` repeated calls naming it (:attr:`missed`); a repeated call for a
    step already taken is passed on at once (the clock reports that step again)."""

    def __init__(self, clock: LockstepClock, session: zenoh.Session, keys: tuple[str, str], feed: Any,
                 published: Callable[[], int], auth: BusAuth | None = None) -> None:
        time_key, ready_key = keys
        self.clock, self._published = clock, published
        self._lock = threading.Lock()
        self._seen_seq = -1  # newest passenger status seq received
        self._pending: tuple[int, int] | None = None  # (t, status seq) waiting for that status
        self._pending_since, self._pending_calls = 0.0, 0  # wall time of its first call [s], calls since
        self._stepped_ns = -1  # the latest step passed to the clock
        self.missed = 0  # passenger statuses given up (lost in an outage)
        self._wire = _ClockWire(session, ready_key, auth)
        feed.add_listener(self._on_status)
        self._sub = session.declare_subscriber(time_key, self._on_time)
        clock.upstream = self

    def _on_status(self, status: Any) -> None:
        with self._lock:
            self._seen_seq = max(self._seen_seq, int(status.seq))
            pending = self._pending
            if pending is None or self._seen_seq < pending[1]:
                return
            self._pending = None
            self._stepped_ns = max(self._stepped_ns, pending[0])
        self.clock.barrier(pending[0])

    def _on_time(self, sample: zenoh.Sample) -> None:
        values = self._wire.read(sample, 2)
        if values is None:
            return
        t_ns, seq = values
        if t_ns < 0:  # the controller left the lockstep: real time from now, as after a silence
            log.info("lockstep: the controller left; going on in real time")
            threading.Thread(target=self.clock.close, name="lockstep-leave", daemon=True).start()
            return
        self.clock.heard()  # the controller is there, even while its call waits for the status it names
        with self._lock:
            if self._seen_seq < seq and t_ns > self._stepped_ns:
                now = time.monotonic()
                if self._pending is None or self._pending[0] != t_ns:
                    self._pending, self._pending_since, self._pending_calls = (t_ns, seq), now, 0
                    return
                self._pending_calls += 1  # the same call again: its status may be lost
                if now - self._pending_since < LOST_WALL_S or self._pending_calls < LOST_AFTER_REPEATS:
                    return
                self.missed += 1
                log.warning("lockstep: the passenger status %d never came (step t = %.3f s, %d calls in %.1f s, "
                            "wall); stepping without it", seq, t_ns / 1e9, self._pending_calls + 1,
                            now - self._pending_since)
            self._pending = None
            self._stepped_ns = max(self._stepped_ns, t_ns)
        self.clock.barrier(t_ns)

    def report(self, t_ns: int, wake_ns: int) -> None:
        self._wire.put(f"{t_ns} {wake_ns} {self._published()}")

    def close(self) -> None:
        undeclare(self._sub, self._wire.pub)
