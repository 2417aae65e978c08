"""What a command costs before it does anything: CPU [s] of ``python -m mission.cli <command>``
up to its first refusal (a missing config file) or its ``--help``, as the tests start them.

``python -m bench.startup_bench [--runs N] [--against DIR]`` starts each command ``N`` times and
prints the median and the least CPU (user + system, from the child's rusage: a loaded machine
inflates it much less than wall time). With ``--against DIR`` (e.g. a worktree of main) each run
also starts DIR's command at the same moment and the table shows both. A flight in the suite
starts four such processes (``demo`` or the test, and the three of the pair), the fault matrix and
the attacks three, the configuration tests one per refusal (docs/testing.md, "Where the time goes").
"""
from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
from pathlib import Path

import click

ROOT = Path(__file__).resolve().parents[1]
MISSING = "/nonexistent/marsupial-startup-bench.toml"
COMMANDS = {
    "run": ["run", MISSING],
    "carrier": ["carrier", MISSING],
    "mock-vehicle": ["mock-vehicle", "--help"],
    "simulate": ["simulate", MISSING],
    "demo": ["demo", "--help"],
}


def child_cpu(args: list[str], root: Path, env: dict[str, str]) -> float:
    """CPU [s] (user + system) of one ``python -m mission.cli ARGS`` with ``root`` first on the path."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-m", "mission.cli", *args], cwd=root, env={**env, "PYTHONPATH": str(root)},
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def measure(runs: int, roots: list[Path], env: dict[str, str]) -> dict[str, list[list[float]]]:
    """{command: for each root, the CPU of each run}; the roots take turns within a run."""
    out: dict[str, list[list[float]]] = {name: [[] for _ in roots] for name in COMMANDS}
    for name, args in COMMANDS.items():
        for root in roots:  # once unmeasured: bytecode written where it is written, caches warm
            child_cpu(args, root, env)
        for _ in range(runs):
            for i, root in enumerate(roots):
                out[name][i].append(child_cpu(args, root, env))
    return out


@click.command()
@click.option("--runs", type=click.IntRange(1), default=5, show_default=True, help="Starts of each command.")
@click.option("--against", "other", type=click.Path(exists=True, file_okay=False, path_type=Path), default=None,
              help="Another checkout (e.g. a worktree of main) measured in the same runs.")
def main(runs: int, other: Path | None) -> None:
    roots = [ROOT] + ([other.resolve()] if other is not None else [])
    results = measure(runs, roots, dict(os.environ))
    heads = "".join(f"  {r.name + ' median':>16} {'least':>7}" for r in roots)
    click.echo(f"start-up CPU [s], {runs} runs, load average {os.getloadavg()[0]:.1f}, "
               f"PYTHONDONTWRITEBYTECODE={os.environ.get('PYTHONDONTWRITEBYTECODE', '')!r}")
    click.echo(f"{'command':<14}{heads}")
    for name, per_root in results.items():
        cells = "".join(f"  {statistics.median(v):16.2f} {min(v):7.2f}" for v in per_root)
        click.echo(f"{name:<14}{cells}")


if __name__ == "__main__":
    main()
