"""A team on the bus (real Zenoh on loopback, scouting off): each passenger's status on its own key,
the carrier binding each one separately, and a passenger hearing its teammates (NeighbourFeed):
what is malformed, foreign, out of order or implausible is dropped and counted, never a crash and
never heard; its own status never comes back as a teammate's."""
from __future__ import annotations

import contextlib

import numpy as np
import pytest

from mission.bus.auth import BusAuth
from mission.bus.bridge import PassengerFeed, PassengerPublisher, keys
from mission.bus.neighbours import NeighbourFeed, Roster
from mission.bus.wire import PassengerStatus
from mission.controller import as_neighbours
from mission.time.clock import ManualClock
from tests.support.zenoh_util import hub_and_clients, wait_for

pytestmark = pytest.mark.timeout(30)

AUTH = BusAuth(bytes.fromhex("3c" * 32), "team")
TEAM = ("alpha", "bravo", "charlie")


def _status(seq: int, position: list[float], velocity: list[float] | None = None, phase: str = "NAVIGATING",
            stamp: float | None = None) -> PassengerStatus:
    return PassengerStatus(phase, 0.02 * seq if stamp is None else stamp, seq, position, velocity or [1.0, 0.0, 0.0])


def test_teammates_are_heard_and_bad_statuses_are_dropped_and_counted() -> None:
    clock = ManualClock()
    with contextlib.ExitStack() as stack:
        sessions = dict(zip(("alpha", "bravo", "rogue"), hub_and_clients(stack, 3)))
        feed = NeighbourFeed(sessions["alpha"], "team", "alpha", TEAM, clock, max_speed_m_s=6.0, max_age_s=1.0,
                             auth=AUTH)
        stack.callback(feed.close)
        own = stack.enter_context(PassengerPublisher(sessions["alpha"], "team", auth=AUTH, passenger="alpha"))
        bravo = stack.enter_context(PassengerPublisher(sessions["bravo"], "team", auth=AUTH, passenger="bravo"))
        wait_for(lambda: bravo.matched, what="alpha hears bravo's key")
        own.publish(_status(1, [0.0, 0.0, -1.0]))  # our own: never a teammate
        bravo.publish(_status(1, [10.0, 0.0, -2.0], phase="SEPARATED"))
        wait_for(lambda: feed.counters["accepted"] == 1, what="bravo's first status")

        rogue = sessions["rogue"]
        signer = AUTH.signer()

        def put(name: str, payload: bytes, signed: bool = True) -> None:
            key = keys("team", name).passenger_state
            rogue.put(key, payload, attachment=signer.attachment(key, payload) if signed else None)

        def judged() -> int:
            return feed.counters["accepted"] + sum(feed.counters["dropped"].values())

        # one at a time, each judged before the next: Zenoh's publishers drop what a full queue cannot
        # take (congestion control DROP, the default), and a loaded machine dropped two of four sent
        # back to back (CI, 2026-12-06)
        sends = [lambda: put("bravo", _status(50, [10.0, 0.0, -2.0]).to_json(), signed=False),  # unsigned
                 lambda: put("bravo", b'{"phase": "RIDING", "stamp": ', signed=True),  # malformed
                 lambda: put("zulu", _status(2, [5.0, 5.0, -2.0]).to_json()),  # not a teammate
                 lambda: bravo.publish(_status(2, [10.02, 0.0, -2.0], velocity=[40.0, 0.0, 0.0])),  # implausible speed
                 lambda: bravo.publish(_status(3, [30.0, 0.0, -2.0])),  # 20 m in 40 ms
                 lambda: bravo.publish(_status(4, [10.04, 0.0, -2.0], stamp=0.0)),  # stamped before the last
                 lambda: bravo.publish(_status(5, [10.06, 0.2, -2.0], phase="NAVIGATING"))]  # good
        for n, send in enumerate(sends, start=judged() + 1):
            send()
            wait_for(lambda: judged() == n, what=f"sample {n} judged")
        assert feed.counters["accepted"] == 2 and sum(feed.counters["dropped"].values()) == 6
        c = feed.counters
        assert c["dropped"] == {"unsigned": 1, "decode": 1, "unbound": 1, "speed": 1, "jump": 1, "stale_stamp": 1}, c
        assert c["heard"] == ["bravo"] and c["signed"]

        clock.advance(0.2)
        heard = feed.heard()
        assert [m.name for m in heard] == ["bravo"] and heard[0].phase == "NAVIGATING"
        assert np.allclose(heard[0].position_ned_m, [10.06, 0.2, -2.0]) and heard[0].age_s == pytest.approx(0.2)
        mates = as_neighbours(heard)
        assert mates is not None and mates.phases == ("NAVIGATING",) and mates.age_s is not None
        assert mates.positions_m.shape == (1, 3) and float(mates.age_s[0]) == pytest.approx(0.2)
        assert as_neighbours([]) is None


