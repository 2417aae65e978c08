"""Fixtures and helpers of the VehicleLink socket tests in this folder (every test here checks that
the link's and the fake PX4's threads are gone afterwards)."""
from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest

from mission.time.clock import ScaledClock
from mission.mavlink.link import VehicleLink
from sim.testing.fake_px4 import FakePx4 as Px4Peer

ANY_PORT = "udpin:127.0.0.1:0"


def link_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith(("marsupial-link", "fake-px4"))]


@pytest.fixture(autouse=True)
def no_leaked_threads() -> Iterator[None]:
    before = set(link_threads())
    yield
    leaked = [t for t in link_threads() if t not in before]
    assert not leaked, f"threads left running: {[t.name for t in leaked]}"


@pytest.fixture
def link() -> Iterator[VehicleLink]:
    with VehicleLink(ANY_PORT, ScaledClock(1.0)) as lk:
        yield lk
    assert not lk.is_open


def connected(link: VehicleLink, **peer_kwargs: object) -> Px4Peer:
    """A fake PX4 towards ``link``, to be used as a context manager."""
    return Px4Peer(link.port, **peer_kwargs)  # type: ignore[arg-type]
