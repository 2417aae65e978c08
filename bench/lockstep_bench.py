"""Lockstep demo benchmark: speed, reliability under load, and determinism.

``python -m bench.lockstep_bench`` runs ``marsupial demo`` (lockstep, the default) as a subprocess
for each pair count, ``--runs`` times, optionally with ``--busy N`` busy-loop processes loading
the CPU, and prints one table:

* real-time factor of the flight: simulated time between a pair's first and last phase line
  (``[mission X s]``) over the wall time between their arrival on the demo's stdout (start-up of
  the Python processes excluded), slowest pair of the run; and the whole demo's wall time;
* CPU: user + system seconds of the demo and all its processes (``RUSAGE_CHILDREN``, start-up
  included) per simulated second of flying (the pairs' mission clocks summed), a figure that does
  not depend on what else the machine runs, and the load average when the run started;
* P1-P3 per pair and the mission's outcome;
* determinism: the largest difference of any number in a pair's ``summary.json`` from the same
  pair in the first run of that pair count (0 means every run flew the same flight).

Run it with nothing else on the machine for the speed figures; the load average is printed.
"""
from __future__ import annotations

import json
import os
import resource
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import click

LINE = re.compile(r"^(pair\d+): \[mission\s+([0-9.]+) s")


@dataclass
class DemoRun:
    pairs: int
    wall_s: float
    exit_code: int
    speed_x: float  # slowest pair's simulated seconds per wall second over its flight
    cpu_s: float = 0.0  # user + system CPU of the demo and its processes [s]
    sim_s: float = 0.0  # simulated seconds flown, the pairs' mission clocks summed [s]
    load: float = 0.0  # 1-minute load average at the start
    summaries: dict[str, dict] = field(default_factory=dict)

    def held(self) -> str:
        """``P1 a/n P2 b/n P3 c/n``."""
        n = len(self.summaries)
        return " ".join(f"P{i} {sum(bool(s.get(f'p{i}')) for s in self.summaries.values())}/{n}" for i in (1, 2, 3))

    def cpu_per_sim_s(self) -> float:
        """CPU seconds per simulated second (inf when nothing flew)."""
        return self.cpu_s / self.sim_s if self.sim_s > 0 else float("inf")


def run_demo(pairs: int, timeout_s: float) -> DemoRun:
    """One ``marsupial demo --pairs PAIRS`` in lockstep; stdout lines timestamped as they arrive."""
    with tempfile.TemporaryDirectory(prefix="lockstep-bench-") as tmp:
        cmd = [sys.executable, "-m", "mission.cli", "demo", "--pairs", str(pairs), "--log-root", f"{tmp}/logs",
               "--plot", "", "--timeout", str(timeout_s)]
        load = os.getloadavg()[0]
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.monotonic()
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                env={**os.environ, "PYTHONUNBUFFERED": "1"})
        first: dict[str, tuple[float, float]] = {}
        last: dict[str, tuple[float, float]] = {}
        assert proc.stdout is not None
        for line in proc.stdout:
            m = LINE.match(line)
            if m:
                point = (float(m.group(2)), time.monotonic())
                first.setdefault(m.group(1), point)
                last[m.group(1)] = point
        code = proc.wait()
        wall = time.monotonic() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu_s = after.ru_utime + after.ru_stime - usage.ru_utime - usage.ru_stime
        speeds = [(last[p][0] - first[p][0]) / max(last[p][1] - first[p][1], 1e-9) for p in first if p in last]
        summaries = {}
        for d in sorted(Path(tmp, "logs").glob("pair*")):
            path = d / "summary.json"
            summaries[d.name] = json.loads(path.read_text()) if path.exists() else {}
    return DemoRun(pairs, wall, code, min(speeds) if speeds else 0.0, cpu_s=cpu_s,
                   sim_s=sum(point[0] for point in last.values()), load=load, summaries=summaries)


# Differ between runs by design: a Zenoh session id; the controller's link counters that count the
# lockstep handshake before time starts (the vehicle's hellos, resent every 50 ms of wall time
# until answered, the answers to them, the vehicle's t = 0 streams that reach the controller before
# its HEARTBEAT does, and a HEARTBEAT sent or not before the vehicle is known).
RUN_IDENTITY = {"bound_source", "rx_bytes", "rx_messages", "rx_ignored", "tx_messages", "tx_heartbeats"}


def max_difference(a: dict, b: dict, prefix: str = "") -> tuple[float, str]:
    """Largest |a - b| over the numbers of two summaries, nested ones included, and where it is
    (inf if their keys or texts differ); session identities are ignored."""
    if a.keys() != b.keys():
        return float("inf"), f"{prefix}keys"
    worst: tuple[float, str] = (0.0, "")
    for k, v in a.items():
        w = b[k]
        if k in RUN_IDENTITY:
            continue
        if isinstance(v, dict) and isinstance(w, dict):
            worst = max(worst, max_difference(v, w, f"{prefix}{k}."))
        elif isinstance(v, (int, float)) and not isinstance(v, bool) and isinstance(w, (int, float)):
            worst = max(worst, (abs(float(v) - float(w)), f"{prefix}{k}"))
        elif v != w:
            return float("inf"), f"{prefix}{k}"
    return worst


@click.command()
@click.option("--pairs", "pair_counts", default="1,3,10", show_default=True, help="Pair counts, comma-separated.")
@click.option("--runs", type=click.IntRange(1), default=1, show_default=True, help="Runs per pair count.")
@click.option("--busy", type=click.IntRange(0), default=0, show_default=True,
              help="Busy-loop processes loading the CPU meanwhile (2 = both cores of this machine).")
@click.option("--timeout", "timeout_s", type=float, default=600.0, show_default=True, help="Per demo run [s, wall].")
def main(pair_counts: str, runs: int, busy: int, timeout_s: float) -> None:
    """Benchmark the lockstep demo and print a table (see the module docstring)."""
    loops = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(busy)]
    try:
        click.echo(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start, "
                   f"{busy} busy loops")
        click.echo(f"{'pairs':>5} {'run':>4} {'load':>5} {'flight x real time':>19} {'demo wall [s]':>14} "
                   f"{'CPU s / sim s':>14} {'exit':>5}  "
                   f"{'P1-P3 (pairs held)':<22} {'max diff vs run 1':>18}")
        for pairs in (int(p) for p in pair_counts.split(",")):
            reference: DemoRun | None = None
            for i in range(1, runs + 1):
                r = run_demo(pairs, timeout_s)
                reference = reference or r
                diff, where = max((max_difference(reference.summaries.get(p, {}), s) for p, s in r.summaries.items()),
                                  default=(float("inf"), "no summary"))
                click.echo(f"{pairs:>5} {i:>4} {r.load:>5.1f} {r.speed_x:>19.1f} {r.wall_s:>14.1f} {r.cpu_per_sim_s():>14.3f} "
                           f"{r.exit_code:>5}  {r.held():<22} "
                           f"{diff:>18.3g} {where if diff else ''}")
        click.echo(f"load average {os.getloadavg()[0]:.1f} at the end")
    finally:
        for p in loops:
            p.kill()
            p.wait()


if __name__ == "__main__":
    main()
