"""Lockstep over real Zenoh sessions on loopback, against a busy machine.

The controller's relay to the carrier (:class:`mission.bus.lockstep.ZenohRelay`): a slow carrier whose
liveliness token is present is waited for, so a busy machine cannot change a simulated flight; a
silent one whose token is gone is dropped at once, one with no token known after the short
watchdog, so a dead carrier is carrier loss. The state streams never drop a sample in lockstep.

The scripted carrier answers the relay's clock calls on its own session; its state samples reach
the relay through a stand-in feed (the carrier feed itself has its own tests)."""
from __future__ import annotations

import logging
import threading
import time
from types import SimpleNamespace

import pytest
import zenoh

from mission.carrier.controller import CarrierController
from mission.carrier.backends.sim import SimRobot
from mission.bus.bridge import open_session
from mission.time.clock import LOST_AFTER_REPEATS, LockstepClock, ScaledClock
from mission.config.schema import load_config, with_overrides
from mission.bus import lockstep
from mission.bus.lockstep import LOST_WALL_S, RESEND_WALL_S, ZenohRelay, ZenohUpstream, clock_keys
from mission.cli.run import mission_io
from tests.conftest import CONFIGS
from tests.support.zenoh_util import peer_pair

WATCHDOG_S = 0.3  # the relay's short limit in these tests [s, wall]
SLOW_S = 1.0  # the slow step's answer comes this late [s, wall]: beyond WATCHDOG_S
WAKE_NS = 33_333_333  # the carrier's next wake after each step [ns]


class _StateFeed:
    """The carrier feed as the relay sees it: listeners called with each state sample (``.seq``)."""

    def __init__(self) -> None:
        self.listeners: list = []

    def add_listener(self, callback) -> None:
        self.listeners.append(callback)

    def deliver(self, seq: int) -> None:
        for callback in self.listeners:
            callback(SimpleNamespace(seq=seq))


class _ScriptedCarrier:
    """Answers each clock call ``"t seq"``: publishes a state sample, then ``"t wake seq"``; a
    repeated call for a step it answered gets the same ready again (as a carrier's clock does).
    The calls at ``slow_at_ns`` are answered ``SLOW_S`` late (wall). ``lose`` (what, t): the
    outage loses the first call at ``t``, its first ready, or its state sample."""

    def __init__(self, session, keys: tuple[str, str], feed: _StateFeed, slow_at_ns: int = -1,
                 lose: tuple[str, int] | None = None) -> None:
        self.feed, self.slow_at_ns, self.seq, self.lose = feed, slow_at_ns, -1, lose
        self.answered: list[int] = []
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()
        self._closed = False
        self._ready = session.declare_publisher(keys[1])
        self._sub = session.declare_subscriber(keys[0], self._on_call)

    def _on_call(self, sample) -> None:
        t_ns = int(sample.payload.to_bytes().decode().split()[0])
        thread = threading.Thread(target=self._answer, args=(t_ns,), daemon=True)  # never block Zenoh's thread
        with self._lock:  # close() joins only threads that started: a call racing close() is not answered
            if self._closed:
                return
            thread.start()
            self._threads.append(thread)

    def _answer(self, t_ns: int) -> None:
        if t_ns == self.slow_at_ns:
            time.sleep(SLOW_S)
        with self._lock:
            lose, self.lose = (self.lose, None) if self.lose is not None and self.lose[1] == t_ns else (None, self.lose)
            if lose is not None and lose[0] == "call":
                return
            if t_ns in self.answered:  # a repeated call: the same ready again
                self._ready.put(f"{t_ns} {t_ns + WAKE_NS} {self.answered.index(t_ns)}")
                return
            self.answered.append(t_ns)
            self.seq += 1
            if not (lose is not None and lose[0] == "sample"):
                self.feed.deliver(self.seq)
            if not (lose is not None and lose[0] == "ready"):
                self._ready.put(f"{t_ns} {t_ns + WAKE_NS} {self.seq}")

    def close(self) -> None:
        self._sub.undeclare()
        with self._lock:
            self._closed = True
            threads = list(self._threads)
        for thread in threads:  # a late answer still goes out before its publisher goes
            thread.join(2 * SLOW_S)
        self._ready.undeclare()


