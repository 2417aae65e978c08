"""End-to-end latency and setpoint stream of the real controller loop (issue 7, sections 2 and 3).

Method
------
Two processes on loopback, as deployed:

* **This process plays the carrier and the vehicle.** The carrier is a
  :class:`~mission.carrier_bridge.CarrierPublisher` on its own Zenoh session (listening on a
  free 127.0.0.1 port). It publishes a :class:`~mission.wire.CarrierState` at random intervals
  (uniform in 0.5..1.5 times ``1 / carrier_rate_hz``, 30 Hz by default like the demo's carrier,
  so samples fall at every phase of the controller's tick grid) with ``seq`` = the sample's
  number, and stamps ``t_pub`` (CLOCK_REALTIME) just before ``publish`` (JSON encoding + put). The vehicle is a raw UDP socket that speaks just
  enough PX4 (HEARTBEAT armed in OFFBOARD, LOCAL_POSITION_NED at the dock point, COMMAND_ACK
  ACCEPTED, the mode a DO_SET_MODE asks for) and takes the kernel's receive stamp of every
  datagram (SO_TIMESTAMPNS, CLOCK_REALTIME): the arrival at the vehicle's socket, free of this
  process's own scheduling.
* **A child process** (``python -m bench.e2e --child``) runs the real
  :class:`~mission.controller.MissionController` with ``marsupial run``'s wiring (VehicleLink,
  CarrierFeed, PassengerPublisher, FlightRecorder) at the asked rate, on the demo configuration.
  Thin proxies around the link and the feed record, per tick: when it started (the loop's first
  call after its periodic wait reads ``link.state``), which carrier sample ``feed.latest()``
  returned (its ``seq`` and when the feed's Zenoh callback received it) and when
  ``send_velocity_ned`` returned. The child's clock is CLOCK_MONOTONIC at speed 1; it converts
  its stamps to CLOCK_REALTIME with an offset sampled at start (the two do not drift apart
  measurably in a run of seconds).

Matching. The k-th setpoint to arrive at the vehicle is the k-th the loop sent (loopback UDP does
not drop or reorder at these rates); the setpoint's ``time_boot_ms`` (the link clock at send) is
checked against the child's record and mismatches are counted. For every carrier sample, the
first tick that used it gives::

    raw  = arrival of that tick's setpoint - t_pub        what a user sees
    wait = tick start - receipt by the feed                the periodic loop's wait: 0..1 period
    seen = raw - wait                                      Zenoh leg + compute + send + MAVLink leg

``seen`` splits into the Zenoh leg (t_pub -> receipt) and ``tick -> arrival``, which splits
again into *observe* (``link.state`` .. ``feed.latest()``), *step* (the phases, law and filters,
until ``send_velocity_ned`` is called) and *send -> arrival* (message, encode, ``sendto``: on
loopback the kernel delivers, and stamps, inside ``sendto``).

``seen`` ("after the sample was seen") is the figure held against the targets (p50 <= 0.5 ms,
p99 <= 2 ms at 50 Hz, and at most twice the transport floor): ``raw`` cannot be lower than the
tick wait (half a period on average, 10 ms at 50 Hz), whatever the code does. Only samples
first used while the mission is RIDING (its steady phase: the law, the CBF filter, the passenger
status on Zenoh and the flight record run every tick) count.

Transport floor, measured in the same run and at the same cadence (an idle process wakes up
slower: a ping every 33 ms costs about twice one every 4 ms on this kind of machine): a
Zenoh-only ping (``put`` of a carrier-state-sized payload on one session -> subscriber callback
on a second session in a second process, as the controller's is, over loopback TCP, express,
congestion control DROP like our publishers), at the carrier's rate; and a MAVLink-only ping
(pymavlink encode of a SET_POSITION_TARGET_LOCAL_NED + ``sendto`` -> kernel receive stamp on a
second socket) at the controller's rate. Floor = Zenoh + MAVLink, per percentile.

Stream. From the same runs: the kernel arrival stamps of the setpoints sent while RIDING give
the achieved rate (count / span) and the jitter, ``|interval - 1/rate|`` (p99, ms). The child's
CPU share is ``time.process_time()`` over wall time in that window: all of its threads (loop,
link receiver and heartbeat, command worker, Zenoh's).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import random
import resource
import select
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from mission import px4
from mission.mavlink_env import mavlink
from sim.net import free_port

ROOT = Path(__file__).resolve().parents[1]
DEMO_CONFIG = ROOT / "configs" / "demo.toml"
PAIR = "bench"
CARRIER_NED_M = (0.0, 0.0, 0.0)  # the carrier stands still, 30 m from the demo's target
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)  # Linux asm-generic value (x86_64, arm64)
_STAMP_CMSG_LEN = socket.CMSG_SPACE(16)
WARMUP_S = 0.3  # of RIDING, not measured [s]



def percentiles_ms(values_ns: Any) -> dict[str, float | int | None]:
    """p50, p99, max [ms] and count of a sequence of durations [ns]."""
    a = np.asarray(values_ns, dtype=float)
    if a.size == 0:
        return {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
    return {"n": int(a.size), "p50_ms": float(np.percentile(a, 50) / 1e6), "p99_ms": float(np.percentile(a, 99) / 1e6),
            "max_ms": float(a.max() / 1e6)}


def _stamping_socket() -> socket.socket:
    """A UDP socket on 127.0.0.1 (ephemeral port) that asks the kernel for receive stamps."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    return sock


