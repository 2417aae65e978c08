"""The mock vehicle's deck follows a pair's carrier over Zenoh (``mock-vehicle --deck PAIR``).

The deck moves with the carrier's newest state (its Zenoh state through the vehicle's origin, or
with ``--deck-truth`` the carrier's sim-only truth, :func:`sim.robots.truth.truth_key`), moved on
from the state's stamp by its velocity.

**In lockstep the deck steps on the carrier's step.** The carrier steps only at the vehicle's
barriers, so when the vehicle integrates past barrier ``t`` the carrier has published every state
of its steps up to ``t``, but Zenoh may still be delivering the newest. Taking whatever has
arrived made a seated vehicle's position and velocity depend on the wall clock while the carrier
changed speed (docs/lockstep.md). :class:`StepAligned` waits instead, before each physics step,
until the deck's newest state is the one of the carrier's newest step at or before the vehicle's
barrier. It reads which step that is from the carrier's own ``clock/ready`` messages (``"t wake
seq"``, :mod:`mission.bus.lockstep`): the newest ready with ``wake`` after the barrier names the
step; its state is the one with ``seq`` (the state feed) or stamped at its ``t`` (the truth, which
the carrier stamps with its step time). A carrier that is not in the lockstep (no ready heard) is
followed as it arrives. A wait longer than :data:`WAIT_WALL_S` of wall time is given up (counted,
the run is no longer deterministic; a state given up is not waited for again), and after
:data:`GIVE_UP_AFTER` give-ups in a row the deck follows arrivals for the rest of the run (a
backend whose states are not stamped with its step).

In lockstep the deck takes the newest valid state heard (:meth:`StepAligned.newest`), not the
carrier feed's gate's: the gate binds a source after three plausible states in a row and unbinds
it when the carrier's liveliness token goes, at wall-clock moments (two runs' decks were first
known at 0.075 and 0.44 s, no step given up). The world follows the carrier's every step.

**The deck is first known at the vehicle's first pass.** The lockstep carrier joins at the
controller's first barrier (t = 0: the controller calls it until it answers before it answers the
vehicle), so its first ready and state precede the vehicle's first integration. The first pass
waits for them as for any step; before, nothing was waited for until the first state *arrived*,
so the deck (its first touchdown, the camera's first frame) became known at 0.075 s in one run
and 0.14 s in another. A carrier that never sends a ready (not in the lockstep) costs one give-up
at the first pass (counted) and is then followed as it arrives; a first state lost before Zenoh's
route to this subscriber was up is given up as any other (counted).

The ready messages are read, not verified: the mock is the world, not a party to the pair's bus
authentication; a forged ready can only make the deck wait (bounded).
"""
from __future__ import annotations

import logging
import math
import threading
from typing import Any

import numpy as np
import zenoh

from mission.bus.bridge import CarrierFeed, undeclare
from mission.bus.lockstep import clock_keys
from mission.bus.wire import CarrierState, GeoOrigin
from sim.camera.publisher import BodyTruth, CameraPublisher, DeckTruth
from sim.robots.truth import TruthTrack, truth_key
from sim.vehicle.mock import MockVehicle
from sim.vehicle.physics.deck import DeckMotion
from sim.vehicle.physics.multicopter import attitude_quaternion

log = logging.getLogger(__name__)

# The longest wall-clock wait for the carrier's step before the deck goes on without it [s]. The
# controller's and the carrier's clocks wait for this vehicle's next barrier meanwhile, 5 s at most
# (mission.time.clock.CONTROLLER_WATCHDOG_WALL_S): an equal wait lost the race by 5 ms on a loaded
# machine, the carrier fell back to its wall clock, and the pair's run was no longer lockstep.
WAIT_WALL_S = 3.0
# (1 s was given up once in a full suite run at load 7: the state came, late; in lockstep the carrier's
# states are sent with congestion control BLOCK, so a wait this long is a loaded machine or a lost route)
GIVE_UP_AFTER = 3  # give-ups in a row after which the deck follows arrivals for the rest of the run
STAMP_SLACK_S = 1e-6  # a state stamped this close to its step's time is that step's [s]


class VehicleClock:
    """The vehicle's clock as it is now (it changes once a lockstep vehicle is left alone), for a
    carrier feed that stamps what it receives on the vehicle's time."""

    def __init__(self, vehicle: MockVehicle) -> None:
        self.vehicle = vehicle

    @property
    def speed(self) -> float:
        return self.vehicle.clock.speed

    @property
    def counters(self) -> dict[str, object] | None:
        return None

    def now(self) -> float:
        return self.vehicle.clock.now()

    def sleep(self, duration_s: float) -> None:
        self.vehicle.clock.sleep(duration_s)

    def wait(self, cond: threading.Condition, timeout_s: float) -> None:
        self.vehicle.clock.wait(cond, timeout_s)

    def notify(self, cond: threading.Condition) -> None:
        self.vehicle.clock.notify(cond)

    def close(self) -> None:
        pass


