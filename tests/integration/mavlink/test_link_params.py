"""Parameter writes against a PX4-like peer over real loopback sockets: a set is confirmed only by
a PARAM_VALUE that shows the value asked, so a late answer to an earlier read (a read sent again
after a timeout is answered twice) is not taken for the vehicle's refusal; a vehicle that really
keeps another value is still reported. On a loaded machine the mission took such a late answer
for a refusal, then "restored" the offboard-loss action it had just replaced (0, Position) over
the Return it had set, and a killed controller left the passenger holding over the target."""
from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from mission.errors import LinkError
from mission.mavlink import px4
from mission.mavlink.env import mavlink
from mission.mavlink.link import VehicleLink
from sim.testing.fake_px4 import FakePx4 as Px4Peer

NAME = "COM_OBL_RC_ACT"
INT32 = mavlink.MAV_PARAM_TYPE_INT32


def _param_value(value: float) -> object:
    return mavlink.MAVLink_param_value_message(NAME.encode(), px4.encode_param(value, INT32), INT32, 1, 0)


@contextmanager
def _answering(peer: Px4Peer, link: VehicleLink, on_set: list[float], kept: float) -> Iterator[None]:
    """The peer answers every read of NAME with ``kept`` and every PARAM_SET with the values of
    ``on_set``, in order, each sent once the link has taken in the one before (a STATUSTEXT
    after it shows), until the block ends."""
    stop = threading.Event()

    def vehicle() -> None:
        reads = sets = 0
        while not stop.is_set():
            for _ in peer.received("PARAM_REQUEST_READ")[reads:]:
                reads += 1
                peer.send(_param_value(kept))
            for _ in peer.received("PARAM_SET")[sets:]:
                sets += 1
                for i, value in enumerate(on_set):
                    peer.send(_param_value(value))
                    mark = f"param {sets} {i}"
                    peer.statustext(mark, severity=6)
                    link.wait_until(lambda st, mark=mark: st.last_statustext == mark, 5.0)
            time.sleep(0.005)

    thread = threading.Thread(target=vehicle, name="fake-px4-params", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(5.0)


def test_a_late_answer_to_an_earlier_read_is_not_taken_for_the_refusal(link: VehicleLink) -> None:
    with Px4Peer(link.port) as peer:
        link.wait_vehicle(timeout_s=5.0)
        with _answering(peer, link, on_set=[0.0, 3.0], kept=0.0):  # the read's late second answer, then the set's
            assert link.set_param(NAME, 3, timeout_s=2.0, retries=0) == 3.0
        assert len(peer.received("PARAM_SET")) == 1


def test_a_vehicle_that_keeps_another_value_is_reported_after_every_attempt(link: VehicleLink) -> None:
    with Px4Peer(link.port) as peer:
        link.wait_vehicle(timeout_s=5.0)
        with _answering(peer, link, on_set=[0.0], kept=0.0), \
                pytest.raises(LinkError, match=rf"vehicle kept {NAME} = 0 \(asked 3\)"):
            link.set_param(NAME, 3, timeout_s=0.3, retries=1)
        assert len(peer.received("PARAM_SET")) == 2
