"""One key per robot on a team's bus (real Zenoh on loopback, scouting off): every robot's public
key in one directory (``zenoh.public_keys_dir``), each robot signing with its own. A status on
bravo's key verifies only with bravo's key: a teammate that holds a valid key of its own (charlie),
or the carrier, cannot speak for bravo, to its teammates or to the carrier. With the pair's shared
key, which every robot of the team holds, charlie can (the weakness the directory closes). The
carrier echoes every passenger's clock pings and no stranger's."""
from __future__ import annotations

import contextlib
from pathlib import Path

import pytest

from mission.bus.auth import CARRIER, BusAuth, team_bus_auth
from mission.bus.bridge import PassengerFeed, PassengerPublisher, keys
from mission.bus.neighbours import NeighbourFeed
from mission.bus.timesync import ClockEcho, ClockPing
from mission.bus.wire import PassengerStatus
from mission.config.keys import write_key_pair
from mission.config.schema import ZenohSection
from mission.time.clock import ManualClock, ScaledClock
from tests.support.zenoh_util import hub_and_clients, wait_for

pytestmark = pytest.mark.timeout(30)

TEAM = ("alpha", "bravo", "charlie")
PAIR = "team"


def _keys(folder: Path) -> dict[str, BusAuth]:
    """A key pair per robot of the team (and a stranger's, outside the directory) and each robot's
    keys on the bus as its process reads them (:func:`team_bus_auth`)."""
    public = folder / "keys"
    public.mkdir()
    for robot in (CARRIER, *TEAM):
        write_key_pair(folder / f"{robot}.key", public / f"{robot}.pub")
    write_key_pair(folder / "stranger.key", folder / "stranger.pub")
    out = {}
    for robot in (CARRIER, *TEAM):
        section = ZenohSection(public_keys_dir=str(public), private_key_file=str(folder / f"{robot}.key"))
        auth = team_bus_auth(section, TEAM, robot, PAIR)
        assert auth is not None and auth.mode == "ed25519"
        out[robot] = auth
    stranger = ZenohSection(public_keys_dir=str(public), private_key_file=str(folder / "stranger.key"))
    out["stranger"] = team_bus_auth(stranger, TEAM, "", PAIR)  # type: ignore[assignment]  # no name: not matched
    return out


def _status(seq: int, x: float) -> PassengerStatus:
    return PassengerStatus("NAVIGATING", 0.02 * seq, seq, [x, 0.0, -2.0], [1.0, 0.0, 0.0])


def _put_as(session: object, auth: BusAuth, name: str, status: PassengerStatus) -> None:
    """Put ``status`` on passenger ``name``'s key, signed with ``auth``'s own key."""
    key, payload = keys(PAIR, name).passenger_state, status.to_json()
    session.put(key, payload, attachment=auth.signer().attachment(key, payload))  # type: ignore[attr-defined]


def test_a_status_verifies_only_with_the_key_of_the_passenger_it_names(tmp_path: Path) -> None:
    auth = _keys(tmp_path)
    clock = ManualClock()
    with contextlib.ExitStack() as stack:
        carrier, a, b, c = hub_and_clients(stack, 4)
        heard = NeighbourFeed(a, PAIR, "alpha", TEAM, clock, max_speed_m_s=6.0, auth=auth["alpha"])
        stack.callback(heard.close)
        feed = stack.enter_context(PassengerFeed(carrier, PAIR, clock, auth=auth[CARRIER].for_peer("bravo"),
                                                 passenger="bravo"))
        bravo = stack.enter_context(PassengerPublisher(b, PAIR, auth=auth["bravo"], passenger="bravo"))
        wait_for(lambda: bravo.matched and feed.alive, what="alpha and the carrier hear bravo")
        bravo.publish(_status(1, 10.0))
        wait_for(lambda: heard.counters["accepted"] == 1 and feed.counters["accepted"] == 1, what="bravo's status")

        _put_as(c, auth["charlie"], "bravo", _status(2, 10.02))  # a teammate with a valid key of its own
        _put_as(c, auth[CARRIER], "bravo", _status(3, 10.04))  # the carrier's key
        _put_as(c, auth["stranger"], "bravo", _status(4, 10.06))  # a key of no robot of the team
        _put_as(c, auth["charlie"], "charlie", _status(5, 20.0))  # charlie as itself: heard
        wait_for(lambda: heard.counters["accepted"] == 2 and sum(heard.counters["dropped"].values()) == 3
                 and feed.counters["dropped"].get("signature", 0) == 3, what="every sample judged")
        assert heard.counters["dropped"] == {"signature": 3}, heard.counters
        assert heard.counters["heard"] == ["bravo", "charlie"] and heard.counters["signed"]
        assert feed.counters["accepted"] == 1 and feed.counters["dropped"] == {"signature": 3}, feed.counters
        assert [m.position_ned_m[0] for m in heard.heard()] == [10.0, 20.0]


def test_with_the_pairs_shared_key_a_teammate_can_speak_for_another(tmp_path: Path) -> None:
    """What the key directory closes: with the pair's key every robot of the team signs alike, and
    charlie's status on bravo's key is heard as bravo's."""
    shared = BusAuth(bytes.fromhex("3c" * 32), PAIR)
    clock = ManualClock()
    with contextlib.ExitStack() as stack:
        a, c = hub_and_clients(stack, 2)
        heard = NeighbourFeed(a, PAIR, "alpha", TEAM, clock, max_speed_m_s=6.0, auth=shared)
        stack.callback(heard.close)
        charlie = stack.enter_context(PassengerPublisher(c, PAIR, auth=shared, passenger="charlie"))
        wait_for(lambda: charlie.matched, what="alpha hears the team's keys")
        _put_as(c, shared, "bravo", _status(2, 10.02))
        wait_for(lambda: heard.counters["accepted"] == 1, what="the forged status judged")
        assert heard.counters["heard"] == ["bravo"] and heard.counters["dropped"] == {}


def test_the_carrier_echoes_every_passengers_pings_and_no_strangers(tmp_path: Path) -> None:
    auth = _keys(tmp_path)
    ours, carrier_clock = ScaledClock(), ScaledClock(start_s=100.0)  # one moment: the carrier 100 s ahead
    with contextlib.ExitStack() as stack:
        carrier, a, b, s = hub_and_clients(stack, 4)
        echo = ClockEcho(carrier, PAIR, carrier_clock, auth[CARRIER])
        stack.callback(echo.close)
        pings = {name: ClockPing(session, PAIR, ours, auth[name], period_s=0.05)
                 for name, session in (("alpha", a), ("bravo", b), ("stranger", s))}
        for ping in pings.values():
            stack.callback(ping.close)
        wait_for(lambda: all(pings[n].estimate() is not None for n in ("alpha", "bravo"))
                 and echo.counters["dropped"].get("signature", 0) >= 3, what="both passengers' clocks, a stranger's pings")
        for name in ("alpha", "bravo"):
            got = pings[name].estimate()
            assert got is not None and abs(got.offset_s - 100.0) <= got.bound_s + 1e-3, (name, got)
        assert set(echo.counters["dropped"]) == {"signature"}, echo.counters  # the stranger's pings, only
        assert pings["stranger"].estimate() is None
