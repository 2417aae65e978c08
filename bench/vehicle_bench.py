"""Benchmarks of the mock vehicle. Prints a table; never run as a test.

1. Setpoint throughput: a separate sender process blasts SET_POSITION_TARGET_LOCAL_NED at a
   fixed rate for a second; the vehicle (in this process, speed 1) must accept every one of them
   and keep its 30 Hz LOCAL_POSITION_NED stream on time meanwhile. The highest rate with
   >= 99.5 % accepted and >= 27 Hz of LOCAL_POSITION_NED is "processed without falling behind".
2. CPU use of a vehicle process (``python -m sim.vehicle.cli``) at the default stream rates,
   for several speed factors, with a 20 Hz (simulated) setpoint stream and a client heartbeat.
3. The same scripted offboard flight (60 s simulated by default) at speed 20 and at speed 1,
   one after the other: wall time of each and the distance between their end positions. The
   vehicle is deterministic for setpoints that arrive at the same physics step; what remains is
   the client's timing, quantised to steps of 5 ms simulated (0.25 ms wall at speed 20).

Usage: ``python -m bench.vehicle_bench [--quick] [--flight-s 60] [--json out.json]``.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import click
import numpy as np

from sim.net import wait_for
from sim.vehicle.mock import PHYSICS_DT_S, MockVehicle, VehicleOptions, spawn_process
from sim.testing.probe import Probe, connect, sleep_until, start_offboard

CLOCK_TICKS_PER_S = os.sysconf("SC_CLK_TCK")

SENDER = r"""
import socket, sys, time
from mission.mavlink.env import mavlink
port, rate, duration = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
mav = mavlink.MAVLink(None, 255, 190)
nan = float("nan")
msg = mavlink.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, 3527, nan, nan, nan, 0.0, 0.0, 0.0,
                                                            nan, nan, nan, nan, nan)
data = bytes(msg.pack(mav))
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sent, t0 = 0, time.monotonic()
while True:
    elapsed = time.monotonic() - t0
    if elapsed >= duration:
        break
    due = int(elapsed * rate)
    while sent < due:
        sock.sendto(data, ("127.0.0.1", port))
        sent += 1
    time.sleep(0.0005)