def _recv_stamped(sock: socket.socket) -> tuple[bytes, int, tuple[str, int]]:
    """One datagram, its kernel receive time [ns, CLOCK_REALTIME] and its sender."""
    data, ancillary, _flags, address = sock.recvmsg(65535, _STAMP_CMSG_LEN)
    for level, kind, payload in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(payload) >= 16:
            sec, nsec = struct.unpack("qq", payload[:16])
            return data, sec * 1_000_000_000 + nsec, address
    return data, time.time_ns(), address  # no stamp: the user-space receive time


# --------------------------------------------------------------------------- transport floor


def mavlink_ping(samples: int, mean_interval_s: float = 0.004) -> dict:
    """One-way MAVLink-only latency: encode + sendto -> kernel receive stamp, on loopback."""
    codec = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
    rx, tx = _stamping_socket(), socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.bind(("127.0.0.1", 0))
    address = rx.getsockname()
    lat = []
    try:
        for i in range(samples + 20):
            t0 = time.time_ns()
            msg = mavlink.MAVLink_set_position_target_local_ned_message(
                i, 1, 1, px4.MAV_FRAME_LOCAL_NED, px4.TYPE_MASK_VELOCITY, 0.0, 0.0, 0.0, 0.5, -0.25, 0.0,
                0.0, 0.0, 0.0, 0.0, 0.0)
            tx.sendto(msg.pack(codec), address)
            _, t_rx, _ = _recv_stamped(rx)
            if i >= 20:  # the first few warm caches and the socket
                lat.append(t_rx - t0)
            time.sleep(random.uniform(0.5, 1.5) * mean_interval_s)
    finally:
        rx.close()
        tx.close()
    return percentiles_ms(lat)


PING_KEY = f"marsupial/{PAIR}/ping"


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
    from mission.carrier_bridge import open_session
    from mission.config import ZenohSection

    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    arrivals: dict[int, int] = {}
    sent: dict[int, int] = {}
    with tempfile.TemporaryDirectory(prefix="bench-ping-") as tmp, contextlib.ExitStack() as stack:
        a = open_session(ZenohSection(listen=[endpoint], rendezvous=None))
        stack.callback(a.close)
        out_path = Path(tmp) / "arrivals.json"
        child = None
        if two_processes:
            child = subprocess.Popen([sys.executable, "-m", "bench.e2e", "--ping-subscriber", endpoint,
                                      "--out", str(out_path)], stdin=subprocess.PIPE, cwd=ROOT)
            stack.callback(lambda: child.kill() if child.poll() is None else None)
        else:
            b = open_session(ZenohSection(connect=[endpoint], rendezvous=None))
            stack.callback(b.close)
            sub = _ping_subscriber(b, arrivals)
            stack.callback(sub.undeclare)
        pub = a.declare_publisher(PING_KEY, congestion_control=zenoh.CongestionControl.DROP, express=True)
        stack.callback(pub.undeclare)
        deadline = time.monotonic() + 15.0
        while not pub.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.1)
        pad = b"x" * (payload_bytes - 8)
        for i in range(samples + 20):
            payload = i.to_bytes(8, "big") + pad
            t0 = time.time_ns()
            pub.put(payload)
            sent[i] = t0
            time.sleep(random.uniform(0.5, 1.5) * mean_interval_s)
        time.sleep(0.1)
        if child is not None:
            assert child.stdin is not None
            child.stdin.close()  # the child writes what it received and exits
            child.wait(timeout=15.0)
            arrivals = {int(k): v for k, v in json.loads(out_path.read_text()).items()}
    lat = [arrivals[i] - sent[i] for i in sorted(sent) if i >= 20 and i in arrivals]
    out = percentiles_ms(lat)
    out["lost"] = samples - len(lat)
    return out