class StepAligned:
    """Waits until ``feed``'s newest state is the carrier's step at or before a barrier (module
    docstring). ``by_seq``: the step's state is named by its sequence number (the carrier's
    published state), else by its stamp (its truth). :attr:`counters`: ``waits`` (barriers that
    waited for a state or a ready), ``given_up`` and ``aligned`` (False once it follows arrivals)."""

    def __init__(self, session: zenoh.Session, pair: str, feed: CarrierFeed, by_seq: bool) -> None:
        self._feed, self._by_seq = feed, by_seq
        self._cv = threading.Condition()
        self._ready: tuple[int, int, int] | None = None  # the newest (t [ns], wake [ns], seq)
        self._done_ns: int | None = None  # the barrier whose step the deck already has
        self._in_a_row = 0
        self._seen_seq, self._seen_stamp_s = 0, -math.inf  # the newest valid state heard
        self._newest: tuple[CarrierState, float] | None = None  # it, and its receive time on the feed's clock [s]
        self._given_up: tuple[int, int, int] | None = None  # the ready whose state never came
        self.counters = {"waits": 0, "given_up": 0, "aligned": True}
        feed.add_listener(self._on_state)
        self._sub = session.declare_subscriber(clock_keys(pair)[1], self._on_ready)

    def _on_state(self, state: CarrierState) -> None:
        rx = self._feed.clock.now()
        with self._cv:  # every valid sample, whether the feed's gate took it yet or not (as the relay counts)
            newer = self._newest is None or (int(state.seq) > self._seen_seq if self._by_seq
                                              else float(state.stamp_s) > self._seen_stamp_s)
            if newer:
                self._newest = (state, rx)
            self._seen_seq = max(self._seen_seq, int(state.seq))
            self._seen_stamp_s = max(self._seen_stamp_s, float(state.stamp_s))
            self._cv.notify_all()

    def newest(self) -> tuple[CarrierState, float] | None:
        """The newest valid state heard (by ``seq``, or by stamp for the truth) and its receive time
        [s], or None. Not the feed's gate's newest: the gate binds a source after three plausible
        states in a row and unbinds it when its liveliness token goes, both at wall-clock moments
        (two lockstep runs' decks were first known at 0.075 and 0.44 s with no step given up); the
        world follows the carrier's every step."""
        with self._cv:
            return self._newest

    def _on_ready(self, sample: zenoh.Sample) -> None:
        try:
            values = [int(v) for v in sample.payload.to_bytes().decode("ascii").split()]
        except (UnicodeDecodeError, ValueError):
            return
        if len(values) != 3:
            return
        with self._cv:
            if self._ready is None or values[0] >= self._ready[0]:
                self._ready = (values[0], values[1], values[2])
            self._cv.notify_all()

    def _has_step(self, barrier_ns: int) -> bool:
        """Lock held: the deck's newest state is the carrier's newest step at or before ``barrier_ns``
        (or the carrier is not stepping with us: nothing to wait for)."""
        ready = self._ready
        if ready is None:  # the carrier's first step comes before the first pass; none after a give-up: not in the lockstep
            return self.counters["given_up"] > 0
        if ready[1] < 0:
            return True
        if ready[1] <= barrier_ns:  # it stepped again at or before the barrier: that ready is still to come
            return False
        if ready == self._given_up:
            return True  # its state was waited for once and never came
        if self._by_seq:
            return self._seen_seq >= ready[2]
        return self._seen_stamp_s >= ready[0] / 1e9 - STAMP_SLACK_S

    def wait(self, barrier_ns: int | None) -> None:
        """Before a physics step after barrier ``barrier_ns`` [ns] (None: no barrier yet): return
        once the deck has the carrier's step of that barrier, or after :data:`WAIT_WALL_S`."""
        if barrier_ns is None or barrier_ns < 0 or barrier_ns == self._done_ns or not self.counters["aligned"]:
            return
        with self._cv:
            if not self._has_step(barrier_ns):
                self.counters["waits"] += 1
                if not self._cv.wait_for(lambda: self._has_step(barrier_ns), WAIT_WALL_S):
                    self._give_up(barrier_ns)
                    return
            had = self._given_up is None or self._ready != self._given_up  # else: a state given up before
            self._done_ns = barrier_ns
            if had:
                self._in_a_row = 0

    def _give_up(self, barrier_ns: int) -> None:
        """Lock held."""
        self.counters["given_up"] += 1
        self._in_a_row += 1
        self._done_ns, self._given_up = barrier_ns, self._ready
        first = self.counters["given_up"] == 1
        newest = self._feed.newest()
        have = "none" if newest is None else f"seq {newest[0].seq} stamped {newest[0].stamp_s:.3f} s"
        (log.warning if first else log.debug)(
            "deck: the carrier's step at or before t = %.3f s did not arrive within %.1f s (wall): its last ready "
            "%s, the deck's newest state %s; the deck goes on with it (the run is no longer deterministic)",
            barrier_ns / 1e9, WAIT_WALL_S, self._ready, have)
        if self._in_a_row >= GIVE_UP_AFTER:
            self.counters["aligned"] = False
            log.warning("deck: %d steps in a row not heard in time; the deck follows the carrier's states as they "
                        "arrive from now on", GIVE_UP_AFTER)

    def close(self) -> None:
        undeclare(self._sub)


