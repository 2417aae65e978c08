"""End-to-end latency and setpoint stream of the real controller loop (``bench`` sections e2e, stream).

This process plays the carrier (a :class:`~mission.bus.bridge.CarrierPublisher` putting a
:class:`~mission.bus.wire.CarrierState` at random intervals around ``1 / carrier_rate_hz``, each
stamped ``t_pub`` just before publishing) and the vehicle (:class:`sim.testing.fake_px4.FakePx4`
with the kernel's receive stamp of every datagram); a child process (:mod:`bench.e2e_child`) runs
the real :class:`~mission.controller.MissionController` with ``marsupial run``'s wiring and records
every tick through ``on_tick``. The k-th setpoint to arrive is the k-th sent (checked by its
``time_boot_ms``). Per carrier sample, the first tick that used it gives ``raw`` (arrival - t_pub),
``wait`` (tick start - receipt) and ``seen = raw - wait`` [ms], the figure held against the
targets, split into the Zenoh leg, observe, step and send -> arrival; only samples first used
while RIDING count. The stream figures (rate, jitter p99, CPU share) come from the same runs.
Method in full: docs/benchmarks.md.
"""
from __future__ import annotations

import contextlib
import json
import random
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import click
import numpy as np
import zenoh

from bench.e2e_child import PAIR
from bench.floor import mavlink_ping, percentiles_ms, zenoh_ping
from mission.mavlink import px4
from sim.testing.fake_px4 import FakePx4
from sim.net import free_port

ROOT = Path(__file__).resolve().parents[1]
CARRIER_NED_M = (0.0, 0.0, 0.0)  # the carrier stands still, 30 m from the demo's target


def stamping_vehicle(controller_port: int, position_ned_m: tuple[float, float, float]) -> FakePx4:
    """The bench's vehicle: a fake PX4 armed in OFFBOARD at ``position_ned_m``, HEARTBEAT at
    5 Hz (and at once after a command, which it obeys), LOCAL_POSITION_NED at 50 Hz, with kernel
    receive stamps of everything the controller sends."""
    vehicle = FakePx4(controller_port, heartbeat_hz=5.0, position_hz=50.0, position_ned_m=position_ned_m,
                      velocity_ned_m_s=(0.0, 0.0, 0.0), rx_stamps=True)
    vehicle.armed, vehicle.custom_mode = True, px4.custom_mode_of("OFFBOARD")
    vehicle.on_command = FakePx4.obey_and_beat
    return vehicle


class ScriptedCarrier:
    """Publishes a still carrier's state at random intervals; ``published[seq]`` = t_pub [ns realtime]."""

    def __init__(self, session: zenoh.Session, rate_hz: float, seed: int = 1) -> None:
        from mission.bus.bridge import CarrierPublisher

        self.publisher = CarrierPublisher(session, PAIR)
        self.rate_hz = rate_hz
        self.published: dict[int, int] = {}
        self._rng = random.Random(seed)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="carrier", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.publisher.close()

    def _run(self) -> None:
        from mission.bus.wire import CarrierState

        t0, seq, still = time.monotonic(), 0, np.zeros(3)
        while not self._stop.is_set():
            seq += 1
            state = CarrierState(stamp_s=time.monotonic() - t0, seq=seq, frame="local_ned",
                                 position=np.asarray(CARRIER_NED_M), velocity_ned_m_s=still, yaw_rad=0.0)
            t_pub = time.time_ns()
            self.publisher.publish(state)
            self.published[seq] = t_pub
            self._stop.wait(self._rng.uniform(0.5, 1.5) / self.rate_hz)


@dataclass
class ControllerRun:
    """What one controller run measured (see the module docstring)."""

    rate_hz: float
    e2e_raw: dict
    e2e_seen: dict
    legs: dict  # p50/p99 of the Zenoh leg, the tick wait, and tick start -> arrival (compute + send)
    stream: dict
    child: dict  # cpu share, overruns, peak RSS, counters
    mismatches: int
    samples_unused: int
    notes: list[str] = field(default_factory=list)


