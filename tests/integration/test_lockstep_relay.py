"""Lockstep over real Zenoh sessions on loopback, against a busy machine.

The controller's relay to the carrier (:class:`mission.lockstep.ZenohRelay`): a slow carrier whose
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
from mission.carrier.sim_robot import SimRobot
from mission.carrier_bridge import open_session
from mission.clock import LockstepClock, ScaledClock
from mission.config import load_config, with_overrides
from mission.lockstep import ZenohRelay, clock_keys
from mission.run_cli import mission_io
from tests.conftest import CONFIGS
from tests.integration.zenoh_util import peer_pair

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
    """Answers each clock call ``"t seq"``: publishes a state sample, then ``"t wake seq"``;
    the calls at ``slow_at_ns`` are answered ``SLOW_S`` late (wall)."""

    def __init__(self, session, keys: tuple[str, str], feed: _StateFeed, slow_at_ns: int) -> None:
        self.feed, self.slow_at_ns, self.seq = feed, slow_at_ns, -1
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
            if t_ns in self.answered:  # a repeated join call
                return
            self.answered.append(t_ns)
            self.seq += 1
            self.feed.deliver(self.seq)
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
    caplog.set_level(logging.WARNING, logger="mission.lockstep")
    keys = clock_keys("relay-test")
    feed = _StateFeed()
    with peer_pair() as (controller, carrier_session):
        carrier = _ScriptedCarrier(carrier_session, keys, feed, slow_at_ns=WAKE_NS)
        relay = ZenohRelay(controller, keys, feed, SimpleNamespace(last_seq=-1), alive=lambda: alive,
                           watchdog_wall_s=WATCHDOG_S, alive_watchdog_wall_s=10 * SLOW_S, join_wall_s=10.0)
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
            else:
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
        with mission_io(cfg, clock) as (_feed, passenger, _link):  # what `marsupial run` opens
            assert passenger.congestion_control == expected
        session = open_session(cfg.zenoh)
        try:
            with CarrierController(cfg, clock, session, SimRobot(cfg, clock)) as carrier:  # `marsupial carrier`
                assert carrier.publisher.congestion_control == expected
        finally:
            session.close()
    finally:
        clock.close()
