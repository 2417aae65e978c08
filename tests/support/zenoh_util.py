"""Helpers for tests with real Zenoh sessions on loopback (multicast scouting off, explicit
``tcp/127.0.0.1:<port>`` endpoints chosen per test, so tests can run in parallel)."""
from __future__ import annotations

import contextlib
from collections.abc import Iterator

import zenoh

from mission.bus.bridge import open_session
from mission.config.schema import ZenohSection
from mission.bus.gate import GateLimits
from sim.net import free_port, wait_for  # noqa: F401  (re-exported for the tests)


#: Carrier-feed limits for transport and codec tests: one sample binds its source and no speed
#: limit bites (binding and plausibility have their own tests, tests/unit/bus/test_feed_gate.py).
LENIENT = GateLimits(max_speed_m_s=1000.0, bind_samples=1)


def endpoint(port: int) -> str:
    return f"tcp/127.0.0.1:{port}"


def peer(listen: list[str] | None = None, connect: list[str] | None = None, mode: str = "peer") -> zenoh.Session:
    """A session on loopback with the given endpoints (no multicast, no rendezvous)."""
    section = ZenohSection(mode=mode, listen=listen or [], connect=connect or [], multicast_scouting=False,
                           rendezvous=None)  # type: ignore[arg-type]
    return open_session(section)


@contextlib.contextmanager
def closing_all(*sessions: zenoh.Session) -> Iterator[tuple[zenoh.Session, ...]]:
    """Close every session on exit (undeclare entities before leaving the block)."""
    try:
        yield sessions
    finally:
        for s in sessions:
            s.close()


@contextlib.contextmanager
def connected(listen: str, connect: str, b_listen: list[str] | None = None) -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    """Session ``a`` listening on ``listen`` and ``b`` connected to ``connect`` (``listen`` itself,
    or a relay in front of it), once ``b`` has ``a`` as a peer; both closed on exit."""
    a = peer(listen=[listen])
    try:
        b = peer(listen=b_listen, connect=[connect])
    except BaseException:
        a.close()
        raise
    with closing_all(b, a):
        wait_for(lambda: len(list(b.info.peers_zid())) > 0, what="b connected to a")
        yield a, b


def hub_and_clients(stack: contextlib.ExitStack, count: int) -> tuple[zenoh.Session, ...]:
    """A router on a fresh port and ``count`` client sessions connected to it, as robots on one
    network reach each other; all closed by ``stack`` (clients first)."""
    hub_ep = endpoint(free_port())
    hub = peer(listen=[hub_ep], mode="router")
    stack.callback(hub.close)
    clients = []
    for _ in range(count):
        clients.append(peer(connect=[hub_ep], mode="client"))
        stack.callback(clients[-1].close)
    return tuple(clients)


@contextlib.contextmanager
def peer_pair() -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    """Two connected peer sessions: ``a`` listens on a fresh port, ``b`` connects to it."""
    ep = endpoint(free_port())
    with connected(ep, ep, b_listen=["tcp/127.0.0.1:0"]) as pair:
        yield pair


def wait_matched(pub: zenoh.Publisher, timeout_s: float = 10.0) -> None:
    """Wait until ``pub`` has a matching subscriber (so the next put is delivered)."""
    wait_for(lambda: pub.matching_status.matching, timeout_s, f"a subscriber matching {pub.key_expr}")
