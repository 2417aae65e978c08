"""Several marsupial pairs share one Zenoh network: keys are namespaced per pair, so three pairs
publishing at once never see each other's states, statuses or liveliness tokens.

The network is a router with one client session per robot (the fleet set-up). A hub *peer*
would do too, but peers do not route data for each other: until gossip has linked two peers
directly, a put can be lost although the publisher already sees the subscriber, which makes
exact counts racy in a test."""
from __future__ import annotations

import contextlib

import pytest

from mission.bus.bridge import CarrierFeed, CarrierPublisher, PassengerFeed, PassengerPublisher
from mission.time.clock import ManualClock
from mission.bus.wire import CarrierState, PassengerStatus
from tests.support.zenoh_util import LENIENT, endpoint, free_port, peer, wait_for

pytestmark = pytest.mark.timeout(30)

PAIRS = ("alpha", "bravo", "charlie")
N = 25


def test_three_pairs_publishing_at_once_have_no_crosstalk() -> None:
    hub_ep = endpoint(free_port())
    clock = ManualClock()
    with contextlib.ExitStack() as stack:
        hub = peer(listen=[hub_ep], mode="router")
        stack.callback(hub.close)
        carriers, passengers = {}, {}
        for name in PAIRS:  # each robot its own session
            for side in (carriers, passengers):
                s = peer(connect=[hub_ep], mode="client")
                stack.callback(s.close)
                side[name] = s
        cfeeds = {n: stack.enter_context(CarrierFeed(passengers[n], n, clock, limits=LENIENT)) for n in PAIRS}
        pfeeds = {n: stack.enter_context(PassengerFeed(carriers[n], n, clock)) for n in PAIRS}
        cpubs = {n: stack.enter_context(CarrierPublisher(carriers[n], n)) for n in PAIRS}
        ppubs = {n: stack.enter_context(PassengerPublisher(passengers[n], n)) for n in PAIRS}
        wait_for(lambda: all(p.matched for p in [*cpubs.values(), *ppubs.values()]), what="all matched")
        wait_for(lambda: all(f.alive for f in [*cfeeds.values(), *pfeeds.values()]), what="all tokens")

        # Disjoint sequence ranges per pair: a foreign sample reaching a feed would either be
        # accepted (and show as a foreign marker or key) or make the next own sample "stale_seq"
        # (a counted drop). Publishers drop under congestion (newest wins), so counts are not exact.
        def seq_of(i: int, k: int) -> int:
            return 1_000_000 * (i + 1) + k  # room for many resends (one per poll)

        for k in range(N):
            for i, n in enumerate(PAIRS):  # interleaved: all pairs at once
                marker = float(seq_of(i, k))
                cpubs[n].publish(CarrierState(0.01 * k, seq_of(i, k), "local_ned", [marker, 0.0, 0.0], [0.0, 0.0, 0.0]))
                ppubs[n].publish(PassengerStatus("RIDING", 0.01 * k, seq_of(i, k), [marker, 1.0, 0.0], [0.0, 0.0, 0.0]))

        # Resend a fresh last sample until one got through, for every pair. Each resend has a new
        # sequence number (never a repeat): a repeat of one already delivered is a legitimate
        # "stale_seq" drop, which would hide the crosstalk this test looks for.
        next_k = {(side, n): N for side in ("c", "p") for n in PAIRS}

        def resend(side: str, i: int, n: str) -> None:
            k = next_k[(side, n)]
            next_k[(side, n)] = k + 1
            s = seq_of(i, k)
            if side == "c":
                cpubs[n].publish(CarrierState(0.01 * k, s, "local_ned", [float(s), 0.0, 0.0], [0.0] * 3))
            else:
                ppubs[n].publish(PassengerStatus("RIDING", 0.01 * k, s, [float(s), 1.0, 0.0], [0.0] * 3))

        def final_seen() -> bool:
            done = True
            for i, n in enumerate(PAIRS):
                c, p = cfeeds[n].latest(), pfeeds[n].latest()
                if c is None or c.state.seq < seq_of(i, N):
                    resend("c", i, n)
                    done = False
                if p is None or p.status.seq < seq_of(i, N):
                    resend("p", i, n)
                    done = False
            return done

        wait_for(final_seen, what="the last sample of every pair")
        for i, n in enumerate(PAIRS):
            c, p = cfeeds[n].latest(), pfeeds[n].latest()
            assert c is not None and c.key == f"marsupial/{n}/carrier/state"
            assert p is not None and p.key == f"marsupial/{n}/passenger/state"
            assert seq_of(i, N) <= c.state.seq < seq_of(i + 1, 0) and c.state.position[0] == c.state.seq
            assert seq_of(i, N) <= p.status.seq < seq_of(i + 1, 0) and p.status.position_ned_m[0] == p.status.seq
            for f in (cfeeds[n], pfeeds[n]):
                counters = f.counters
                assert counters["dropped"] == {}, (f.key, counters)
                assert counters["received"] == counters["accepted"] >= 1, (f.key, counters)

        # one pair's carrier going away is seen by that pair only
        cpubs["bravo"].close()
        wait_for(lambda: cfeeds["bravo"].alive is False, what="bravo's carrier gone")
        assert cfeeds["alpha"].alive is True and cfeeds["charlie"].alive is True