print(sent)
"""


@dataclass
class ThroughputRow:
    rate_hz: float
    sent: int
    accepted: int
    position_stream_hz: float  # LOCAL_POSITION_NED received during the blast (30 when on time)

    @property
    def ok(self) -> bool:
        return self.accepted >= 0.995 * self.sent and self.position_stream_hz >= 27.0


def setpoint_throughput(rates_hz: list[float], duration_s: float = 1.0) -> list[ThroughputRow]:
    """Accepted setpoints for each sender rate [Hz wall], vehicle at speed 1 in this process."""
    rows = []
    for rate in rates_hz:
        with Probe() as probe, MockVehicle(VehicleOptions(target=f"127.0.0.1:{probe.port}")) as vehicle:
            connect(probe)
            before = vehicle.counters["setpoints_accepted"]
            sender = subprocess.Popen([sys.executable, "-c", SENDER, str(vehicle.port), str(rate), str(duration_s)],
                                      stdout=subprocess.PIPE, text=True)
            time.sleep(0.3)  # the sender's start-up
            mark, t0 = probe.mark(), time.monotonic()
            time.sleep(duration_s / 2)
            stream_hz = len(probe.messages("LOCAL_POSITION_NED", after=mark)) / (time.monotonic() - t0)
            sent = int(sender.communicate(timeout=30)[0].strip())
            time.sleep(0.3)  # let the socket buffer drain
            rows.append(ThroughputRow(rate, sent, vehicle.counters["setpoints_accepted"] - before, stream_hz))
    return rows


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS_PER_S  # utime + stime


@dataclass
class CpuRow:
    speed: float
    cpu_percent: float
    rx_msgs_per_wall_s: float


def cpu_use(speeds: list[float], duration_s: float = 3.0) -> list[CpuRow]:
    """CPU of a vehicle process at the default streams, with a 20 Hz simulated setpoint stream."""
    rows = []
    for speed in speeds:
        with Probe() as probe:
            process, port = spawn_process(["--mavlink", "127.0.0.1:0", "--target", f"127.0.0.1:{probe.port}",
                                           "--speed", str(speed), "--status-every", "0"], stderr=subprocess.DEVNULL)
            try:
                connect(probe)
                with start_offboard(probe, (0.0, 0.0, -0.5), period_s=0.05 / speed):
                    time.sleep(0.5)
                    cpu0, rx0, t0 = _cpu_s(process.pid), probe.received, time.monotonic()
                    time.sleep(duration_s)
                    cpu1, rx1, t1 = _cpu_s(process.pid), probe.received, time.monotonic()
            finally:
                process.terminate()
                process.wait(timeout=10)
        rows.append(CpuRow(speed, 100.0 * (cpu1 - cpu0) / (t1 - t0), (rx1 - rx0) / (t1 - t0)))
    return rows


FLIGHT_SCRIPT = [(0.0, (0.0, 0.0, -2.0)), (3.0, (2.0, 0.0, 0.0)), (13.0, (0.0, 2.0, -0.5)), (23.0, (-2.0, 0.0, 0.5)),
                 (33.0, (0.0, -1.5, 0.0)), (43.0, (1.0, 1.0, -0.3)), (53.0, (0.0, 0.0, 0.0))]


@dataclass
class FlightRow:
    speed: float
    flight_s: float
    wall_s: float
    end_ned_m: tuple[float, float, float]


def scripted_flight(speed: float, flight_s: float, out: dict[float, FlightRow]) -> None:
    """Arm in OFFBOARD, then change the velocity setpoint at fixed simulated times since arming."""
    scale = flight_s / 60.0
    with Probe() as probe, MockVehicle(VehicleOptions(target=f"127.0.0.1:{probe.port}", speed=speed)) as vehicle:
        connect(probe)
        stream = start_offboard(probe, FLIGHT_SCRIPT[0][1], period_s=min(0.05, 0.2 / speed))
        t_armed = vehicle.event_time("Armed by external command")
        assert t_armed is not None
        wall0 = time.monotonic()
        with stream:
            climb_s = FLIGHT_SCRIPT[1][0]  # the climb keeps its length (PX4's response needs it to get clear of the ground)
            for t_change, velocity in FLIGHT_SCRIPT[1:]:
                sleep_until(vehicle.clock, t_armed + climb_s + (t_change - climb_s) * scale)
                stream.set(send_now=True, velocity_ned_m_s=velocity)
            sleep_until(vehicle.clock, t_armed + flight_s)
            wall_s = time.monotonic() - wall0
            end = wait_for(vehicle.when(lambda s: s.t_s >= t_armed + flight_s + 2.0), 10.0, "s.t_s >= t_armed + flight_s + 2.0")
        assert end is not None and end.mode == "OFFBOARD" and end.armed, (end.mode if end else None)
        out[speed] = FlightRow(speed, flight_s, wall_s, tuple(float(x) for x in end.position_ned_m))  # type: ignore[arg-type]


def flights(speeds: list[float], flight_s: float) -> dict[float, FlightRow]:
    """One flight after the other, so that they do not compete for the CPU (and the GIL)."""
    out: dict[float, FlightRow] = {}
    for speed in speeds:
        scripted_flight(speed, flight_s, out)
    return out


def _table(title: str, header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    line = lambda cells: "  ".join(c.rjust(w) for c, w in zip(cells, widths))  # noqa: E731
    return "\n".join([title, line(header), line(["-" * w for w in widths]), *map(line, rows), ""])


@click.command()
@click.option("--quick", is_flag=True, help="Fewer rates and speeds; a 12 s flight instead of 60 s.")
@click.option("--flight-s", type=float, default=None, help="Simulated length of the scripted flight [s] (default 60).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write the results as JSON.")
def main(quick: bool, flight_s: float | None, json_path: Path | None) -> None:
    """Benchmark the mock vehicle: setpoint throughput, CPU use, sped-up flight fidelity."""
    rates = [500.0, 2000.0, 5000.0] if quick else [200.0, 1000.0, 5000.0, 20000.0, 50000.0]
    throughput = setpoint_throughput(rates)
    best = max((r.rate_hz for r in throughput if r.ok), default=0.0)
    click.echo(_table(f"Setpoint throughput (vehicle at speed 1; highest rate kept up with: {best:g} Hz)",
                      ["rate Hz", "sent", "accepted", "LOCAL_POSITION_NED Hz", "kept up"],
                      [[f"{r.rate_hz:g}", str(r.sent), str(r.accepted), f"{r.position_stream_hz:.1f}", "yes" if r.ok else "NO"]
                       for r in throughput]))
    cpu = cpu_use([1.0, 20.0] if quick else [1.0, 5.0, 20.0, 50.0])
    click.echo(_table("CPU of a vehicle process at the default stream rates (+20 Hz simulated setpoints)",
                      ["speed", "CPU %", "msgs/s wall"],
                      [[f"{r.speed:g}", f"{r.cpu_percent:.1f}", f"{r.rx_msgs_per_wall_s:.0f}"] for r in cpu]))
    length_s = flight_s if flight_s is not None else (12.0 if quick else 60.0)
    flown = flights([20.0, 1.0], length_s)
    ref = np.array(flown[1.0].end_ned_m)
    changes = np.diff(np.array([v for _, v in FLIGHT_SCRIPT]), axis=0)
    bound_m = float(np.linalg.norm(changes, axis=1).sum() * PHYSICS_DT_S)
    click.echo(_table(f"Scripted {length_s:g} s offboard flight (end-position difference vs speed 1; each physics "
                      f"step of client timing error per setpoint change adds up to {bound_m:.3f} m)",
                      ["speed", "wall s", "end N", "end E", "end D", "diff m"],
                      [[f"{r.speed:g}", f"{r.wall_s:.2f}", *(f"{x:.3f}" for x in r.end_ned_m),
                        f"{np.linalg.norm(np.array(r.end_ned_m) - ref):.3f}"] for r in flown.values()]))
    if json_path is not None:
        json_path.write_text(json.dumps({
            "throughput": [asdict(r) | {"ok": r.ok} for r in throughput], "best_rate_hz": best,
            "cpu": [asdict(r) for r in cpu], "flights": [asdict(r) for r in flown.values()]}, indent=2))


if __name__ == "__main__":
    main()
