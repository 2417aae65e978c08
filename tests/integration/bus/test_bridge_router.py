"""A Python session in router mode routes carrier states, passenger statuses and liveliness
between two client sessions (the fleet set-up of configs/zenoh/router.json5 and
fleet_client.json5, on a test-chosen loopback port)."""
from __future__ import annotations

import numpy as np
import pytest

from mission.bus.bridge import CarrierFeed, CarrierPublisher, PassengerFeed, PassengerPublisher
from mission.time.clock import ManualClock
from mission.bus.wire import CarrierState, PassengerStatus
from tests.support.zenoh_util import LENIENT, endpoint, free_port, peer, wait_for

pytestmark = pytest.mark.timeout(30)


def test_router_routes_pub_sub_and_liveliness_between_clients() -> None:
    ep = endpoint(free_port())
    router = peer(listen=[ep], mode="router")
    try:
        passenger_side = peer(connect=[ep], mode="client")
        carrier_side = peer(connect=[ep], mode="client")
        try:
            clock = ManualClock()
            with CarrierFeed(passenger_side, "fleet1", clock, limits=LENIENT) as cfeed, \
                    PassengerFeed(carrier_side, "fleet1", clock) as pfeed, \
                    PassengerPublisher(passenger_side, "fleet1") as ppub:
                cpub = CarrierPublisher(carrier_side, "fleet1")
                wait_for(lambda: cpub.matched and ppub.matched, what="matching through the router")
                cpub.publish(CarrierState(1.0, 1, "local_ned", [3.0, 4.0, 0.0], [1.0, 0.0, 0.0], 0.0))
                ppub.publish(PassengerStatus("RIDING", 1.0, 1, [3.0, 4.0, -1.5], [1.0, 0.0, 0.0]))
                rx = wait_for(cfeed.latest, what="carrier state via router")
                np.testing.assert_array_equal(rx.state.position, [3.0, 4.0, 0.0])
                assert wait_for(pfeed.latest, what="passenger status via router").status.phase == "RIDING"
                wait_for(lambda: cfeed.alive is True and pfeed.alive is True, what="tokens via router")
                cpub.close()  # the carrier undeclares its token: the passenger side sees it go
                wait_for(lambda: cfeed.alive is False, what="carrier token gone via router")
                assert pfeed.alive is True
            assert cfeed.counters["dropped"] == {} and pfeed.counters["dropped"] == {}
        finally:
            carrier_side.close()
            passenger_side.close()
    finally:
        router.close()
