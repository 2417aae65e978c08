"""What a feed hears of liveliness on real loopback Zenoh sessions (prints a table).

    python -m bench.liveliness_bench [--trials 20]

Per trial, a fresh pair of sessions (``a`` holds the sender's token, ``b`` the feed):

- ``close -> gone``: ``a`` closes (a process that ends); wall time until the carrier feed says
  ``alive is False`` (what the mission's "carrier liveliness token gone" abort waits on);
- ``get, token present`` / ``get, no token``: one ``liveliness().get`` on the alive key before
  and after (what confirming each DELETE by a query would add to the above); ``query round
  trip``: a ``get`` answered by a queryable on ``a``, for scale (a liveliness get quicker than
  that, first call on the pair included, is answered from the session's own table: the one the
  DELETE came from);
- ``link drop``: the TCP link between the sessions is cut (tests/integration/bus/link_cut.py)
  with ``a`` open: wall time from the DELETE the feed hears to the PUT that follows (the
  sessions reconnecting), and whether the DELETE came at all.

Wall times on a shared machine: inflated by load, compare runs taken together.
"""
from __future__ import annotations

import threading
import time

import click
import numpy as np
import zenoh

from mission.bus.bridge import CarrierFeed, CarrierPublisher, keys
from mission.time.clock import ManualClock
from tests.integration.bus.link_cut import LinkCut
from tests.support.zenoh_util import LENIENT, endpoint, free_port, peer, wait_for


def _timed_get(session: zenoh.Session, key: str, liveliness: bool = True) -> tuple[float, int]:
    t0 = time.perf_counter()
    replies = session.liveliness().get(key, timeout=2.0) if liveliness else session.get(key, timeout=2.0)
    n = len([r for r in replies if r.ok is not None])
    return time.perf_counter() - t0, n


def _close_to_gone() -> tuple[float, float, float, float]:
    ep = endpoint(free_port())
    b = peer(listen=[ep])
    try:
        with CarrierFeed(b, "p", ManualClock(1.0), limits=LENIENT) as feed:
            a = peer(connect=[ep])
            pub = CarrierPublisher(a, "p")
            wait_for(lambda: feed.alive is True, what="alive")
            present, n = _timed_get(b, keys("p").carrier_alive)
            assert n == 1
            queryable = a.declare_queryable("bench/q", lambda q: q.reply("bench/q", b"1"))
            wait_for(lambda: _timed_get(b, "bench/q", liveliness=False)[1], what="queryable")
            rtt, _ = _timed_get(b, "bench/q", liveliness=False)
            queryable.undeclare()
            t0 = time.perf_counter()
            a.close()
            wait_for(lambda: feed.alive is False, what="gone")
            gone = time.perf_counter() - t0
            got, n = _timed_get(b, keys("p").carrier_alive)
            assert n == 0
            pub.close()
    finally:
        b.close()
    return gone, present, got, rtt


def _link_drop() -> float | None:
    pa = free_port()
    a = peer(listen=[endpoint(pa)])
    events: list[tuple[float, str]] = []
    lock = threading.Lock()

    def on(sample: zenoh.Sample) -> None:
        with lock:
            events.append((time.perf_counter(), "PUT" if sample.kind == zenoh.SampleKind.PUT else "DELETE"))

    with LinkCut(pa) as link:
        b = peer(connect=[link.endpoint])
        try:
            token = a.liveliness().declare_token(keys("p").carrier_alive)
            sub = b.liveliness().declare_subscriber(keys("p").carrier_alive, on, history=True)
            wait_for(lambda: events, what="PUT")
            link.cut()
            try:
                wait_for(lambda: len(events) >= 3, timeout_s=5.0, what="DELETE and PUT")
            except AssertionError:
                return None
            finally:
                sub.undeclare()
                token.undeclare()
            (t_del, k1), (t_put, k2) = events[1], events[2]
            assert (k1, k2) == ("DELETE", "PUT"), events
            return t_put - t_del
        finally:
            b.close()
            a.close()


@click.command()
@click.option("--trials", default=20, show_default=True)
def main(trials: int) -> None:
    """Print the median and max of each measurement over ``trials``."""
    gone, present, get, rtt, drop = [], [], [], [], []
    misses = 0
    for _ in range(trials):
        for xs, x in zip((gone, present, get, rtt), _close_to_gone()):
            xs.append(x)
        d = _link_drop()
        if d is None:
            misses += 1
        else:
            drop.append(d)
    for name, xs in (("close -> gone", gone), ("get, token present", present), ("get, no token", get),
                     ("query round trip", rtt), ("link drop: DELETE -> PUT", drop)):
        ms = np.array(xs) * 1e3
        print(f"{name:26} median {np.median(ms):7.2f} ms   max {ms.max():7.2f} ms   (n={len(xs)})")
    print(f"link drops without a DELETE: {misses} of {trials}")


if __name__ == "__main__":
    main()