def ping_subscriber_main(endpoint: str, out: str) -> None:
    """The child of :func:`zenoh_ping`: stamp every ping until stdin closes, then write them."""
    from mission.carrier_bridge import open_session
    from mission.config import ZenohSection

    arrivals: dict[int, int] = {}
    session = open_session(ZenohSection(connect=[endpoint], rendezvous=None))
    try:
        sub = _ping_subscriber(session, arrivals)
        sys.stdin.read()
        sub.undeclare()
    finally:
        session.close()
    Path(out).write_text(json.dumps(dict(arrivals)))


# --------------------------------------------------------------------------- warm and cold


def step_warm_cold(gap_s: float = 0.02, samples: int = 150) -> dict:
    """One RIDING tick of :func:`mission.phases.step` (law + both filters) on the demo's model,
    back to back ("warm") and after sleeping ``gap_s`` before each call ("cold", as a 50 Hz loop
    is): p50/p99 [us]. The difference is what a mostly idle periodic loop pays on this machine
    (caches, branch predictors and the core's idle state), not what the code does."""
    from mission import phases
    from mission.config import load_config
    from mission.controller import mission_model
    from mission.phases import CarrierObs, MissionState, Observation, Phase, VehicleObs

    model = mission_model(load_config(DEMO_CONFIG))
    dock = np.array([0.0, 0.0, -1.5])
    state = MissionState(phase=Phase.RIDING, x_ref=dock, e_ref=np.zeros(3), prev_dock=dock, u_ref=np.zeros(3),
                         u_cmd=np.zeros(3), start_s=0.0)
    obs = Observation(t_s=1.0, vehicle=VehicleObs(dock, np.zeros(3), True, "OFFBOARD", 0.1),
                      carrier=CarrierObs(np.zeros(3), np.zeros(3), 0.01))
    out = {}
    for name, gap, n in (("warm", 0.0, samples * 10), ("cold", gap_s, samples)):
        times = []
        for _ in range(n):
            if gap:
                time.sleep(gap)
            t0 = time.perf_counter_ns()
            phases.step(state, obs, model)
            times.append(time.perf_counter_ns() - t0)
        out[f"{name}_p50_us"] = float(np.percentile(times, 50) / 1e3)
        out[f"{name}_p99_us"] = float(np.percentile(times, 99) / 1e3)
    out["gap_s"] = gap_s
    return out


# --------------------------------------------------------------------------- the vehicle