@pytest.mark.parametrize("alive, dropped_because", [
    (True, None),  # slow, not gone: waited for
    (False, "its liveliness token is gone"),  # killed: dropped at once
    (None, f"no answer within {WATCHDOG_S:.1f} s"),  # no token known: the short watchdog
], ids=["token-present-waits", "token-gone-drops-at-once", "no-token-known-drops-after-the-watchdog"])
def test_a_slow_carrier_is_waited_for_while_its_liveliness_token_is_present(alive, dropped_because, caplog) -> None:
    caplog.set_level(logging.WARNING, logger="mission.bus.lockstep")
    keys = clock_keys("relay-test")
    feed = _StateFeed()
    with peer_pair() as (controller, carrier_session):
        carrier = _ScriptedCarrier(carrier_session, keys, feed, slow_at_ns=WAKE_NS)
        kept: list[float] = []  # the relay telling our upstream (the vehicle) that the step goes on
        relay = ZenohRelay(controller, keys, feed, SimpleNamespace(last_seq=-1), alive=lambda: alive,
                           watchdog_wall_s=WATCHDOG_S, alive_watchdog_wall_s=10 * SLOW_S, join_wall_s=10.0,
                           keepalive=lambda: kept.append(time.monotonic()))
        try:
            relay.run(0)  # joins (the call is repeated until the route is up)
            assert relay.wake_ns() == WAKE_NS and relay.dropped == 0
            start = time.monotonic()
            relay.run(WAKE_NS)  # the slow step
            waited = time.monotonic() - start
            if dropped_because is None:
                assert waited >= SLOW_S and relay.dropped == 0
                assert relay.wake_ns() == 2 * WAKE_NS  # the carrier's answer to this step, not a guess
                assert "liveliness token is present: waiting up to" in caplog.text
                assert kept and start < kept[0], (start, kept)  # told while it waited
            else:
                assert alive or not kept, kept  # not for a carrier not known to be alive
                assert waited < SLOW_S and relay.dropped == 1
                assert relay.wake_ns() is None  # dropped: no longer a participant
                assert dropped_because in caplog.text
        finally:
            relay.close()
            carrier.close()


@pytest.mark.parametrize("lockstep, expected", [(True, zenoh.CongestionControl.BLOCK), (False, zenoh.CongestionControl.DROP)],
                         ids=["lockstep-blocks", "real-time-drops"])
def test_state_streams_never_drop_a_sample_in_lockstep(tmp_path, lockstep, expected) -> None:
    """In lockstep each step waits for the sample a clock message names (the passenger status a
    call names, the carrier state a ready names): a sample Zenoh dropped on a congested link (it
    drops a DROP sample that waits over about 1 ms for its queue) held both sides until their
    watchdogs fired, under two busy loops. So the state streams block there; in real time they
    drop, so a congested link never stalls the loop."""
    cfg = with_overrides(load_config(CONFIGS / "demo.toml"), {
        "zenoh.listen": ["tcp/127.0.0.1:0"], "zenoh.connect": [], "zenoh.rendezvous": None,
        "mavlink.url": "udpin:127.0.0.1:0"})
    clock = LockstepClock(name="test", creator_runs=False) if lockstep else ScaledClock()
    try:
        with mission_io(cfg, clock) as (_feed, passenger, _link, _sources, _neighbours):  # what `marsupial run` opens
            assert passenger.congestion_control == expected
        session = open_session(cfg.zenoh)
        try:
            with CarrierController(cfg, clock, session, SimRobot(cfg, clock)) as carrier:  # `marsupial carrier`
                assert carrier.publisher.congestion_control == expected
        finally:
            session.close()
    finally:
        clock.close()


@pytest.mark.parametrize("lost", ["call", "ready", "sample"])
def test_a_call_an_answer_or_a_sample_lost_in_an_outage_is_asked_again_or_given_up(lost, caplog) -> None:
    """A Zenoh outage (a router restarted) lost a call sent as the route came back: the relay
    waited for a carrier that never heard it, and the vehicle dropped the controller. The relay
    calls again every RESEND_WALL_S while unanswered (the carrier reports a step it took again),
    and gives up a state sample a ready names after LOST_WALL_S and LOST_AFTER_REPEATS readies;
    the carrier stays in the lockstep either way."""
    caplog.set_level(logging.WARNING, logger="mission.bus.lockstep")
    keys = clock_keys("outage-test")
    feed = _StateFeed()
    with peer_pair() as (controller, carrier_session):
        carrier = _ScriptedCarrier(carrier_session, keys, feed, lose=(lost, WAKE_NS))
        relay = ZenohRelay(controller, keys, feed, SimpleNamespace(last_seq=-1), alive=lambda: True,
                           watchdog_wall_s=WATCHDOG_S, alive_watchdog_wall_s=10 * LOST_WALL_S, join_wall_s=10.0)
        try:
            relay.run(0)
            start = time.monotonic()
            relay.run(WAKE_NS)  # the step the outage hit
            waited = time.monotonic() - start
            assert relay.dropped == 0 and relay.wake_ns() == 2 * WAKE_NS  # this step's answer: still in step
            if lost == "sample":
                assert relay.missed == 1 and waited >= LOST_WALL_S
                assert "state sample 1 never came" in caplog.text
            else:
                assert relay.missed == 0 and waited >= RESEND_WALL_S  # asked again, not given up
            relay.run(2 * WAKE_NS)  # the next step is in step again, at once
            assert relay.dropped == 0 and relay.wake_ns() == 3 * WAKE_NS and carrier.answered == [0, WAKE_NS, 2 * WAKE_NS]
        finally:
            relay.close()
            carrier.close()


