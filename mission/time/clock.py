"""Injected clocks.

Every timeout, watchdog, stream period and integration step reads a :class:`Clock`, never
``time.time()``. A :class:`ScaledClock` runs ``speed`` times faster than the wall clock, like
PX4's SIH speed factor, so processes that share a speed factor agree on rates and timeouts while a test
flies a minute in seconds. A :class:`ManualClock` is driven by hand in unit tests; a :class:`MonotonicClock`
(speed 1) converts to and from CLOCK_MONOTONIC stamps.
A :class:`LockstepClock` follows simulated time owned by another process (the mock vehicle) and
holds it until every thread of this process that waits on the clock has finished its step, as
PX4 SITL does with its simulator (the wire protocol: :mod:`mission.bus.lockstep`, :mod:`mission.mavlink.lockstep`).

Waiting: a thread that blocks for a time or on a condition does so through the clock
(``sleep``, ``wait``) and wakes others with ``notify``, so the same code runs on a scaled wall
clock and in lockstep.
"""
from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

log = logging.getLogger(__name__)

_WALL_SLICE_S = 0.05  # longest wall-clock block of a condition wait on a scaled clock [s]
NS_PER_S = 1_000_000_000


def to_ns(t_s: float) -> int:
    """Seconds to integer nanoseconds (rounded: ``0.06000000000000001`` is 60 ms)."""
    return round(t_s * NS_PER_S)


class Clock(Protocol):
    """A monotonic time source in seconds [s] of simulated time."""

    speed: float

    def now(self) -> float: ...

    def sleep(self, duration_s: float) -> None: ...

    def wait(self, cond: threading.Condition, timeout_s: float) -> None:
        """Wait on ``cond`` (its lock held) until notified or ``timeout_s`` [s] passed; may wake
        early, so call it in a loop that re-checks its predicate."""
        ...

    def notify(self, cond: threading.Condition) -> None:
        """``cond.notify_all()`` (its lock held) for threads waiting through :meth:`wait`."""
        ...

    @property
    def counters(self) -> dict[str, object] | None:
        """A lockstep clock's health (was every step in step?); None for other clocks."""
        ...

    def close(self) -> None: ...


class ScaledClock:
    """Monotonic clock that advances ``speed`` simulated seconds per wall second.

    ``now()`` starts at ``start_s`` when the clock is made. ``sleep(d)`` blocks ``d / speed``
    wall seconds.
    """

    counters = None  # only a lockstep clock keeps counters

    def __init__(self, speed: float = 1.0, start_s: float = 0.0) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed!r}")
        self.speed = float(speed)
        self._t0 = time.monotonic() - start_s / self.speed

    def now(self) -> float:
        return (time.monotonic() - self._t0) * self.speed

    def sleep(self, duration_s: float) -> None:
        if duration_s > 0:
            time.sleep(duration_s / self.speed)

    def wait(self, cond: threading.Condition, timeout_s: float) -> None:
        if timeout_s > 0:
            cond.wait(min(timeout_s / self.speed, _WALL_SLICE_S))

    def notify(self, cond: threading.Condition) -> None:
        cond.notify_all()

    def close(self) -> None:
        pass

    def wall(self, duration_s: float) -> float:
        """Wall-clock seconds that ``duration_s`` simulated seconds take."""
        return duration_s / self.speed