class StampingVehicle:
    """Just enough of a PX4 on one raw UDP socket, with kernel receive stamps of setpoints.

    It stands armed in OFFBOARD at ``position_ned_m``: HEARTBEAT every ``heartbeat_s`` and at once
    after a mode change, LOCAL_POSITION_NED every ``position_s``; every COMMAND_LONG is ACCEPTED
    (DO_SET_MODE switches the mode it reports). ``arrivals`` holds ``(kernel stamp [ns realtime],
    time_boot_ms)`` of every SET_POSITION_TARGET_LOCAL_NED, in arrival order.
    """

    def __init__(self, position_ned_m: tuple[float, float, float], heartbeat_s: float = 0.2,
                 position_s: float = 0.02) -> None:
        self.sock = _stamping_socket()
        self.port = int(self.sock.getsockname()[1])
        self.position_ned_m = position_ned_m
        self.heartbeat_s, self.position_s = heartbeat_s, position_s
        self.custom_mode = px4.custom_mode_of("OFFBOARD")
        self.arrivals: list[tuple[int, int]] = []
        self._peer: tuple[str, int] | None = None
        self._tx_codec = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self._rx_codec = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self._tx_lock = threading.Lock()
        self._stop = threading.Event()
        self._t0 = time.monotonic()
        self._threads = [threading.Thread(target=self._receive, name="vehicle-rx", daemon=True),
                         threading.Thread(target=self._telemetry, name="vehicle-tx", daemon=True)]

    def start(self, controller_port: int) -> None:
        self._peer = ("127.0.0.1", controller_port)
        for t in self._threads:
            t.start()

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            if t.is_alive():
                t.join(timeout=2.0)
        self.sock.close()

    def _send(self, msg: Any) -> None:
        with self._tx_lock:
            if self._peer is not None:
                self.sock.sendto(msg.pack(self._tx_codec), self._peer)

    def _heartbeat(self) -> None:
        base_mode = 1 | 128  # CUSTOM_MODE_ENABLED | SAFETY_ARMED
        self._send(mavlink.MAVLink_heartbeat_message(px4.MAV_TYPE_QUADROTOR, px4.MAV_AUTOPILOT_PX4, base_mode,
                                                     self.custom_mode, 4, 3))

    def _telemetry(self) -> None:
        next_hb = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_hb:
                self._heartbeat()
                next_hb = now + self.heartbeat_s
            x, y, z = self.position_ned_m
            boot_ms = int((now - self._t0) * 1000) & 0xFFFFFFFF
            self._send(mavlink.MAVLink_local_position_ned_message(boot_ms, x, y, z, 0.0, 0.0, 0.0))
            self._stop.wait(self.position_s)

    def _receive(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self.sock], [], [], 0.05)
            if not ready:
                continue
            try:
                data, stamp, _ = _recv_stamped(self.sock)
            except OSError:
                continue
            try:
                messages = self._rx_codec.parse_buffer(data) or []
            except Exception:  # not ours to judge: the bench only counts setpoints
                continue
            for msg in messages:
                kind = msg.get_type()
                if kind == "SET_POSITION_TARGET_LOCAL_NED":
                    self.arrivals.append((stamp, int(msg.time_boot_ms)))
                elif kind == "COMMAND_LONG":
                    self._on_command(msg)

    def _on_command(self, msg: Any) -> None:
        if msg.command == px4.MAV_CMD_DO_SET_MODE:
            self.custom_mode = px4.encode_custom_mode(int(msg.param2), int(msg.param3))
        self._send(mavlink.MAVLink_command_ack_message(msg.command, px4.MAV_RESULT_ACCEPTED, 0, 0,
                                                       msg.get_srcSystem(), msg.get_srcComponent()))
        self._heartbeat()


# --------------------------------------------------------------------------- the carrier


class ScriptedCarrier:
    """Publishes a still carrier's state at random intervals; ``published[seq]`` = t_pub [ns realtime]."""

    def __init__(self, session: zenoh.Session, rate_hz: float, seed: int = 1) -> None:
        from mission.carrier_bridge import CarrierPublisher

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
        from mission.wire import CarrierState

        t0, seq, still = time.monotonic(), 0, np.zeros(3)
        while not self._stop.is_set():
            seq += 1
            state = CarrierState(stamp_s=time.monotonic() - t0, seq=seq, frame="local_ned",
                                 position=np.asarray(CARRIER_NED_M), velocity_ned_m_s=still, yaw_rad=0.0)
            t_pub = time.time_ns()
            self.publisher.publish(state)
            self.published[seq] = t_pub
            self._stop.wait(self._rng.uniform(0.5, 1.5) / self.rate_hz)


# --------------------------------------------------------------------------- the run


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


def run_controller(rate_hz: float, duration_s: float, carrier_rate_hz: float = 30.0, profile: str = "") -> ControllerRun:
    """Fly the real controller loop at ``rate_hz`` for ``duration_s`` of RIDING; measure it.

    ``profile``: a path where the child writes cProfile statistics of its loop.
    """
    from mission.carrier_bridge import open_session
    from mission.config import ZenohSection

    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    dock = (CARRIER_NED_M[0], CARRIER_NED_M[1], CARRIER_NED_M[2] - 1.5)  # demo.toml dock offset
    with tempfile.TemporaryDirectory(prefix="bench-e2e-") as tmp:
        out_path = Path(tmp) / "child.json"
        session = open_session(ZenohSection(listen=[endpoint], rendezvous=None))
        carrier = vehicle = child = None
        try:
            carrier = ScriptedCarrier(session, carrier_rate_hz)
            carrier.start()
            vehicle = StampingVehicle(dock)
            child = subprocess.Popen(
                [sys.executable, "-m", "bench.e2e", "--child", "--rate", str(rate_hz), "--duration", str(duration_s),
                 "--zenoh-connect", endpoint, "--log-dir", tmp, "--out", str(out_path), "--profile", profile],
                stdout=subprocess.PIPE, text=True, cwd=ROOT)
            assert child.stdout is not None
            line = child.stdout.readline().split()
            if len(line) != 2 or line[0] != "PORT":
                raise RuntimeError(f"controller child did not report its port (got {line!r})")
            vehicle.start(int(line[1]))
            child.wait(timeout=duration_s + 60.0)
            if child.returncode != 0:
                raise RuntimeError(f"controller child exited with code {child.returncode}")
            result = json.loads(out_path.read_text())
        finally:
            if child is not None and child.poll() is None:
                child.kill()
                child.wait()
            if vehicle is not None:
                vehicle.close()
            if carrier is not None:
                carrier.close()
            session.close()
    return analyse(rate_hz, result, carrier.published, vehicle.arrivals)