def test_a_shorter_lost_wall_gives_a_missing_sample_up_after_it_and_the_repeats(caplog) -> None:
    """``lost_wall_s`` (``run --lockstep-lost-wall``) below the 2 s default: a state sample that never
    comes is given up after it, still only after LOST_AFTER_REPEATS readies (the calls repeated
    sooner, every lost_wall_s / LOST_AFTER_REPEATS), and the next step is in step again."""
    caplog.set_level(logging.WARNING, logger="mission.bus.lockstep")
    keys = clock_keys("lost-wall-test")
    feed = _StateFeed()
    with peer_pair() as (controller, carrier_session):
        carrier = _ScriptedCarrier(carrier_session, keys, feed, lose=("sample", WAKE_NS))
        relay = ZenohRelay(controller, keys, feed, SimpleNamespace(last_seq=-1), alive=lambda: True,
                           watchdog_wall_s=WATCHDOG_S, alive_watchdog_wall_s=10 * LOST_WALL_S, join_wall_s=10.0,
                           lost_wall_s=0.3)
        try:
            relay.run(0)
            start = time.monotonic()
            relay.run(WAKE_NS)
            waited = time.monotonic() - start
            assert relay.missed == 1 and relay.dropped == 0 and waited >= 0.3
            readies = int(caplog.text.split("state sample 1 never came")[1].split(" readies")[0].rsplit(" ", 1)[1])
            assert readies >= LOST_AFTER_REPEATS, caplog.text
            relay.run(2 * WAKE_NS)
            assert relay.wake_ns() == 3 * WAKE_NS and carrier.answered == [0, WAKE_NS, 2 * WAKE_NS]
        finally:
            relay.close()
            carrier.close()


class _Barriers:
    """The carrier's clock as its upstream sees it: records each barrier."""

    def __init__(self) -> None:
        self.upstream = None
        self.at: list[int] = []
        self.cv = threading.Condition()

    def barrier(self, t_ns: int) -> None:
        with self.cv:
            self.at.append(t_ns)
            self.cv.notify_all()

    def heard(self) -> None:
        """A call came (its barrier may wait for the status it names)."""


def test_a_passenger_status_lost_in_an_outage_is_given_up_after_repeated_calls(monkeypatch, caplog) -> None:
    """The carrier steps on a call once the passenger status it names has come; one that never
    comes (lost in an outage) is given up after LOST_WALL_S and LOST_AFTER_REPEATS repeated
    calls, never after one call; a repeated call for a step taken is passed on at once."""
    monkeypatch.setattr(lockstep, "LOST_WALL_S", 0.4)
    caplog.set_level(logging.WARNING, logger="mission.bus.lockstep")
    keys = clock_keys("status-test")
    statuses, clock = _StateFeed(), _Barriers()
    with peer_pair() as (carrier_session, controller):
        upstream = ZenohUpstream(clock, carrier_session, keys, statuses, published=lambda: 0)  # type: ignore[arg-type]
        calls = controller.declare_publisher(keys[0])
        try:
            def call_until(t_ns: int, seq: int, period_s: float) -> tuple[int, float]:
                start, sent = time.monotonic(), 0
                with clock.cv:
                    while t_ns not in clock.at:
                        calls.put(f"{t_ns} {seq}")  # the relay's call, repeated while unanswered
                        sent += 1
                        clock.cv.wait(period_s)
                        assert time.monotonic() - start < 10.0, clock.at
                return sent, time.monotonic() - start

            statuses.deliver(0)
            call_until(0, 0, 0.05)  # the route is up, status 0 came: stepped
            sent, waited = call_until(WAKE_NS, 1, 0.1)  # status 1 is lost
            assert upstream.missed == 1 and waited >= 0.4 and sent >= lockstep.LOST_AFTER_REPEATS + 1
            assert "passenger status 1 never came" in caplog.text
            clock.at.clear()
            call_until(WAKE_NS, 1, 0.05)  # the same call again: passed on, not waited for again
            statuses.deliver(2)
            call_until(2 * WAKE_NS, 2, 0.05)
            assert upstream.missed == 1 and clock.at[-1] == 2 * WAKE_NS  # in step again
        finally:
            calls.undeclare()
            upstream.close()
