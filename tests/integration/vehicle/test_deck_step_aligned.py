"""The lockstep deck steps on the carrier's step (sim/robots/deck_follow.py, ``StepAligned``),
over real Zenoh on loopback: after a barrier the deck waits until it has the state of the
carrier's newest step at or before it, as the carrier's ``clock/ready`` names it (by sequence
number for its published state, by stamp for its truth), and not longer than its wall bound.

Before, the deck took whatever state had arrived, and two lockstep runs of ``configs/cycle.toml``
parted at t = 14.6 s, while the carrier braked (docs/lockstep.md)."""
from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest

from mission.bus.bridge import CarrierFeed, CarrierPublisher
from mission.bus.lockstep import clock_keys
from mission.bus.wire import CarrierState
from mission.time.clock import ManualClock
from sim.robots import deck_follow
from sim.robots.deck_follow import StepAligned
from tests.support.zenoh_util import LENIENT, peer_pair, wait_for

pytestmark = pytest.mark.timeout(60)

MS = 1_000_000  # [ns]


class Carrier:
    """The carrier's side: its state (or truth) and its ready messages."""

    def __init__(self, session, pair: str, key: str | None = None) -> None:
        self.session, self.ready_key = session, clock_keys(pair)[1]
        self.states = CarrierPublisher(session, pair) if key is None else None
        self.truth = session.declare_publisher(key) if key is not None else None

    def state(self, seq: int, t_s: float) -> None:
        state = CarrierState(stamp_s=t_s, seq=seq, frame="local_ned", position=(t_s, 0.0, 0.0),
                             velocity_ned_m_s=(1.0, 0.0, 0.0))
        if self.states is not None:
            self.states.publish(state)
        else:
            from mission.bus.encodings import encode_carrier
            self.truth.put(encode_carrier(state, "json"))

    def ready(self, t_ns: int, wake_ns: int, seq: int) -> None:
        self.session.put(self.ready_key, f"{t_ns} {wake_ns} {seq}".encode())

    def close(self) -> None:
        if self.states is not None:
            self.states.close()
        if self.truth is not None:
            self.truth.undeclare()


@pytest.fixture
def sides() -> Iterator[tuple[Carrier, CarrierFeed, StepAligned]]:
    with peer_pair() as (carrier_side, vehicle_side):
        carrier = Carrier(carrier_side, "step0")
        feed = CarrierFeed(vehicle_side, "step0", ManualClock(), max_age_s=1e9, limits=LENIENT)
        aligned = StepAligned(vehicle_side, "step0", feed, by_seq=True)
        try:
            yield carrier, feed, aligned
        finally:
            aligned.close()
            feed.close()
            carrier.close()


def connect(carrier: Carrier, feed: CarrierFeed | None, aligned: StepAligned) -> None:
    """The carrier's step 0 (state 1, ready ``0 40 ms 1``), put again until the vehicle's side has both
    (a put before the route is up is lost)."""
    def heard() -> bool:
        carrier.state(1, 0.0)  # the same sequence number again is dropped as a repeat
        carrier.ready(0, 40 * MS, 1)
        return aligned.newest() is not None and aligned._ready is not None
    wait_for(heard, 10.0, "the carrier's first state and ready")


def waiting(aligned: StepAligned, barrier_ns: int) -> tuple[threading.Thread, threading.Event]:
    done = threading.Event()

    def run() -> None:
        aligned.wait(barrier_ns)
        done.set()
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, done


def test_the_deck_waits_for_the_state_the_ready_names(sides):
    carrier, feed, aligned = sides
    connect(carrier, feed, aligned)
    aligned.wait(0)  # has it: no wait
    assert aligned.counters["waits"] == 0
    carrier.ready(40 * MS, 80 * MS, 2)  # the carrier stepped at 40 ms; its state 2 is still on the way
    wait_for(lambda: aligned._ready is not None and aligned._ready[0] == 40 * MS, 10.0, "the ready")
    thread, done = waiting(aligned, 60 * MS)
    assert not done.wait(0.3), "returned before the state the ready names"
    carrier.state(2, 0.04)
    thread.join(10.0)
    assert done.is_set() and feed.newest()[0].seq == 2
    assert aligned.counters == {"waits": 1, "given_up": 0, "aligned": True}


def test_a_ready_that_wakes_before_the_barrier_means_a_newer_step_to_wait_for(sides):
    carrier, feed, aligned = sides
    connect(carrier, feed, aligned)
    thread, done = waiting(aligned, 40 * MS)  # it wakes at 40 ms: its step of 40 ms is still to come
    assert not done.wait(0.3), "returned without the carrier's step at the barrier"
    carrier.state(2, 0.04)
    carrier.ready(40 * MS, 80 * MS, 2)
    thread.join(10.0)
    assert done.is_set() and feed.newest()[0].seq == 2