class ManualClock:
    """A clock advanced explicitly (unit tests); ``sleep`` advances it instantly, ``wait``
    blocks at most one short wall slice (deadlines never pass by themselves)."""

    counters = None  # only a lockstep clock keeps counters

    def __init__(self, start_s: float = 0.0) -> None:
        self.speed = 1.0
        self._t = float(start_s)
        self._lock = threading.Lock()

    def now(self) -> float:
        with self._lock:
            return self._t

    def advance(self, duration_s: float) -> None:
        with self._lock:
            self._t += duration_s

    def advance_to(self, t_s: float) -> None:
        """Move the clock to ``t_s`` [s] (never back): a time owner's step times, exactly."""
        with self._lock:
            self._t = max(self._t, float(t_s))

    def sleep(self, duration_s: float) -> None:
        self.advance(max(duration_s, 0.0))

    def wait(self, cond: threading.Condition, timeout_s: float) -> None:
        cond.wait(min(max(timeout_s, 0.0), _WALL_SLICE_S))

    def notify(self, cond: threading.Condition) -> None:
        cond.notify_all()

    def close(self) -> None:
        pass


class Periodic:
    """Deadline keeper for a fixed-rate loop: ``wait()`` sleeps until the next tick.

    Ticks are scheduled on an absolute grid (no drift); if the loop falls behind by more
    than one period the grid is re-anchored and the overrun counted. That includes a sleep
    that ends more than a period late (the process was stopped or starved in it): the tick is
    then the time it really is, not the grid time it overslept, so a tick's time is never
    older than the observations read in it.
    """

    def __init__(self, clock: Clock, period_s: float) -> None:
        if not period_s > 0:
            raise ValueError(f"period must be > 0, got {period_s!r}")
        self.clock, self.period_s = clock, float(period_s)
        self._next, self.overruns = clock.now() + self.period_s, 0

    def wait(self) -> float:
        """Sleep until the next tick; return the clock time of the tick."""
        now = self.clock.now()
        if now <= self._next + self.period_s:
            self.clock.sleep(self._next - now)
            now = self.clock.now()
        if now > self._next + self.period_s:
            self.overruns += 1
            self._next = now
        tick = self._next
        self._next += self.period_s
        return tick


def join_thread(clock: Clock, thread: threading.Thread, timeout_s: float) -> bool:
    """Wait on ``clock`` until ``thread`` has ended or ``timeout_s`` [s] passed; True if it
    ended. Unlike ``thread.join`` it lets a lockstep clock run the thread meanwhile."""
    if not (isinstance(clock, LockstepClock) and clock.lockstep):
        thread.join(timeout_s / clock.speed)
        return not thread.is_alive()
    deadline = clock.now() + timeout_s
    while thread.is_alive() and clock.now() < deadline:
        clock.sleep(min(0.01, max(deadline - clock.now(), 0.0)))
    return not thread.is_alive()


def start_thread(clock: Clock, target: Callable[[], None], name: str) -> threading.Thread:
    """Start ``target`` in a daemon thread ``name``; in lockstep a participant from its start."""
    if isinstance(clock, LockstepClock) and clock.lockstep:
        return clock.start_thread(target, name)
    thread = threading.Thread(target=target, name=name, daemon=True)
    thread.start()
    return thread


# ------------------------------------------------------------------------------------- lockstep

# The lockstep protocol's limits on the wall clock, for the relays over Zenoh (mission.bus.lockstep)
# and MAVLink (mission.mavlink.lockstep); why each: docs/lockstep.md.
HELLO_WALL_S = 0.05  # resend period of a call nobody has answered yet [s, wall]
RESEND_WALL_S = 0.5  # resend period of an unanswered call once joined (an outage lost it) [s, wall]
LOST_WALL_S = 2.0  # a named sample still missing this long ... [s, wall]
LOST_AFTER_REPEATS = 3  # ... after this many repeats of the message naming it is given up
CARRIER_WATCHDOG_WALL_S = 2.0  # the controller drops a carrier silent this long [s, wall]
# ... or, while its liveliness token is present, sim.lockstep_carrier_wait_wall_s (the configuration)
CONTROLLER_WATCHDOG_WALL_S = 5.0  # the controller's clock falls back to the wall clock [s, wall]
VEHICLE_WATCHDOG_WALL_S = 10.0  # the vehicle drops a controller silent this long [s, wall]
OWN_STALL_WALL_S = 1.0  # a watchdog's wait this much longer than asked: this process stood still [s, wall]


