"""The transport floor of the end-to-end figures: Zenoh-only and MAVLink-only one-way pings.

Measured in the same run and at the same cadence as the controller runs of :mod:`bench.e2e` (an
idle process wakes up slower: a ping every 33 ms costs about twice one every 4 ms on this kind
of machine):

* Zenoh: ``put`` of a carrier-state-sized payload on one session -> subscriber callback on a
  second session in a second process (as the controller's is), over loopback TCP, express,
  congestion control DROP like our publishers;
* MAVLink: pymavlink encode of a SET_POSITION_TARGET_LOCAL_NED + ``sendto`` -> kernel receive
  stamp on a second socket.

Floor = Zenoh + MAVLink, per percentile. ``python -m bench.floor ping-subscriber`` is the Zenoh
ping's child process (internal).
"""
from __future__ import annotations

import contextlib
import json
import random
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import click
import numpy as np
import zenoh

from mission.mavlink import setpoints
from mission.mavlink.env import mavlink
from sim.net import enable_rx_stamps, free_port, recv_stamped, wait_for

ROOT = Path(__file__).resolve().parents[1]
PING_KEY = "marsupial/bench/ping"
WARMUP_PINGS = 20  # the first few warm caches and the socket; not counted


def percentiles_ms(values_ns: Any) -> dict[str, float | int | None]:
    """p50, p99, max [ms] and count of a sequence of durations [ns]."""
    a = np.asarray(values_ns, dtype=float)
    if a.size == 0:
        return {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
    return {"n": int(a.size), "p50_ms": float(np.percentile(a, 50) / 1e6), "p99_ms": float(np.percentile(a, 99) / 1e6),
            "max_ms": float(a.max() / 1e6)}


def mavlink_ping(samples: int, mean_interval_s: float = 0.004) -> dict:
    """One-way MAVLink-only latency: encode + sendto -> kernel receive stamp, on loopback."""
    codec = mavlink.MAVLink(None, srcSystem=1, srcComponent=mavlink.MAV_COMP_ID_ONBOARD_COMPUTER)
    rx, tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM), socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    enable_rx_stamps(rx)
    tx.bind(("127.0.0.1", 0))
    address = rx.getsockname()
    lat = []
    try:
        for i in range(samples + WARMUP_PINGS):
            t0 = time.time_ns()
            msg = mavlink.MAVLink_set_position_target_local_ned_message(
                i, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, setpoints.TYPE_MASK_VELOCITY, 0.0, 0.0, 0.0, 0.5, -0.25, 0.0,
                0.0, 0.0, 0.0, 0.0, 0.0)
            tx.sendto(msg.pack(codec), address)
            _, t_rx, _ = recv_stamped(rx)
            if i >= WARMUP_PINGS:
                lat.append(t_rx - t0)
            time.sleep(random.uniform(0.5, 1.5) * mean_interval_s)
    finally:
        rx.close()
        tx.close()
    return percentiles_ms(lat)


def _ping_subscriber(session: zenoh.Session, arrivals: dict[int, int]) -> Any:
    def on_sample(sample: zenoh.Sample) -> None:
        t = time.time_ns()
        arrivals[int.from_bytes(sample.payload.to_bytes()[:8], "big")] = t

    return session.declare_subscriber(PING_KEY, on_sample)


def zenoh_ping(samples: int, mean_interval_s: float = 0.004, payload_bytes: int = 140,
               two_processes: bool = True) -> dict:
    """One-way Zenoh-only latency: ``put`` on one session -> callback on another (loopback TCP).

    The subscriber's session is in a child process (as the controller's is) unless
    ``two_processes`` is False (both sessions in this process).
    """
    from mission.bus.bridge import open_session
    from mission.config.schema import ZenohSection

    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    arrivals: dict[int, int] = {}
    sent: dict[int, int] = {}
    with tempfile.TemporaryDirectory(prefix="bench-ping-") as tmp, contextlib.ExitStack() as stack:
        a = open_session(ZenohSection(listen=[endpoint], rendezvous=None))
        stack.callback(a.close)
        out_path = Path(tmp) / "arrivals.json"
        child = None
        if two_processes:
            child = subprocess.Popen([sys.executable, "-m", "bench.floor", "ping-subscriber", endpoint,
                                      "--out", str(out_path)], stdin=subprocess.PIPE, cwd=ROOT)
            stack.callback(lambda: child.kill() if child.poll() is None else None)
        else:
            b = open_session(ZenohSection(connect=[endpoint], rendezvous=None))
            stack.callback(b.close)
            sub = _ping_subscriber(b, arrivals)
            stack.callback(sub.undeclare)
        pub = a.declare_publisher(PING_KEY, congestion_control=zenoh.CongestionControl.DROP, express=True)
        stack.callback(pub.undeclare)
        wait_for(lambda: pub.matching_status.matching, 15.0, "the ping subscriber")
        time.sleep(0.1)  # let the route settle: pings are not retried
        pad = b"x" * (payload_bytes - 8)
        for i in range(samples + WARMUP_PINGS):
            payload = i.to_bytes(8, "big") + pad
            t0 = time.time_ns()
            pub.put(payload)
            sent[i] = t0
            time.sleep(random.uniform(0.5, 1.5) * mean_interval_s)
        time.sleep(0.1)  # the last pings in flight
        if child is not None:
            assert child.stdin is not None
            child.stdin.close()  # the child writes what it received and exits
            child.wait(timeout=15.0)
            arrivals = {int(k): v for k, v in json.loads(out_path.read_text()).items()}
    lat = [arrivals[i] - sent[i] for i in sorted(sent) if i >= WARMUP_PINGS and i in arrivals]
    out = percentiles_ms(lat)
    out["lost"] = samples - len(lat)
    return out


@click.group()
def cli() -> None:
    """Transport-floor pings (internal entry points of the bench's child processes)."""


@cli.command("ping-subscriber")
@click.argument("endpoint")
@click.option("--out", required=True, type=click.Path(dir_okay=False), help="Where to write the arrivals (JSON).")
def ping_subscriber(endpoint: str, out: str) -> None:
    """The child of :func:`zenoh_ping`: stamp every ping until stdin closes, then write them."""
    from mission.bus.bridge import open_session
    from mission.config.schema import ZenohSection

    arrivals: dict[int, int] = {}
    session = open_session(ZenohSection(connect=[endpoint], rendezvous=None))
    try:
        sub = _ping_subscriber(session, arrivals)
        sys.stdin.read()
        sub.undeclare()
    finally:
        session.close()
    Path(out).write_text(json.dumps(dict(arrivals)))


@cli.command("print")
@click.option("--samples", default=500, show_default=True)
def print_floor(samples: int) -> None:
    """Print both pings (Zenoh in 2 and in 1 process, MAVLink) at the default cadence."""
    click.echo(f"zenoh ping, 2 processes {zenoh_ping(samples)}")
    click.echo(f"zenoh ping, 1 process {zenoh_ping(samples, two_processes=False)}")
    click.echo(f"mavlink ping {mavlink_ping(samples)}")


if __name__ == "__main__":
    cli()
