"""Where one lockstep step goes: CPU and wake-ups of each process of a one-pair demo, per step.

``python -m bench.lockstep_profile [--runs N]`` runs ``marsupial demo --pairs 1`` (lockstep) and
samples every process of it from ``/proc`` (user + system CPU and context switches, all threads)
every few milliseconds. Over the flight only (between the first and the last phase line on the
demo's stdout, so start-up and shutdown are left out) it prints, per 20 ms controller step
(one tick of ``mission.rate_hz = 50``):

* each process's CPU [us] and voluntary context switches (a thread blocking: about one per
  wake-up, hand-off or socket wait);
* the wall time [us] of a step and the real-time factor of the flight.

The steps are sequential (the vehicle waits for the controller, which waits for the carrier), so
on an idle machine the wall time of a step is about the CPU of the three processes plus the
wake-ups between them. Both figures grow with what else the machine runs (the wall time much
more; the CPU up to 1.5x at load 7: cold caches), so the load average is printed, and
``--against DIR`` compares two checkouts fairly: each run flies this checkout's demo and DIR's
(e.g. a worktree of main) at the same moment, under the same load, and prints their ratios.
"""
from __future__ import annotations

import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import click

LINE = re.compile(r"^(pair\d+): \[mission\s+([0-9.]+) s")
STEP_S = 0.02  # the demo's controller period [s]
TCK = os.sysconf("SC_CLK_TCK")
ROOT = Path(__file__).resolve().parents[1]
SHIM = Path(__file__).resolve().parent / "thread_names"
ROLE = re.compile(r"mission\.cli (mock-vehicle|carrier|run|demo)")


def _children(pid: int) -> list[int]:
    out: list[int] = []
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as f:
                out += [int(x) for x in f.read().split()]
    except OSError:
        pass
    return out


def _sample(pid: int, threads: bool) -> dict[str, tuple[float, int]]:
    """(CPU [s], voluntary context switches) of process ``pid``: all its threads together under
    ``""``, or with ``threads`` per thread name (numbers at the end of a name dropped)."""
    out: dict[str, tuple[float, int]] = {}
    for task in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{task}/stat") as f:
            text = f.read()
        fields = text.rsplit(")", 1)[1].split()
        with open(f"/proc/{pid}/task/{task}/status") as f:
            switches = int(next(line for line in f if line.startswith("voluntary_ctxt_switches")).split()[1])
        name = re.sub(r"[-_ ]?\d+$", "", text[text.index("(") + 1:text.rindex(")")]) if threads else ""
        cpu, sw = out.get(name, (0.0, 0))
        out[name] = (cpu + (int(fields[11]) + int(fields[12])) / TCK, sw + switches)
    return out


@dataclass
class Sampler:
    """Polls every descendant of ``root`` every ``period_s`` [s, wall]."""

    root: int
    threads: bool = False
    period_s: float = 0.005
    names: dict[int, str] = field(default_factory=dict)
    samples: list[tuple[float, dict[int, dict[str, tuple[float, int]]]]] = field(default_factory=list)
    stop: threading.Event = field(default_factory=threading.Event)

    def run(self) -> None:
        while not self.stop.is_set():
            now, snap = time.monotonic(), {}
            todo = [self.root]
            while todo:
                pid = todo.pop()
                todo += _children(pid)
                try:
                    if pid not in self.names:
                        with open(f"/proc/{pid}/cmdline") as f:
                            m = ROLE.search(f.read().replace("\0", " "))
                        if m and (m.group(1) != "demo" or pid == self.root):  # (a child shows the demo's command line until its exec)
                            self.names[pid] = m.group(1)
                    snap[pid] = _sample(pid, self.threads)
                except (OSError, StopIteration, ValueError):  # gone, or not started yet
                    pass
            self.samples.append((now, snap))
            self.stop.wait(self.period_s)

    def at(self, t: float) -> dict[int, dict[str, tuple[float, int]]]:
        """Each process's sample nearest wall time ``t`` [s, monotonic]."""
        out: dict[int, dict[str, tuple[float, int]]] = {}
        for _, snap in sorted(self.samples, key=lambda s: -abs(s[0] - t)):
            out.update(snap)
        return out