def analyse(rate_hz: float, child: dict, published: dict[int, int], arrivals: list[tuple[int, int]]) -> ControllerRun:
    """Pair sends with arrivals, samples with their first use; compute the figures."""
    # [tick start, seq used, its receipt, send returned, send time on the link clock [ms], riding,
    #  feed read, send called] (times [ns] realtime)
    sends = child.pop("sends")
    start_ns, end_ns = child["window_ns"]
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
             ("observe", observe), ("step", step), ("send_to_arrival", send), ("send_call", send_call))}
    return ControllerRun(rate_hz=rate_hz, e2e_raw=percentiles_ms(raw), e2e_seen=percentiles_ms(seen), legs=legs,
                         stream=stream, child=child, mismatches=mismatches, samples_unused=unused, notes=notes)


# --------------------------------------------------------------------------- the child


class _Clock:
    """The Clock protocol at speed 1 on CLOCK_MONOTONIC, convertible to CLOCK_REALTIME [ns]."""

    speed = 1.0

    def __init__(self) -> None:
        best = None
        for _ in range(50):  # the realtime - monotonic offset, from the tightest bracket
            m0 = time.monotonic_ns()
            r = time.time_ns()
            m1 = time.monotonic_ns()
            if best is None or m1 - m0 < best[0]:
                best = (m1 - m0, r - (m0 + m1) // 2)
        assert best is not None
        self._offset_ns = best[1]
        self._t0_ns = time.monotonic_ns()

    def now(self) -> float:
        return (time.monotonic_ns() - self._t0_ns) * 1e-9

    def sleep(self, duration_s: float) -> None:
        if duration_s > 0:
            time.sleep(duration_s)

    def real_ns(self, t_s: float) -> int:
        return self._t0_ns + int(round(t_s * 1e9)) + self._offset_ns

    def real_now_ns(self) -> int:
        return time.monotonic_ns() + self._offset_ns


class _Trace:
    """Per-tick stamps of the loop, taken by the proxies below (lists of tuples: cheap)."""

    def __init__(self, clock: _Clock) -> None:
        self.clock = clock
        self.controller: Any = None
        self.tick_ns = 0
        self.observed_ns = 0
        self.seq = -1
        self.rx_s = 0.0
        self.sends: list[tuple[int, int, int, int, int, bool, int, int]] = []


class _TracedLink:
    """The real VehicleLink; reading ``state`` (the tick's first call) and sending are stamped."""

    def __init__(self, link: Any, trace: _Trace) -> None:
        self._link, self._trace = link, trace

    @property
    def state(self) -> Any:
        self._trace.tick_ns = self._trace.clock.real_now_ns()
        return self._link.state

    def send_velocity_ned(self, v_ned_m_s: Any, yaw_rad: float | None = None) -> None:
        tr = self._trace
        t_send = tr.clock.real_now_ns()
        self._link.send_velocity_ned(v_ned_m_s, yaw_rad)
        now_s = tr.clock.now()
        tr.sends.append((tr.tick_ns, tr.seq, tr.clock.real_ns(tr.rx_s), tr.clock.real_ns(now_s), int(now_s * 1000),
                         tr.controller.state.phase.value == "RIDING", tr.observed_ns, t_send))

    def __getattr__(self, name: str) -> Any:
        return getattr(self._link, name)


class _TracedFeed:
    """The real CarrierFeed; ``latest()`` notes which sample the tick used."""

    def __init__(self, feed: Any, trace: _Trace) -> None:
        self._feed, self._trace = feed, trace

    def latest(self) -> Any:
        received = self._feed.latest()
        self._trace.observed_ns = self._trace.clock.real_now_ns()
        if received is not None:
            self._trace.seq, self._trace.rx_s = received.value.seq, received.rx_time_s
        return received

    def __getattr__(self, name: str) -> Any:
        return getattr(self._feed, name)


def child_main(rate_hz: float, duration_s: float, zenoh_connect: str, log_dir: str, out: str,
               profile: str = "") -> None:
    """The controller process: ``marsupial run``'s wiring with the tracing proxies."""
    from contextlib import ExitStack

    from mission.config import load_config, with_overrides
    from mission.controller import MissionController, mission_info
    from mission.log import FlightRecorder
    from mission.run_cli import mission_io

    cfg = with_overrides(load_config(DEMO_CONFIG), {
        "mission.rate_hz": rate_hz, "mission.max_duration_s": duration_s + 120.0, "zenoh.pair": PAIR,
        "zenoh.listen": [], "zenoh.connect": [zenoh_connect], "mavlink.url": "udpin:127.0.0.1:0"})
    clock = _Clock()
    trace = _Trace(clock)
    stop = threading.Event()
    window: dict[str, Any] = {}
    with ExitStack() as stack:
        recorder = FlightRecorder(Path(log_dir) / "flight", mission_info(cfg))
        feed, publisher, link = stack.enter_context(mission_io(cfg, clock, recorder.tlog_path))
        controller = MissionController(cfg, _TracedLink(link, trace), _TracedFeed(feed, trace), clock,
                                       publisher=publisher, recorder=recorder, stop=stop)
        trace.controller = controller
        print(f"PORT {link.port}", flush=True)

        def measure_window() -> None:
            deadline = time.monotonic() + 30.0
            while controller.state.phase.value != "RIDING":
                if time.monotonic() > deadline or controller.state.phase.value in ("ABORT", "DONE"):
                    stop.set()
                    return
                time.sleep(0.001)
            time.sleep(WARMUP_S)
            window["start"] = (clock.real_now_ns(), time.process_time(), controller.ticks)
            time.sleep(duration_s)
            window["end"] = (clock.real_now_ns(), time.process_time(), controller.ticks)
            stop.set()

        watcher = threading.Thread(target=measure_window, daemon=True)
        watcher.start()
        if profile:
            import cProfile

            profiler = cProfile.Profile()
            outcome = profiler.runcall(controller.run)
            profiler.dump_stats(profile)
        else:
            outcome = controller.run()
        watcher.join(timeout=5.0)
        counters = link.counters
    if "end" not in window:
        raise SystemExit(f"the controller never rode steadily: {outcome.phase} {outcome.reason} {outcome.detail}")
    (s_ns, s_cpu, s_ticks), (e_ns, e_cpu, e_ticks) = window["start"], window["end"]
    wall_s = (e_ns - s_ns) / 1e9
    result = {
        "sends": trace.sends,
        "window_ns": [s_ns, e_ns],
        "wall_s": wall_s,
        "cpu_share": (e_cpu - s_cpu) / wall_s,
        "loop_hz": (e_ticks - s_ticks) / wall_s,
        "overruns": controller.overruns,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,  # Linux: KiB
        "tx_setpoints": counters.tx_setpoints,
        "outcome": f"{outcome.phase} {outcome.reason}",
        "feed": feed.counters,
    }
    Path(out).write_text(json.dumps(result))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description="End-to-end bench (see the module docstring).")
    ap.add_argument("--child", action="store_true", help="run as the controller process (internal)")
    ap.add_argument("--rate", type=float, default=50.0)
    ap.add_argument("--duration", type=float, default=5.0)
    ap.add_argument("--zenoh-connect", default="")
    ap.add_argument("--log-dir", default="")
    ap.add_argument("--out", default="")
    ap.add_argument("--profile", default="", help="write cProfile statistics of the loop here")
    ap.add_argument("--ping-subscriber", default="", help="run as the Zenoh ping's subscriber (internal)")
    args = ap.parse_args(argv)
    if args.ping_subscriber:
        ping_subscriber_main(args.ping_subscriber, args.out)
        return
    if args.child:
        child_main(args.rate, args.duration, args.zenoh_connect, args.log_dir, args.out, args.profile)
        return
    print("zenoh ping, 2 processes", zenoh_ping(500))
    print("zenoh ping, 1 process", zenoh_ping(500, two_processes=False))
    print("mavlink ping", mavlink_ping(500))
    r = run_controller(args.rate, args.duration, profile=args.profile)
    print(json.dumps({k: v for k, v in r.__dict__.items()}, indent=1, default=str))


if __name__ == "__main__":
    main()