def test_no_carrier_in_the_lockstep_one_give_up_at_the_first_pass_then_no_wait(sides, monkeypatch):
    """The lockstep carrier's first ready precedes the vehicle's first pass, so the first pass waits
    for it; a carrier that sends none (on its own clock) is given up there once, then never waited for."""
    monkeypatch.setattr(deck_follow, "WAIT_WALL_S", 0.1)
    _carrier, _feed, aligned = sides
    aligned.wait(0)
    assert aligned.counters == {"waits": 1, "given_up": 1, "aligned": True}
    aligned.wait(20 * MS)
    aligned.wait(40 * MS)
    assert aligned.counters == {"waits": 1, "given_up": 1, "aligned": True}


def test_a_step_that_never_comes_is_given_up_once_and_three_in_a_row_end_the_alignment(sides, monkeypatch):
    monkeypatch.setattr(deck_follow, "WAIT_WALL_S", 0.1)
    carrier, feed, aligned = sides
    connect(carrier, feed, aligned)
    carrier.ready(20 * MS, 60 * MS, 7)  # names a state that is never published
    wait_for(lambda: aligned._ready[0] == 20 * MS, 10.0, "the ready")
    aligned.wait(20 * MS)
    aligned.wait(40 * MS)  # the same step's state: given up already, not waited for again
    assert aligned.counters == {"waits": 1, "given_up": 1, "aligned": True}
    for k in (3, 4):  # two more steps whose states never come: three give-ups in a row
        carrier.ready(k * 20 * MS, (k + 2) * 20 * MS, 6 + k)
        wait_for(lambda k=k: aligned._ready[0] == k * 20 * MS, 10.0, "the ready")
        aligned.wait(k * 20 * MS)
    assert aligned.counters == {"waits": 3, "given_up": 3, "aligned": False}
    aligned.wait(100 * MS)  # no longer waits
    assert aligned.counters["waits"] == 3


def test_the_first_pass_waits_for_the_carrier_s_first_ready_and_state(sides, monkeypatch):
    """The deck is first known at the vehicle's first pass, not at whichever pass the carrier's first
    state happened to arrive by (two relnav demos put it at 0.075 and 0.14 s, and the camera's frames
    with it): the first barrier waits for the first ready, then for the state it names."""
    monkeypatch.setattr(deck_follow, "WAIT_WALL_S", 10.0)  # the wall bound is not what is tested here
    carrier, feed, aligned = sides
    thread, done = waiting(aligned, 0)
    assert not done.wait(0.3), "returned before the carrier's first ready"
    wait_for(lambda: carrier.ready(0, 40 * MS, 1) or aligned._ready is not None, 10.0, "the ready")
    assert not done.wait(0.3), "returned before the state the first ready names"
    wait_for(lambda: carrier.state(1, 0.0) or feed.newest() is not None, 10.0, "the first state")
    thread.join(10.0)
    assert done.is_set() and feed.newest()[0].seq == 1
    assert aligned.counters == {"waits": 1, "given_up": 0, "aligned": True}


def test_the_truth_is_named_by_its_stamp():
    from sim.robots.truth import truth_key

    with peer_pair() as (carrier_side, vehicle_side):
        carrier = Carrier(carrier_side, "step1", key=truth_key("step1"))
        feed = CarrierFeed(vehicle_side, "step1", ManualClock(), key=truth_key("step1"), max_age_s=1e9,
                           limits=LENIENT)
        aligned = StepAligned(vehicle_side, "step1", feed, by_seq=False)
        try:
            def heard() -> bool:
                carrier.state(1, 0.0)
                return feed.newest() is not None
            wait_for(heard, 10.0, "the first truth")
            # the seq is the published state's, not the truth's
            wait_for(lambda: carrier.ready(40 * MS, 80 * MS, 99) or aligned._ready is not None, 10.0, "the ready")
            thread, done = waiting(aligned, 60 * MS)
            assert not done.wait(0.3), "returned before the truth of the step"
            carrier.state(2, 0.04)
            thread.join(10.0)
            assert done.is_set() and feed.newest()[0].stamp_s == pytest.approx(0.04)
        finally:
            aligned.close()
            feed.close()
            carrier.close()


def test_the_deck_takes_the_newest_state_heard_not_the_gate_s():
    """The feed's gate binds the carrier only after three plausible states in a row (and unbinds it
    when its liveliness token goes), at wall-clock moments; the lockstep deck follows every valid
    state heard, so it is known from the carrier's first step."""
    with peer_pair() as (carrier_side, vehicle_side):
        carrier = Carrier(carrier_side, "step2")
        feed = CarrierFeed(vehicle_side, "step2", ManualClock(), max_age_s=1e9)  # the default gate: binds at 3
        aligned = StepAligned(vehicle_side, "step2", feed, by_seq=True)
        try:
            connect(carrier, feed=None, aligned=aligned)
            aligned.wait(0)
            assert feed.newest() is None  # unbound: one state of three
            state, _ = aligned.newest()
            assert state.seq == 1 and state.position[0] == 0.0
        finally:
            aligned.close()
            feed.close()
            carrier.close()
