"""A Zenoh session's close under a slowloris (350 TCP connections to its listener that send one
byte and then nothing) raises nothing (on main, a mission's close under such a load raised
zenoh.ZError, exit 1 instead of its own code). A close left running after CLOSE_TIMEOUT_S, and the
process's exit code then: tests/adversarial/test_bus_attacks.py."""
from __future__ import annotations

import socket
import time

import pytest

from mission.bus.session import close_session
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
        # let it finish here (an abandoned close would outlive the test)
        ended = close_session(session, timeout_s=30.0)
        took = time.monotonic() - start
    finally:
        for conn in conns:
            conn.close()
    assert len(conns) == 350 and took < 20.0, took  # Zenoh's own close gives up after ~10 s
    assert ended  # this close ended; close_abandoned() is the process's, which another test may have set
    close_session(session)  # closing again is harmless too
