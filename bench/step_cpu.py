"""CPU per lockstep step of each process, this checkout against an earlier one, flown side by side.

``python -m bench.step_cpu [--before REF | --against DIR] [--config FILE ...] [--runs N]`` flies
the one-pair lockstep demo of each configuration (exact estimates, ``--estimate-error 0``) with
this checkout and with the earlier one (``REF`` exported from git into a temporary directory, or
the checkout ``DIR``), both at the same moment so that both see the same load, ``N`` times, and
prints per configuration the least and the median CPU [ms] (user + system, all threads) of each
process per 20 ms controller step over the flight (start-up and shutdown left out: :mod:`bench.lockstep_profile`
samples ``/proc``), before, after and their ratio. The mission controller is ``run``, the mock
vehicle ``mock-vehicle``, the carrier ``carrier``; ``all`` adds the three and the demo's own
process. CPU time depends much less on the load than wall time does (up to 1.5x at load 7: cold
caches), and the two sides share it; load only adds to it, so the least of several runs is
the steadier figure. The load average is printed.
"""
from __future__ import annotations

import os
import statistics
import subprocess
import tarfile
import tempfile
from io import BytesIO
from pathlib import Path

import click

from bench.lockstep_profile import ROOT, profile_pair

PROCESSES = ("run", "mock-vehicle", "carrier")


def export(ref: str, into: Path) -> Path:
    """The tree of git ``ref`` of this checkout, written under ``into``."""
    data = subprocess.run(["git", "archive", "--format=tar", ref], cwd=ROOT, check=True, capture_output=True).stdout
    with tarfile.open(fileobj=BytesIO(data)) as tar:
        tar.extractall(into, filter="data")
    return into


def per_process_ms(result: dict[str, float]) -> dict[str, float]:
    """CPU [ms] per step of each process of one :func:`bench.lockstep_profile.profile_once` result, and ``all``."""
    out = {p: result.get(f"{p} CPU us", 0.0) / 1e3 for p in PROCESSES}
    out["all"] = sum(v for k, v in result.items() if k.endswith("CPU us")) / 1e3
    return out


def side_by_side(before: Path, after: Path, demo_args: tuple[str, ...]) -> tuple[dict[str, float], dict[str, float]]:
    """One flight of each checkout at the same moment: their per-process CPU [ms] per step."""
    first, second = profile_pair(before, after, demo_args)
    return per_process_ms(first), per_process_ms(second)


@click.command()
@click.option("--before", "ref", default="81773f1", show_default=True, help="Git revision to compare against.")
@click.option("--against", "other", type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="A checkout to compare against instead of --before.")
@click.option("--config", "configs", multiple=True, default=("configs/cycle.toml", "configs/px4_sitl.toml"),
              show_default=True, help="Demo configuration (repeatable).")
@click.option("--runs", type=click.IntRange(1), default=3, show_default=True, help="Side-by-side flights per configuration.")
def main(ref: str, other: Path | None, configs: tuple[str, ...], runs: int) -> None:
    """Print each process's CPU per lockstep step, before and after (see the module docstring)."""
    with tempfile.TemporaryDirectory(prefix="step-cpu-") as tmp:
        before = other.resolve() if other is not None else export(ref, Path(tmp))
        click.echo(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; "
                   f"before: {other or ref}, after: {ROOT}")
        for config in configs:
            args = ("--config", config, "--estimate-error", "0", "--timeout", "900")  # each checkout its own file
            pairs = []
            for i in range(runs):
                pairs.append(side_by_side(before, ROOT, args))
                click.echo(f"  {config} run {i + 1}, load {os.getloadavg()[0]:.1f}: " + ", ".join(
                    f"{name} {pairs[-1][0][name]:.2f} -> {pairs[-1][1][name]:.2f}" for name in (*PROCESSES, "all")), err=True)
            click.echo(f"{config}: CPU [ms] per 20 ms step over {runs} runs: the least (load only adds), the median")
            click.echo(f"  {'process':<14}{'before':>8}{'after':>8}{'ratio':>7}   {'median before':>14}{'after':>8}{'ratio':>7}")
            for name in (*PROCESSES, "all"):
                b, a = min(p[0][name] for p in pairs), min(p[1][name] for p in pairs)
                mb, ma = statistics.median(p[0][name] for p in pairs), statistics.median(p[1][name] for p in pairs)
                click.echo(f"  {name:<14}{b:>8.2f}{a:>8.2f}{a / b if b else float('nan'):>7.2f}   "
                           f"{mb:>14.2f}{ma:>8.2f}{ma / mb if mb else float('nan'):>7.2f}")
        click.echo(f"load average {os.getloadavg()[0]:.1f} at the end")


if __name__ == "__main__":
    main()