def test_the_recovery_queue_hears_what_a_teammate_shares_and_the_roster_names() -> None:
    """A returning teammate's status carries how long its recovery has run and its battery; the
    team's file gives its system id and its leg's target: the queue's claim is whole over the bus
    (without them a teammate's recovery counted as never begun, and each passenger thought it
    went first)."""
    clock = ManualClock()
    roster = {"bravo": Roster(2, ((44.0, 4.0, -4.0), (20.0, -20.0, -4.0)))}
    with contextlib.ExitStack() as stack:
        a, b = hub_and_clients(stack, 2)
        feed = NeighbourFeed(a, "team", "alpha", TEAM, clock, max_speed_m_s=6.0, auth=AUTH, roster=roster)
        stack.callback(feed.close)
        bravo = stack.enter_context(PassengerPublisher(b, "team", auth=AUTH, passenger="bravo"))
        wait_for(lambda: bravo.matched, what="alpha hears bravo's key")
        bravo.publish(PassengerStatus("HOLDOFF", 30.0, 1, [40.0, 4.0, -6.0], [0.0, 0.0, 0.0], leg=1,
                                      recovery_s=12.5, battery_pct=41.0))
        wait_for(lambda: feed.counters["accepted"] == 1, what="bravo's status")
        clock.advance(0.1)
        mates = as_neighbours(feed.heard())
        assert mates is not None and mates.phases == ("HOLDOFF",)
        assert mates.recovery_s == (12.5,) and mates.battery_pct == (41.0,) and mates.ids == (2,)
        assert mates.targets_ned_m is not None and np.allclose(mates.targets_ned_m, [[20.0, -20.0, -4.0]])
        from mission.phases.queue import claim, goes_before, neighbour_claim
        theirs = neighbour_claim(mates, 0, must_pct=30.0)
        assert theirs.asked_s == pytest.approx(12.6) and theirs.rank == 2
        assert goes_before(theirs, claim(5.0, 80.0, 30.0, 1))  # asked 7.6 s before us: it goes first
        assert goes_before(claim(20.0, 80.0, 30.0, 1), theirs)


def test_the_carrier_binds_each_passenger_on_its_own_key() -> None:
    clock = ManualClock()
    with contextlib.ExitStack() as stack:
        carrier, a, b = hub_and_clients(stack, 3)
        feeds = {n: stack.enter_context(PassengerFeed(carrier, "team", clock, auth=AUTH, passenger=n))
                 for n in ("alpha", "bravo")}
        pubs = {"alpha": stack.enter_context(PassengerPublisher(a, "team", auth=AUTH, passenger="alpha")),
                "bravo": stack.enter_context(PassengerPublisher(b, "team", auth=AUTH, passenger="bravo"))}
        wait_for(lambda: all(p.matched for p in pubs.values()), what="both matched")
        wait_for(lambda: all(f.alive for f in feeds.values()), what="both tokens")
        pubs["alpha"].publish(_status(1, [1.0, 0.0, 0.0], phase="PREFLIGHT"))
        pubs["bravo"].publish(_status(1, [2.0, 0.0, 0.0], phase="PREFLIGHT"))
        wait_for(lambda: all(f.latest() is not None for f in feeds.values()), what="each bound")
        for name, x in (("alpha", 1.0), ("bravo", 2.0)):
            got = feeds[name].latest()
            assert got is not None and got.key == f"marsupial/team/passenger/{name}/state"
            assert got.status.position_ned_m[0] == x and feeds[name].counters["dropped"] == {}
            assert feeds[name].counters["bound_source"] is not None
