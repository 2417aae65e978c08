"""free_port: ports below the ephemeral range, one lane per pytest-xdist worker, never the same twice."""
from __future__ import annotations

import socket

import pytest

from sim import net
from sim.net import LANE_ENV, PORT_RANGE, free_port, port_lane
from tests.conftest import xdist_port_lane


@pytest.fixture
def lane(monkeypatch):
    """Set this process's lane (and forget where free_port was in each lane)."""
    monkeypatch.setattr(net, "_cursor", {})

    def set_lane(spec: str | None) -> None:
        if spec is None:
            monkeypatch.delenv(LANE_ENV, raising=False)
        else:
            monkeypatch.setenv(LANE_ENV, spec)
    return set_lane


@pytest.mark.parametrize("kind", [socket.SOCK_STREAM, socket.SOCK_DGRAM], ids=["tcp", "udp"])
def test_ports_are_below_the_ephemeral_range_bindable_and_never_handed_out_twice(lane, kind) -> None:
    lane(None)
    ports = [free_port(kind) for _ in range(200)]
    assert all(PORT_RANGE[0] <= p < PORT_RANGE[1] for p in ports)
    assert len(set(ports)) == len(ports)
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", ports[-1]))  # really free


@pytest.mark.parametrize("count", [1, 2, 3, 8])
def test_lanes_split_the_range_without_overlap_and_each_worker_stays_in_its_own(lane, count) -> None:
    bounds = []
    for index in range(count):
        lane(f"{index}/{count}")
        lo, hi = port_lane()
        bounds.append((lo, hi))
        assert all(lo <= free_port() < hi for _ in range(20))
    assert bounds[0][0] == PORT_RANGE[0] and bounds[-1][1] <= PORT_RANGE[1]
    assert all(a[1] == b[0] for a, b in zip(bounds, bounds[1:]))  # adjacent, disjoint


def test_a_port_someone_holds_is_skipped(lane, monkeypatch) -> None:
    lane("0/2")
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as held:
        held.bind(("127.0.0.1", free_port()))
        port = held.getsockname()[1]
        monkeypatch.setattr(net, "_cursor", {port_lane(): port})  # the next pick would be the held port
        assert free_port() != port


@pytest.mark.parametrize("spec", ["x", "1", "3/3", "-1/2", "0/0", "0/1000", "a/b"])
def test_a_malformed_lane_names_the_variable(lane, spec) -> None:
    lane(spec)
    with pytest.raises(ValueError, match=LANE_ENV):
        free_port()


@pytest.mark.parametrize("env, expected", [
    ({"PYTEST_XDIST_WORKER": "gw2", "PYTEST_XDIST_WORKER_COUNT": "3"}, "2/3"),
    ({"PYTEST_XDIST_WORKER": "gw0", "PYTEST_XDIST_WORKER_COUNT": "1"}, "0/1"),
    ({}, None),
    ({"PYTEST_XDIST_WORKER": "master"}, None),
])
def test_each_xdist_worker_gets_its_own_lane(env, expected) -> None:
    assert xdist_port_lane(env) == expected