class DeckFeed:
    """What :func:`follow_carrier` starts: the carrier feed and, in lockstep, its step alignment."""

    def __init__(self, feed: CarrierFeed, aligned: StepAligned | None) -> None:
        self.feed, self.aligned = feed, aligned

    def close(self) -> None:
        if self.aligned is not None:
            self.aligned.close()
        self.feed.close()


def follow_carrier(vehicle: MockVehicle, session: Any, pair: str, truth: bool = False,
                   track: TruthTrack | None = None, camera: CameraPublisher | None = None) -> DeckFeed:
    """Give ``vehicle``'s deck the motion of pair ``pair``'s carrier from its Zenoh state (a wgs84
    state through the vehicle's origin), or with ``truth`` from the carrier's sim-only true state
    (:func:`sim.robots.truth.truth_key`); ``track`` samples the truth at every pass, ``camera``
    renders its frames from it; returns the feed (close it before the session)."""
    key = truth_key(pair) if truth else None
    feed = CarrierFeed(session, pair, VehicleClock(vehicle), key=key, origin=GeoOrigin(*vehicle.options.home),
                       max_age_s=math.inf)
    lockstep = vehicle.options.lockstep
    aligned = StepAligned(session, pair, feed, by_seq=not truth) if lockstep else None
    heard: list[bool] = []
    made: list[tuple[CarrierState, float, DeckMotion]] = []  # the last sample's motion (asked for at every pass)

    def motion() -> DeckMotion | None:
        if aligned is not None:
            stepper = vehicle._lockstep
            aligned.wait(None if stepper is None else stepper.barrier_ns)
        got = motion_now()
        if track is not None:
            track.sample(vehicle, got)
        if camera is not None:  # every slot of its grid, a time mark while the deck is not known
            t, kin = float(vehicle._t_s), vehicle._kin
            body = BodyTruth(np.array([kin.n_m, kin.e_m, kin.d_m]), np.array(attitude_quaternion(kin)),
                             np.array([kin.vn_m_s, kin.ve_m_s, kin.vd_m_s]))
            camera.sample(t, body, None if got is None else DeckTruth(
                np.asarray(got.centre(t, 0.0)), np.asarray(got.velocity_ned_m_s), made[0][0].yaw_rad))
        return got

    def motion_now() -> DeckMotion | None:
        got = feed.newest() if aligned is None else aligned.newest()
        if got is None:
            return None
        value, rx_s = got
        if made and made[0][0] is value and made[0][1] == rx_s:
            return made[0][2]
        if not heard:
            heard.append(True)
            log.info("deck: pair %s's carrier heard at %s m NED", pair, [round(float(c), 2) for c in value.position])
        # In lockstep the carrier and the vehicle step on one simulated time: the deck moves on from
        # the sample's own stamp, not from when it arrived (a sample delivered late on a loaded
        # machine would put the deck back by speed x delay). On wall clocks the two processes'
        # clocks may be apart by more than the transport's delay: from its arrival.
        stamp = value.stamp_s
        t_s = stamp if lockstep and abs(stamp - rx_s) <= 1.0 else rx_s
        new = DeckMotion(tuple(value.position), tuple(value.velocity_ned_m_s), t_s)  # type: ignore[arg-type]
        made[:] = [(value, rx_s, new)]
        return new

    vehicle.follow_deck(motion)
    return DeckFeed(feed, aligned)
