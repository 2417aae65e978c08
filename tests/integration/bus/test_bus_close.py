"""A Zenoh session closes within a bound under a slowloris: 350 TCP connections to its listener
that send one byte and then nothing (on main, a mission's close under such a load raised
zenoh.ZError, exit 1 instead of its own code)."""
from __future__ import annotations

import socket
import time

import pytest

from mission.bus.session import CLOSE_TIMEOUT_S, close_session
from tests.support.zenoh_util import endpoint, free_port, peer

pytestmark = pytest.mark.timeout(60)


def test_close_under_a_slowloris_returns_within_its_bound_and_raises_nothing() -> None:
    port = free_port()
    session = peer(listen=[endpoint(port)])
    conns: list[socket.socket] = []
    try:
        for _ in range(350):
            conn = socket.create_connection(("127.0.0.1", port), timeout=5.0)
            conn.sendall(b"\x00")  # a frame begun, never finished
            conns.append(conn)
        start = time.monotonic()
        close_session(session)
        took = time.monotonic() - start
    finally:
        for conn in conns:
            conn.close()
    assert len(conns) == 350 and took < CLOSE_TIMEOUT_S + 1.0, took
    close_session(session)  # closing again is harmless too