class Silence:
    """How long [s, wall] a peer has been silent as this process saw it: a stretch in which this
    process itself stood still (stopped by SIGSTOP, or starved: one of its watchdog's short waits
    took over :data:`OWN_STALL_WALL_S`) is not the peer's silence, whose messages are waiting in
    this process's sockets. :meth:`restart` on each message of the peer (and when this process
    begins to wait for it); :meth:`elapsed` after each wait (every few tens of ms), or a stall is
    taken for silence."""

    def __init__(self) -> None:
        self._since = self._checked = time.monotonic()
        self.own_stalls = 0  # stretches of this process's own standstill left out

    def restart(self) -> None:
        self._since = self._checked = time.monotonic()

    def elapsed(self) -> float:
        now = time.monotonic()
        gap, self._checked = now - self._checked, now
        if gap > OWN_STALL_WALL_S:
            self._since += gap
            self.own_stalls += 1
        return now - self._since


class Upstream(Protocol):
    """Where a :class:`LockstepClock` reports that this process finished a step."""

    def report(self, t_ns: int, wake_ns: int) -> None:
        """Done at simulated time ``t_ns``, next needs ``wake_ns`` [ns]; ``wake_ns < 0``: it leaves."""
        ...


class Downstream(Protocol):
    """Participants in other processes that this clock brings along (a relay)."""

    def run(self, t_ns: int) -> None:
        """Bring the remote participants that are due up to ``t_ns``; block until they are done."""
        ...

    def wake_ns(self) -> int | None:
        """Earliest time [ns] a remote participant needs, or None."""
        ...

    def leave(self) -> None:
        """This clock left the lockstep (closed, or fell back to the wall clock)."""
        ...


@dataclass(eq=False)
class _Ticket:
    """One thread parked on the clock until ``deadline_ns`` or, with ``cond``, a notify.

    A sleeper blocks on its own ``gate`` (a lock the scheduler releases), a condition waiter on
    ``cond``: a grant wakes exactly the thread it is for, never every parked thread."""

    thread: threading.Thread
    order: int
    deadline_ns: int
    cond: threading.Condition | None
    granted: bool = False
    dirty: bool = False  # notified by a participant during this step: runs again in this step
    gate: threading.Lock = field(default_factory=threading.Lock)

    def open(self) -> None:
        """Wake the parked thread (the caller set ``granted`` or fell back)."""
        if self.cond is None:
            if self.gate.locked():
                self.gate.release()
        else:
            with self.cond:
                self.cond.notify_all()


def _say_leaving(upstream: Upstream | None, t_ns: int) -> None:
    """Tell ``upstream`` this process left the lockstep at step ``t_ns`` (closed, or fell back)."""
    if upstream is None:
        return
    try:
        upstream.report(t_ns, -1)
    except Exception as exc:  # noqa: BLE001 - leaving must not fail
        log.debug("lockstep leave not sent: %s", exc)


