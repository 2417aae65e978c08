"""A carrier whose stamps run ahead of the clock the feed shares with it (a carrier that left the
lockstep and ran on by its own clock: seen in a lossy-link fault flight under load, where the
measured age reached -132 s and the dock point predicted from it lay 148 m away): its states are
aged by their arrival, counted, never by a measurement time after they arrived."""
from __future__ import annotations

import pytest

from mission.bus.bridge import CarrierFeed, CarrierPublisher
from mission.bus.feeds import FUTURE_SLACK_S
from mission.bus.wire import CarrierState
from mission.time.clock import ManualClock
from mission.time.offset import SharedClock
from tests.support.zenoh_util import LENIENT, peer_pair, wait_for

pytestmark = pytest.mark.timeout(30)


def _flow(ahead_s: float) -> tuple[object, dict]:
    """A carrier stamping ``ahead_s`` [s] ahead of the shared clock sends five states 0.02 s apart;
    the feed's newest 0.03 s after the last arrived, and its counters."""
    clock = ManualClock(10.0)
    with peer_pair() as (a, b), CarrierFeed(b, "p", clock, limits=LENIENT, max_age_s=0.5,
                                            offset=SharedClock()) as feed, CarrierPublisher(a, "p") as pub:
        wait_for(lambda: pub.matched, what="the feed matched")
        for seq in range(1, 6):
            pub.publish(CarrierState(clock.now() + ahead_s, seq, "local_ned", [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], 0.0))
            wait_for(lambda: (r := feed.latest()) is not None and r.state.seq == seq, what=f"state {seq}")
            clock.advance(0.02)
        clock.advance(0.01)
        return feed.latest(), feed.counters


def test_on_the_shared_clock_a_state_is_aged_by_its_measurement() -> None:
    got, counters = _flow(-0.01)  # measured 0.01 s before it arrived
    assert got.age_s == pytest.approx(0.04) and got.rx_age_s == pytest.approx(0.03) and got.age_bound_s == 0.0
    assert counters["future_stamps"] == 0
    got, counters = _flow(FUTURE_SLACK_S * 0.5)  # a little ahead, within the slack: still the measurement's
    assert got.age_s == pytest.approx(0.03 - FUTURE_SLACK_S * 0.5) and counters["future_stamps"] == 0


def test_a_state_stamped_after_it_arrived_is_aged_by_its_arrival() -> None:
    got, counters = _flow(74.0)  # 74 s ahead: the offset does not hold for this carrier's clock
    assert got.age_s == pytest.approx(0.03) and got.rx_age_s == pytest.approx(0.03)
    assert got.age_bound_s is None and not got.stale
    assert counters["future_stamps"] >= 1