def profile_once(threads: bool, root: Path = ROOT, demo_args: tuple[str, ...] = ()) -> dict[str, float]:
    """One demo of the checkout at ``root`` (``demo_args``: more of ``marsupial demo``'s options,
    e.g. ``--config``); per-step figures (see the module docstring)."""
    with tempfile.TemporaryDirectory(prefix="lockstep-profile-") as tmp:
        cmd = [sys.executable, "-m", "mission.cli", "demo", "--pairs", "1", "--log-root", f"{tmp}/logs", "--plot", "",
               *demo_args]
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONPATH": str(root)}
        if threads:
            env["PYTHONPATH"] = os.pathsep.join([str(root), str(SHIM)])
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env, cwd=root)
        sampler = Sampler(proc.pid, threads)
        thread = threading.Thread(target=sampler.run, daemon=True)
        thread.start()
        first: tuple[float, float] | None = None
        last: tuple[float, float] | None = None
        assert proc.stdout is not None
        for line in proc.stdout:
            m = LINE.match(line)
            if m:
                point = (float(m.group(2)), time.monotonic())
                first, last = first or point, point
        code = proc.wait()
        sampler.stop.set()
        thread.join()
    if first is None or last is None or last[0] <= first[0]:
        raise click.ClickException(f"the demo printed no flight (exit {code})")
    steps = (last[0] - first[0]) / STEP_S
    a, b = sampler.at(first[1]), sampler.at(last[1])
    out = {"steps": steps, "wall_us": (last[1] - first[1]) / steps * 1e6, "x_real_time": (last[0] - first[0]) / (last[1] - first[1])}
    for pid, per_thread in b.items():
        for thread_name, (cpu, switches) in per_thread.items():
            cpu0, switches0 = a.get(pid, {}).get(thread_name, (0.0, 0))
            name = f"{sampler.names.get(pid, str(pid))} {thread_name}".strip()
            out[f"{name} CPU us"] = out.get(f"{name} CPU us", 0.0) + (cpu - cpu0) / steps * 1e6
            out[f"{name} switches"] = out.get(f"{name} switches", 0.0) + (switches - switches0) / steps
    return out


def profile_pair(first: Path, second: Path, demo_args: tuple[str, ...] = ()) -> tuple[dict[str, float], dict[str, float]]:
    """One demo of each checkout flown at the same moment (so both meet the same load): their
    :func:`profile_once` figures; ``click.ClickException`` if either failed."""
    out: dict[Path, dict[str, float]] = {}
    workers = [threading.Thread(target=lambda r=r: out.__setitem__(r, profile_once(False, r, demo_args)))
               for r in (first, second)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    if len(out) < 2:
        raise click.ClickException("a demo of the pair failed (see above)")
    return out[first], out[second]


def _median(values: list[float]) -> float:
    return statistics.median(values)


def _all_cpu(result: dict[str, float]) -> float:
    return sum(v for k, v in result.items() if k.endswith("CPU us"))


def paired(runs: int, other: Path) -> None:
    """``runs`` pairs of demos, this checkout's and ``other``'s flown at the same moment: per pair
    the ratio (this / other) of all CPU and of the wall time per step, and each side's figures."""
    click.echo(f"paired runs: this checkout ({ROOT}) / {other}; per 20 ms step")
    ratios: dict[str, list[float]] = {"all CPU": [], "wall": []}
    for i in range(runs):
        mine, theirs = profile_pair(ROOT, other)
        ratios["all CPU"].append(_all_cpu(mine) / _all_cpu(theirs))
        ratios["wall"].append(mine["wall_us"] / theirs["wall_us"])
        click.echo(f"  pair {i + 1} (load {os.getloadavg()[0]:.1f}): all CPU {_all_cpu(mine):.0f} / {_all_cpu(theirs):.0f} us, "
                   f"wall {mine['wall_us']:.0f} / {theirs['wall_us']:.0f} us, " + ", ".join(
                       f"{k.split()[0]} {mine.get(k, 0.0):.0f} / {theirs.get(k, 0.0):.0f}" for k in sorted(mine)
                       if k.endswith("CPU us") and not k.startswith("demo")))
    for name, values in ratios.items():
        click.echo(f"{name} ratio (this / other): " + " ".join(f"{v:.2f}" for v in values) + f"; median {_median(values):.3f}")


@click.command()
@click.option("--runs", type=click.IntRange(1), default=3, show_default=True, help="Demo runs (the table shows each and the median).")
@click.option("--threads", is_flag=True, help="Per thread (names each OS thread after its Python thread, "
              "bench/thread_names/sitecustomize.py).")
@click.option("--against", "other", type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="Another checkout (e.g. a worktree of main): fly both at the same moment, print the ratios.")
def main(runs: int, threads: bool, other: Path | None) -> None:
    """Profile the one-pair lockstep demo per step and print a table (see the module docstring)."""
    click.echo(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start")
    if other is not None:
        paired(runs, other.resolve())
        click.echo(f"load average {os.getloadavg()[0]:.1f} at the end")
        return
    results = []
    for i in range(runs):
        results.append(profile_once(threads))
        click.echo(f"  run {i + 1}: {results[-1]['x_real_time']:.1f}x real time, load {os.getloadavg()[0]:.1f}", err=True)
    keys = sorted({k for r in results for k in r if k != "steps"}, key=lambda k: (k.split()[0], -results[0].get(k, 0.0)))
    keys = [k for k in keys if k.endswith("_us") or k == "x_real_time" or max(r.get(k, 0.0) for r in results) >= 1.0]
    click.echo(f"per 20 ms step, over the flight ({results[0]['steps']:.0f} steps); columns: each run, min, median")
    rows = [(k, [r.get(k, 0.0) for r in results]) for k in keys]
    rows.append(("all CPU us", [_all_cpu(r) for r in results]))
    width = max(len(k) for k, _ in rows) + 2
    for k, values in rows:
        click.echo(f"{k:<{width}}" + "".join(f"{v:>9.1f}" for v in values)
                   + f"{min(values):>10.1f}{_median(values):>9.1f}")
    click.echo(f"load average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