def run_controller(rate_hz: float, duration_s: float, carrier_rate_hz: float = 30.0, profile: str = "",
                   flight_data: str = "none") -> ControllerRun:
    """Fly the real controller loop at ``rate_hz`` for ``duration_s`` of RIDING; measure it.

    ``profile``: a path where the child writes cProfile statistics of its loop. ``flight_data``:
    what the flight record feeds besides record.csv ("none", "mcap", or "live": flight.mcap and
    the live server, with a Foxglove viewer subscribed to every channel).
    """
    from mission.bus.bridge import open_session
    from mission.config.schema import ZenohSection

    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    dock = (CARRIER_NED_M[0], CARRIER_NED_M[1], CARRIER_NED_M[2] - 1.5)  # demo.toml dock offset
    with tempfile.TemporaryDirectory(prefix="bench-e2e-") as tmp, contextlib.ExitStack() as stack:
        out_path = Path(tmp) / "child.json"
        session = open_session(ZenohSection(listen=[endpoint], rendezvous=None))
        stack.callback(session.close)
        carrier = ScriptedCarrier(session, carrier_rate_hz)
        carrier.start()
        stack.callback(carrier.close)
        child = subprocess.Popen(
            [sys.executable, "-m", "bench.e2e_child", "--rate", str(rate_hz), "--duration", str(duration_s),
             "--zenoh-connect", endpoint, "--log-dir", tmp, "--out", str(out_path), "--profile", profile,
             "--flight-data", flight_data],
            stdout=subprocess.PIPE, text=True, cwd=ROOT)
        stack.callback(lambda: (child.kill(), child.wait()) if child.poll() is None else None)
        assert child.stdout is not None
        line = child.stdout.readline().split()
        if len(line) != 3 or line[0] != "PORT":
            raise RuntimeError(f"controller child did not report its port (got {line!r})")
        if int(line[2]):
            from sim.testing.foxglove_viewer import LiveViewer

            stack.enter_context(LiveViewer(f"ws://127.0.0.1:{int(line[2])}"))
        vehicle = stack.enter_context(stamping_vehicle(int(line[1]), dock))
        child.wait(timeout=duration_s + 60.0)
        if child.returncode != 0:
            raise RuntimeError(f"controller child exited with code {child.returncode}")
        result = json.loads(out_path.read_text())
    arrivals = [(stamp, int(m.time_boot_ms)) for stamp, m in vehicle.stamped
                if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED"]
    return analyse(rate_hz, result, carrier.published, arrivals)


def analyse(rate_hz: float, child: dict, published: dict[int, int], arrivals: list[tuple[int, int]]) -> ControllerRun:
    """Pair sends with arrivals, samples with their first use; compute the figures."""
    # [tick start, seq used, its receipt, send returned, send time on the link clock [ms], riding,
    #  feed read, send called] (times [ns] realtime)
    sends = child.pop("sends")
    start_ns, end_ns = child["window_ns"]
    window_ticks = [t for t in child.pop("ticks", []) if start_ns <= t[0] <= end_ns]
    n = min(len(sends), len(arrivals))
    notes = []
    if len(sends) != len(arrivals):
        notes.append(f"{len(sends)} setpoints sent, {len(arrivals)} arrived")
    mismatches = sum(1 for s, a in zip(sends[:n], arrivals[:n]) if not 0 <= s[4] - a[1] <= 5)
    raw, seen, zen, wait, compute = [], [], [], [], []
    observe, step, send, send_call = [], [], [], []
    used: set[int] = set()
    window_arrivals = []
    for s, (t_arr, _) in zip(sends[:n], arrivals[:n]):
        tick_ns, seq, rx_ns, sent_ns, _, riding, observed_ns, send_ns = s
        in_window = riding and start_ns <= tick_ns <= end_ns
        if in_window:
            window_arrivals.append(t_arr)
            observe.append(observed_ns - tick_ns)
            step.append(send_ns - observed_ns)
            send.append(t_arr - send_ns)
            send_call.append(sent_ns - send_ns)
        if seq in used or seq not in published:
            continue
        used.add(seq)
        if not in_window:
            continue
        t_pub = published[seq]
        raw.append(t_arr - t_pub)
        wait.append(tick_ns - rx_ns)
        seen.append(t_arr - t_pub - (tick_ns - rx_ns))
        zen.append(rx_ns - t_pub)
        compute.append(t_arr - tick_ns)
    in_window_pubs = [seq for seq, t in published.items() if start_ns <= t <= end_ns]
    unused = sum(1 for seq in in_window_pubs if seq not in used)
    arr = np.asarray(window_arrivals, dtype=float)
    period_ns = 1e9 / rate_hz
    if arr.size > 2:
        dt = np.diff(arr)
        jitter = np.abs(dt - period_ns)
        stream = {"asked_hz": rate_hz, "achieved_hz": float((arr.size - 1) / ((arr[-1] - arr[0]) / 1e9)),
                  "jitter_p50_ms": float(np.percentile(jitter, 50) / 1e6),
                  "jitter_p99_ms": float(np.percentile(jitter, 99) / 1e6),
                  "max_interval_ms": float(dt.max() / 1e6), "setpoints": int(arr.size)}
    else:
        stream = {"asked_hz": rate_hz, "achieved_hz": None, "jitter_p50_ms": None, "jitter_p99_ms": None,
                  "max_interval_ms": None, "setpoints": int(arr.size)}
    legs = {name: percentiles_ms(v) for name, v in
            (("zenoh", zen), ("wait", wait), ("tick_to_arrival", compute),
             # every tick of the window: where tick_to_arrival goes
             ("observe", observe), ("step", step), ("send_to_arrival", send), ("send_call", send_call),
             # every tick of the window, start to the end of its record (on_tick), and the loop
             # thread's CPU time per period (other processes' load excluded)
             ("tick", [t[1] for t in window_ticks]), ("tick_cpu", [t[2] for t in window_ticks]))}
    return ControllerRun(rate_hz=rate_hz, e2e_raw=percentiles_ms(raw), e2e_seen=percentiles_ms(seen), legs=legs,
                         stream=stream, child=child, mismatches=mismatches, samples_unused=unused, notes=notes)


@click.command()
@click.option("--rate", type=float, default=50.0, show_default=True, help="Controller rate [Hz].")
@click.option("--duration", type=float, default=5.0, show_default=True, help="Measured RIDING time [s].")
@click.option("--profile", default="", help="Write cProfile statistics of the controller loop here.")
@click.option("--floor/--no-floor", default=True, show_default=True, help="Measure the transport floor first.")
def main(rate: float, duration: float, profile: str, floor: bool) -> None:
    """End-to-end bench, one controller run (see the module docstring); prints JSON."""
    if floor:
        click.echo(f"zenoh ping, 2 processes {zenoh_ping(500)}")
        click.echo(f"zenoh ping, 1 process {zenoh_ping(500, two_processes=False)}")
        click.echo(f"mavlink ping {mavlink_ping(500)}")
    r = run_controller(rate, duration, profile=profile)
    click.echo(json.dumps({k: v for k, v in r.__dict__.items()}, indent=1, default=str))


if __name__ == "__main__":
    main()
