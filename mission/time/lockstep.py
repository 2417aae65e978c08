"""Lockstep simulated time over the real transports (the wire side of :class:`~mission.time.clock.LockstepClock`).

The mock vehicle owns simulated time, like PX4 SITL's simulator; the mission controller and the
carrier simulator step on it. Nothing else changes: the controller's code is the same in lockstep
and in real time, only its injected clock differs.

MAVLink, vehicle <-> controller (the vehicle's onboard link):

- ``SYSTEM_TIME`` (time_unix_usec 0, time_boot_ms ``t``) from the vehicle: its time is ``t``;
  the telemetry that follows was sampled then. Sent before each burst between barriers.
- ``TIMESYNC`` request (tc1 0, ts1 ``t`` [ns]) from the vehicle: a *barrier*. The vehicle has
  integrated up to ``t``, sent everything due at ``t`` and will not integrate further until the
  controller answers.
- ``TIMESYNC`` answer (tc1 ``wake`` [ns], ts1 ``t``) from the controller: it has finished step
  ``t`` (its setpoint and commands were sent before, on the same socket, so the vehicle has them)
  and next needs the vehicle at ``wake``; ``wake < 0``: it leaves the lockstep.
  These messages are the simulation's own clock, so the vehicle's link faults (loss, latency,
  blackout) never touch them; every other message suffers the faults in simulated time.

Zenoh, controller <-> carrier simulator (``marsupial/<pair>/clock/...``, reliable, blocking):

- ``clock/time`` ``"t seq"`` from the controller: step to ``t`` [ns] (sent at a barrier when the
  carrier is due, before the controller computes that step) once you have the passenger status
  ``seq`` (the last one the controller published).
- ``clock/ready`` ``"t wake seq"`` from the carrier: done at ``t``, next needs ``wake`` [ns]; its
  last state sample is ``seq``, and the controller waits for that sample before its own step.

Zenoh does not keep the order of samples across keys (measured: a put on one key overtook the
put before it on another in 915 of 2000 tries), so each side waits for the *stamped sample*
(its ``seq``) named in the clock message, not merely for the clock message.

A carrier that drives a lockstep vehicle of its own (the mock PX4 rover, ``carrier.backend =
"mavlink"``) brings it along the same way: its clock relays each step ``t`` to that vehicle
(:class:`MavlinkRelay`: the barrier answer with wake ``t``) and waits for the vehicle's next
barrier, so the carrier computes step ``t`` on the rover's state at ``t``.

One barrier: the vehicle integrates to ``t`` and stops -> the controller relays ``t`` to the
carrier if it is due and waits for its ready -> the controller's threads run their step ->
the controller answers with ``min`` of every wake -> the vehicle integrates to that wake.
A participant silent for a few wall seconds (a killed or hung process) is dropped: the vehicle
goes on in real time at its ``--speed`` after :data:`VEHICLE_WATCHDOG_WALL_S` without an answer
(the controller's silence is then offboard loss, as in PX4); the controller stops waiting for a
carrier after :data:`CARRIER_WATCHDOG_WALL_S` (its silence is then carrier loss) and goes on in
real time after :data:`CONTROLLER_WATCHDOG_WALL_S` without the vehicle (vehicle loss). The
carrier's limit is the shortest, so a lost carrier never makes the vehicle drop the controller.

Slow is not gone. A carrier whose Zenoh liveliness token is present is alive, only slow (a busy
machine: one step took 2.5 s of wall); dropping it would let simulated time run on without it,
so the outcome would depend on the machine's load (a lost carrier in a simulated flight). The
controller waits for such a carrier up to :data:`ALIVE_CARRIER_WATCHDOG_WALL_S` (still below the
vehicle's limit). A killed carrier's token goes at once, and the controller stops waiting then (a
carrier restarted meanwhile has a token of its own but steps on no one's clock).

A Zenoh outage (a router restarted, a link that came back) can lose a message on the clock keys
or a state sample, reliable or not: a call sent as the route came back was lost, the controller
waited for the carrier, and the vehicle dropped the controller (offboard loss in a simulated
flight). So the relay calls again every :data:`RESEND_WALL_S` while unanswered (a carrier that
already finished that step reports it again), and a sample that a clock message names but that
never comes is given up after :data:`LOST_WALL_S` and :data:`LOST_AFTER_REPEATS` repeats of that
message (the relay's ``missed``, the carrier's upstream ``missed``: ``samples_lost`` in the
lockstep counters). A run that lost a sample went on with the sample before it: it is no longer
deterministic, and its summary says so.
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

import zenoh

from mission.bus.bridge import keys, undeclare
from mission.time.clock import LockstepClock
from mission.mavlink.env import mavlink

log = logging.getLogger(__name__)

HELLO_WALL_S = 0.05  # resend period of a call nobody has answered yet [s, wall]
RESEND_WALL_S = 0.5  # resend period of an unanswered call once joined (an outage lost it) [s, wall]
LOST_WALL_S = 2.0  # a named sample still missing this long ... [s, wall]
LOST_AFTER_REPEATS = 3  # ... after this many repeats of the message naming it is given up
CARRIER_WATCHDOG_WALL_S = 2.0  # the controller drops a carrier silent this long [s, wall]
ALIVE_CARRIER_WATCHDOG_WALL_S = 6.0  # ... or this long while its liveliness token is present [s, wall]
CONTROLLER_WATCHDOG_WALL_S = 5.0  # the controller's clock falls back to the wall clock [s, wall]
VEHICLE_WATCHDOG_WALL_S = 10.0  # the vehicle drops a controller silent this long [s, wall]


def clock_keys(pair: str) -> tuple[str, str]:
    """The (time, ready) keys of pair ``pair``."""
    root = keys(pair).carrier_state.rsplit("/", 2)[0]
    return f"{root}/clock/time", f"{root}/clock/ready"


def _publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    # Reliable and blocking: a clock message must never be dropped; express keeps it in order
    # with the (express) state samples of the same session.
    return session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK, express=True)


def _ints(sample: zenoh.Sample, count: int) -> list[int] | None:
    try:
        values = [int(v) for v in sample.payload.to_bytes().decode("ascii").split()]
    except (UnicodeDecodeError, ValueError):
        return None
    return values if len(values) == count else None


class MavlinkUpstream:
    """The controller's side of the vehicle's clock: reads SYSTEM_TIME / TIMESYNC from ``link``
    and answers the barriers. ``link`` is a :class:`mission.mavlink.link.VehicleLink`."""

    def __init__(self, clock: LockstepClock, link: Any) -> None:
        self.clock, self.link = clock, link
        link.add_listener(self._on_message)
        clock.upstream = self

    def _on_message(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "SYSTEM_TIME":
            self.clock.advance(int(msg.time_boot_ms) * 1_000_000)
        elif kind == "TIMESYNC" and msg.tc1 == 0:
            self.clock.barrier(int(msg.ts1))

    def report(self, t_ns: int, wake_ns: int) -> None:
        self.link.send_message(mavlink.MAVLink_timesync_message(wake_ns, t_ns))


class MavlinkRelay:
    """A process brings its own lockstep vehicle on ``link`` along (a :class:`~mission.time.clock.Downstream`):
    at each step ``t`` it answers the vehicle's barrier with wake ``t`` and waits until the
    vehicle stopped at its next barrier (at or after ``t``: it integrates whole physics steps),
    its telemetry up to then received ahead of that barrier on the same socket.

    The vehicle is dropped after ``watchdog_wall_s`` without progress (``join_wall_s`` before it
    first answered); it then goes on in real time after its own watchdog, and the state it
    stops sending is what the carrier's own-state watchdog is for. ``link`` is a
    :class:`mission.mavlink.link.VehicleLink`."""

    def __init__(self, link: Any, *, watchdog_wall_s: float = CARRIER_WATCHDOG_WALL_S, join_wall_s: float = 30.0) -> None:
        self.link, self.watchdog_wall_s, self.join_wall_s = link, watchdog_wall_s, join_wall_s
        self._cv = threading.Condition()
        self._at_ns: int | None = None  # the barrier the vehicle waits at
        self._joined = False
        self.dropped = False  # it fell silent
        self.left = False  # we left the lockstep
        link.add_listener(self._on_message)

    def _on_message(self, msg: Any) -> None:
        if msg.get_type() == "TIMESYNC" and msg.tc1 == 0:
            with self._cv:
                self._at_ns = max(self._at_ns if self._at_ns is not None else -1, int(msg.ts1))
                self._cv.notify_all()

    def wake_ns(self) -> int | None:
        return None  # the vehicle needs no step of its own: it is brought to each of ours

    def run(self, t_ns: int) -> None:
        if self.dropped or self.left:
            return
        limit = self.watchdog_wall_s if self._joined else self.join_wall_s
        start, answered = time.monotonic(), None
        with self._cv:
            while self._at_ns is None or self._at_ns < t_ns:
                if self._at_ns is not None and self._at_ns != answered:
                    answered = self._at_ns
                    self._cv.release()
                    try:
                        self.link.send_message(mavlink.MAVLink_timesync_message(t_ns, answered))
                    finally:
                        self._cv.acquire()
                if time.monotonic() - start > limit:
                    self.dropped = True
                    log.warning("lockstep: the vehicle did not reach t = %.3f s within %.1f s (wall); going on "
                                "without it", t_ns / 1e9, limit)
                    return
                self._cv.wait(HELLO_WALL_S)
            self._joined = True

    def leave(self) -> None:
        """Let the vehicle go on in real time now (this process left the lockstep)."""
        with self._cv:
            at = self._at_ns
        if at is not None and not (self.dropped or self.left):
            self.left = True
            try:
                self.link.send_message(mavlink.MAVLink_timesync_message(-1, at))
            except Exception as exc:  # noqa: BLE001 - leaving must not fail
                log.debug("lockstep leave to the vehicle not sent: %s", exc)


class ZenohRelay:
    """The controller brings the pair's carrier simulator along (a :class:`~mission.time.clock.Downstream`),
    on the ``keys`` (time, ready) of :func:`clock_keys`; ``feed`` calls back with each sample it
    receives (``.seq``), ``publisher.last_seq`` is the seq of the last sample sent. The same relay
    brings a ROS-2-shaped robot along for the ros2 carrier (``name`` "robot", keys
    :func:`mission.carrier.backends.ros2.robot_clock_keys`, rmw_zenoh sequence numbers).

    Before the first barrier completes it calls the carrier every :data:`HELLO_WALL_S` until it
    answers (for at most ``join_wall_s``); later it waits ``watchdog_wall_s`` at most, or
    ``alive_watchdog_wall_s`` while ``alive()`` (the carrier's liveliness token) is True, and not at
    all once it is False; then it drops the carrier until it answers again (a restarted carrier
    rejoins at a later barrier). Once joined it calls again every :data:`RESEND_WALL_S` while
    unanswered, and gives up a state sample a ready names after :data:`LOST_WALL_S` and
    :data:`LOST_AFTER_REPEATS` readies naming it. :attr:`dropped` counts the drops,
    :attr:`missed` the samples given up.
    """

    def __init__(self, session: zenoh.Session, keys: tuple[str, str], feed: Any, publisher: Any, *,
                 alive: Callable[[], bool | None] | None = None,
                 watchdog_wall_s: float = CARRIER_WATCHDOG_WALL_S,
                 alive_watchdog_wall_s: float = ALIVE_CARRIER_WATCHDOG_WALL_S,
                 join_wall_s: float = 30.0, name: str = "carrier") -> None:
        time_key, ready_key = keys
        self.watchdog_wall_s, self.join_wall_s, self.name = watchdog_wall_s, join_wall_s, name
        self.alive_watchdog_wall_s = max(alive_watchdog_wall_s, watchdog_wall_s)
        self._alive = alive
        self._publisher = publisher  # PassengerPublisher: last_seq
        self._cv = threading.Condition()
        self._ready: tuple[int, int, int] | None = None
        self._seen_seq = -1  # newest carrier state seq received
        self._state = "joining"  # -> joined -> dropped -> joined ...
        self._wake_ns = 0
        self._step_ns, self._step_readies = 0, 0  # the step run() waits for, readies for it so far
        self.dropped = 0
        self.missed = 0  # state samples given up (lost in an outage)
        self._pub = _publisher(session, time_key)
        self._sub = session.declare_subscriber(ready_key, self._on_ready)
        feed.add_listener(self._on_state)

    def _on_state(self, state: Any) -> None:
        with self._cv:
            self._seen_seq = max(self._seen_seq, int(state.seq))
            self._cv.notify_all()

    def _on_ready(self, sample: zenoh.Sample) -> None:
        values = _ints(sample, 3)
        if values is None:
            log.warning("lockstep: malformed ready on %s dropped", sample.key_expr)
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
                log.warning("lockstep: the %s is back (ready at t = %.3f s)", self.name, values[0] / 1e9)
            self._cv.notify_all()

    def wake_ns(self) -> int | None:
        with self._cv:
            return self._wake_ns if self._state == "joined" else None

    def leave(self) -> None:
        """Nothing to send: the carrier notices a silent clock itself (its watchdog)."""

    def run(self, t_ns: int) -> None:
        with self._cv:
            state, wake = self._state, self._wake_ns
        call = f"{t_ns} {self._publisher.last_seq}"
        if state == "dropped":
            self._pub.put(call)  # lets a restarted carrier find the clock
            return
        if state == "joined" and wake > t_ns:
            return
        start = last_put = time.monotonic()
        slow_logged = False
        with self._cv:
            self._step_ns, self._step_readies = t_ns, 0
        self._pub.put(call)
        with self._cv:
            while not (self._ready is not None and self._ready[0] >= t_ns and self._seen_seq >= self._ready[2]):
                now = time.monotonic()
                if (self._ready is not None and self._ready[0] >= t_ns and now - start > LOST_WALL_S
                        and self._step_readies >= LOST_AFTER_REPEATS):
                    self.missed += 1
                    log.warning("lockstep: the %s's state sample %d never came (step t = %.3f s, %d readies in "
                                "%.1f s, wall); going on without it", self.name, self._ready[2], t_ns / 1e9,
                                self._step_readies, now - start)
                    break
                token = None if self._alive is None or state == "joining" else self._alive()
                limit = self.join_wall_s if state == "joining" else (
                    self.alive_watchdog_wall_s if token else self.watchdog_wall_s)
                if token is False or now - start > limit:
                    self._state = "dropped"
                    self.dropped += 1
                    why = "its liveliness token is gone" if token is False else f"no answer within {limit:.1f} s (wall)"
                    log.warning("lockstep: the %s dropped at step t = %.3f s (%s); going on without it", self.name,
                                t_ns / 1e9, why)
                    return
                if token and not slow_logged and now - start > self.watchdog_wall_s:
                    slow_logged = True
                    log.warning("lockstep: the %s has not finished step t = %.3f s after %.1f s (wall), but its "
                                "liveliness token is present: waiting up to %.1f s", self.name, t_ns / 1e9,
                                now - start, limit)
                if now - last_put > (HELLO_WALL_S if self._state == "joining" else RESEND_WALL_S):
                    self._cv.release()
                    try:
                        self._pub.put(call)
                    finally:
                        self._cv.acquire()
                    last_put = now
                self._cv.wait(HELLO_WALL_S)
            self._state, self._wake_ns = "joined", self._ready[1]

    def close(self) -> None:
        undeclare(self._sub, self._pub)


class ZenohUpstream:
    """The carrier simulator's side: steps on ``clock/time`` once the passenger status it names
    has arrived on ``feed`` (a PassengerFeed: callbacks with ``.seq``), answers on ``clock/ready``
    with the seq of its last state sample (``published()``). ``keys``: (time, ready) of
    :func:`clock_keys` (the ROS-2-shaped robot steps on the ros2 carrier's the same way).

    A status that never comes (lost in an outage) is given up after :data:`LOST_WALL_S` and
    :data:`LOST_AFTER_REPEATS` repeated calls naming it (:attr:`missed`); a repeated call for a
    step already taken is passed on at once (the clock reports that step again)."""

    def __init__(self, clock: LockstepClock, session: zenoh.Session, keys: tuple[str, str], feed: Any,
                 published: Callable[[], int]) -> None:
        time_key, ready_key = keys
        self.clock, self._published = clock, published
        self._lock = threading.Lock()
        self._seen_seq = -1  # newest passenger status seq received
        self._pending: tuple[int, int] | None = None  # (t, status seq) waiting for that status
        self._pending_since, self._pending_calls = 0.0, 0  # wall time of its first call [s], calls since
        self._stepped_ns = -1  # the latest step passed to the clock
        self.missed = 0  # passenger statuses given up (lost in an outage)
        self._pub = _publisher(session, ready_key)
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
        values = _ints(sample, 2)
        if values is None:
            log.warning("lockstep: malformed time on %s dropped", sample.key_expr)
            return
        t_ns, seq = values
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
        self._pub.put(f"{t_ns} {wake_ns} {self._published()}")

    def close(self) -> None:
        undeclare(self._sub, self._pub)