class LockstepClock:
    """Simulated time owned upstream (the mock vehicle), advanced only in steps this process
    has finished.

    Threads that sleep or wait through this clock are its *participants*. At each barrier
    ``t`` announced by the upstream (:meth:`barrier`), the clock (1) lets the downstream
    relay bring its remote participants to ``t``, (2) runs the local participants that are due
    (deadline reached, or notified) one at a time in the order of their thread names, each until
    it waits on the clock again, and (3) reports ``(t, next wake)`` upstream. Between barriers no
    participant runs, so what they read is the same in every run: the outcome is deterministic.
    I/O threads (receivers, Zenoh callbacks) are not participants: a condition they notify wakes
    its waiters at the next barrier, before or after a waiter parked (what a command's ACK races
    with). The thread that makes the clock runs until it first waits (``creator_runs=False``: a
    test thread that only starts the participants' threads).

    Liveness: if the upstream is silent for ``watchdog_wall_s`` wall seconds while this process
    waits for it (``join_wall_s`` before the first barrier; this process's own stalls left out,
    :class:`Silence`), or on :meth:`close`, the clock falls back to a :class:`ScaledClock` at
    ``speed`` from the current simulated time, releases every participant and tells the upstream
    it left.
    """

    def __init__(self, *, speed: float = 1.0, watchdog_wall_s: float = CONTROLLER_WATCHDOG_WALL_S,
                 join_wall_s: float = 60.0, name: str = "lockstep", creator_runs: bool = True) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed!r}")
        self.speed = float(speed)
        self.watchdog_wall_s, self.join_wall_s, self.name = float(watchdog_wall_s), float(join_wall_s), name
        self.upstream: Upstream | None = None
        self.downstream: Downstream | None = None
        self.barriers = 0
        self.fallback_reason: str | None = None
        self._cv = threading.Condition()
        self._t_ns, self._started = 0, False
        self._tickets: dict[int, _Ticket] = {}
        self._order: dict[int, int] = {}
        me = threading.current_thread()
        self._running: dict[int, threading.Thread] = {me.ident or 0: me} if creator_runs else {}
        self._barrier_ns: int | None = None
        self._notified: set[threading.Condition] = set()  # by I/O threads since the last barrier
        self._done_ns, self._wake_ns = -1, 0
        # when the last report went upstream [s, wall monotonic]; the scheduler is back from a repeat of it
        self._reported_wall_s, self._repeating = 0.0, False
        self._fallback: ScaledClock | None = None
        self._closed = False
        self._silence = Silence()  # the upstream's (guarded by _cv)
        self._thread = threading.Thread(target=self._schedule, name=f"{name}-scheduler", daemon=True)
        self._thread.start()

    # ---- the Clock interface ----------------------------------------------------------------
    def now(self) -> float:
        fallback = self._fallback
        return fallback.now() if fallback is not None else self._t_ns / NS_PER_S

    @property
    def lockstep(self) -> bool:
        """True until the clock fell back to the wall clock."""
        return self._fallback is None

    def sleep(self, duration_s: float) -> None:
        """Sleep ``duration_s`` simulated seconds; ``sleep(0)`` before the first barrier waits for it."""
        fallback = self._fallback
        if fallback is not None:
            fallback.sleep(duration_s)
            return
        deadline_ns = self._t_ns + to_ns(max(duration_s, 0.0))
        ticket = self._park(deadline_ns, None)
        if ticket is None:
            return
        ticket.gate.acquire()  # released by the grant, or by the fall-back
        fallback = self._fallback
        if fallback is not None and not ticket.granted:
            fallback.sleep(deadline_ns / NS_PER_S - fallback.now())

    def wait(self, cond: threading.Condition, timeout_s: float) -> None:
        fallback = self._fallback
        if fallback is not None:
            fallback.wait(cond, timeout_s)
            return
        if timeout_s <= 0:
            return
        deadline_ns = self._t_ns + to_ns(timeout_s) if math.isfinite(timeout_s) else 2**62
        ticket = self._park(deadline_ns, cond)
        if ticket is None:
            return
        while not ticket.granted and self._fallback is None:
            cond.wait()

    def notify(self, cond: threading.Condition) -> None:
        me = threading.get_ident()
        with self._cv:
            if me in self._running:
                for ticket in self._tickets.values():
                    if ticket.cond is cond:
                        ticket.dirty = True
            else:
                self._notified.add(cond)
        cond.notify_all()

    def close(self) -> None:
        """Leave the lockstep: tell the upstream, fall back to the wall clock (idempotent)."""
        with self._cv:
            if self._closed:
                return
            self._closed, joined = True, self._done_ns >= 0
        if joined and self._fallback is None:
            _say_leaving(self.upstream, self._t_ns)
        self._fall_back("closed")

    @property
    def counters(self) -> dict[str, object]:
        """Barriers, fall-back to the wall clock (None: never, or closed), downstream drops and
        rejoins, samples lost; ``held``: every step of the run was in step (barriers, no fall-back,
        no participant dropped)."""
        fallback = None if self.fallback_reason == "closed" else self.fallback_reason
        dropped = int(getattr(self.downstream, "dropped", 0) or 0)
        return {"barriers": self.barriers, "fallback": fallback, "downstream_dropped": dropped,
                "downstream_rejoined": int(getattr(self.downstream, "rejoined", 0) or 0),
                "samples_lost": sum(int(getattr(end, "missed", 0) or 0) for end in (self.upstream, self.downstream)),
                "held": self.barriers > 0 and fallback is None and dropped == 0}

    def start_thread(self, target: Callable[[], None], name: str) -> threading.Thread:
        """Start ``target`` in a daemon thread that takes part from its first instruction: its step
        waits until it waits on this clock (or ends). A plain thread started by a participant runs
        unseen until its first wait, so what it sends before that lands at a load-dependent step."""
        registered = threading.Event()

        def run() -> None:
            me = threading.current_thread()
            with self._cv:
                if self._fallback is None:
                    self._running[me.ident or 0] = me
            registered.set()
            try:
                target()
            finally:
                with self._cv:
                    self._running.pop(me.ident or 0, None)
                    self._cv.notify_all()

        thread = threading.Thread(target=run, name=name, daemon=True)
        thread.start()
        registered.wait()
        return thread

    # ---- upstream events (I/O threads) ------------------------------------------------------
    def advance(self, t_ns: int) -> None:
        """The upstream's time is ``t_ns`` (between barriers: messages that follow were sent then); not
        proof that it still steps with us (one that left goes on in real time): only a barrier is."""
        with self._cv:
            if self._started and t_ns > self._t_ns and not self._running:
                self._t_ns = t_ns

    def keepalive(self) -> None:
        """A downstream participant is slow but alive, and this process waits for it: tell the
        upstream that this step is still being worked on (if it can be told: ``working``)."""
        working = getattr(self.upstream, "working", None)
        if working is not None and self._fallback is None:
            working(self._t_ns)

    def heard(self) -> None:
        """The upstream spoke (a call whose barrier waits for a sample it names): it is not silent."""
        with self._cv:
            self._silence.restart()

    def barrier(self, t_ns: int) -> None:
        """The upstream stopped at ``t_ns`` and waits for this process's report."""
        with self._cv:
            self._silence.restart()
            if self._barrier_ns is None or t_ns > self._barrier_ns:
                self._barrier_ns = t_ns
            self._cv.notify_all()

    # ---- internals --------------------------------------------------------------------------
    def _park(self, deadline_ns: int, cond: threading.Condition | None) -> _Ticket | None:
        thread = threading.current_thread()
        me = thread.ident or 0
        with self._cv:
            if self._fallback is not None or (self._started and cond is None and deadline_ns <= self._t_ns):
                return None
            order = self._order.setdefault(me, len(self._order))
            ticket = _Ticket(thread, order, deadline_ns, cond)
            if cond is None:
                ticket.gate.acquire()  # closed until the grant
            self._tickets[me] = ticket
            self._running.pop(me, None)
            self._cv.notify_all()
        return ticket

    def _fall_back(self, reason: str) -> None:
        with self._cv:
            if self._fallback is not None:
                return
            self._fallback = ScaledClock(self.speed, start_s=self._t_ns / NS_PER_S)
            self.fallback_reason = reason
            tickets = list(self._tickets.values())
            self._tickets.clear()
            self._running.clear()
            self._cv.notify_all()
        if reason != "closed":
            log.warning("%s: %s; time goes on at %gx the wall clock from t = %.3f s", self.name, reason, self.speed,
                        self._t_ns / NS_PER_S)
        if self.downstream is not None:
            self.downstream.leave()
        for ticket in tickets:
            ticket.open()

    def _next_barrier(self) -> int | None:
        """Block until a barrier is due and no participant runs; None once fallen back. The
        upstream's silence counts from its last barrier or this process's last report, whichever
        is later. Every :data:`RESEND_WALL_S` without a barrier it returns the step done, reported
        again (lost, or put before a peer's route was up: docs/lockstep.md), not silence's end."""
        with self._cv:
            if self._started and not self._repeating:
                self._silence.restart()
            self._repeating = False
            while True:
                if self._fallback is not None:
                    return None
                if self._barrier_ns is not None and not self._running:
                    t_ns, self._barrier_ns = self._barrier_ns, None
                    return t_ns
                self._cv.wait(_WALL_SLICE_S)
                silent = self._silence.elapsed()
                limit = self.watchdog_wall_s if self._started else self.join_wall_s
                if self._barrier_ns is None and silent > limit:
                    break
                if (self._done_ns >= 0 and self.upstream is not None and not self._running
                        and time.monotonic() - self._reported_wall_s > RESEND_WALL_S):
                    self._repeating = True
                    return self._done_ns
        self._fall_back(f"upstream silent for {silent:.1f} s (wall)")
        if self._done_ns >= 0:  # the vehicle goes on in real time now, not after its longer watchdog
            _say_leaving(self.upstream, self._t_ns)
        return None

    def _schedule(self) -> None:
        while True:
            t_ns = self._next_barrier()
            if t_ns is None:
                return
            if t_ns < self._done_ns:
                continue
            if t_ns > self._done_ns:
                self._step(t_ns)
            if self._fallback is None and self.upstream is not None:
                try:
                    self.upstream.report(self._done_ns, self._wake_ns)
                except Exception:  # noqa: BLE001 - the next barrier asks again
                    log.exception("%s: report failed", self.name)
                self._reported_wall_s = time.monotonic()

    def _step(self, t_ns: int) -> None:
        with self._cv:
            self._t_ns, self._started = max(self._t_ns, t_ns), True
            self.barriers += 1
        if self.downstream is not None:
            self.downstream.run(t_ns)
        with self._cv:
            notified, self._notified = self._notified, set()
            for ticket in self._tickets.values():
                if ticket.cond is not None and ticket.cond in notified:
                    ticket.dirty = True
        for _ in range(10_000):
            with self._cv:
                while self._running and self._fallback is None:  # started in this step (start_thread): until it waits
                    self._cv.wait(_WALL_SLICE_S)
                due = sorted((k for k in self._tickets.values() if k.deadline_ns <= t_ns or k.dirty),
                             key=lambda k: (k.thread.name, k.order))
            if not due:
                break
            for ticket in due:
                self._run_one(ticket)
                if self._fallback is not None:
                    return
        with self._cv:
            wakes = [k.deadline_ns for k in self._tickets.values()]
        remote = self.downstream.wake_ns() if self.downstream is not None else None
        if remote is not None:
            wakes.append(remote)
        self._wake_ns = min(wakes, default=t_ns + NS_PER_S)
        self._wake_ns = max(self._wake_ns, t_ns + 1)
        self._done_ns = t_ns

    def _run_one(self, ticket: _Ticket) -> None:
        """Hand the step to one parked participant and wait until it parks again or ends."""
        me = ticket.thread.ident or 0
        with self._cv:
            if self._tickets.get(me) is not ticket:
                return
            del self._tickets[me]
            ticket.dirty = False
            self._running[me] = ticket.thread
            ticket.granted = True
        ticket.open()  # (a condition is taken outside the clock's lock: waiters take it first)
        with self._cv:
            while me in self._running and self._fallback is None:
                self._cv.wait(_WALL_SLICE_S)
                if not ticket.thread.is_alive():
                    self._running.pop(me, None)
