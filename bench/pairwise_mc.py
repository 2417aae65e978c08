"""The pairwise separation barrier's Monte-Carlo (docs/team.md, "Keeping passengers apart"): N
random scenarios of 2-3 passengers that leave one stopped deck together for targets across it,
flown in-process on the pure law and filter (:func:`sim.batch.team.fly_team`), each passenger
seeing the others' states one tick old; the same scenarios flown again with no barrier (each as if
alone) say how often the barrier had work to do.

Slots ``--spacing`` apart on the deck (D to D + 1.5 m by default). Kinds of scenario: ``cross`` (each target 60 deg either side of
straight across the deck), ``head-on`` (two passengers, each for a point beyond the other's slot
on one line: exactly symmetric) and ``roundabout`` (three passengers, all through the deck's
centre at once: exactly symmetric). Deadlock: a passenger not at its target within the flight's
time (``--duration``).

Usage: ``python -m bench.pairwise_mc [-n 200] [--seed 1] [--config configs/demo.toml] [--dim 3] [--spacing LO HI]
[--delay-ticks 1] [--json F]``. A violation: a pair more than 0.01 m inside what the barrier
keeps (D once the pair has been D apart, before that its largest distance so far:
``TeamFlight.shortfall_m``). Exit code 0 when there was no violation and every passenger arrived.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import click
import numpy as np
from tqdm import tqdm

from mission.config.schema import load_config
from sim.batch.team import fly_team, pair_distances

ROOT = Path(__file__).resolve().parents[1]
TOLERANCE_M = 0.01  # [m] a violation: closer than D less this
DECK_DOWN_M = -1.5  # [m] NED z of the slots (the demo's dock point: 1.5 m above the deck's plane)
KINDS = ("cross", "head-on", "roundabout")


def scenario(rng: np.random.Generator, kind: str, separation_m: float, reach_m: float,
             spacing_m: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """One scenario's slots (``spacing_m`` apart, a range [m]) and targets, (k, 3) each, NED [m];
    every target within ``reach_m`` of its slot (b c: the passenger leaves at once) and at least
    ``separation_m + 1`` from the others."""
    while True:
        k = 2 if kind == "head-on" else 3 if kind == "roundabout" else int(rng.integers(2, 4))
        spacing = rng.uniform(*spacing_m)
        turn = rng.uniform(0, 2 * np.pi)
        ang = turn + 2 * np.pi * np.arange(k) / k
        radius = spacing / (2 * np.sin(np.pi / k))
        slots = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.full(k, DECK_DOWN_M)], axis=-1)
        if kind == "head-on":
            beyond = rng.uniform(2.0, 4.0)
            targets = slots[::-1] + (slots[::-1] - slots) / spacing * beyond
        elif kind == "roundabout":
            reach = rng.uniform(3.0, 5.5)
            targets = np.stack([-reach * np.cos(ang), -reach * np.sin(ang), np.full(k, rng.uniform(-4.0, -1.5))], axis=-1)
        else:
            far = ang + np.pi + rng.uniform(-np.pi / 3, np.pi / 3, k)
            reach = rng.uniform(3.0, 6.0, k)
            targets = np.stack([reach * np.cos(far), reach * np.sin(far), rng.uniform(-6.0, -1.0, k)], axis=-1)
        apart = min((float(np.linalg.norm(targets[i] - targets[j])) for i in range(k) for j in range(i)), default=np.inf)
        if np.linalg.norm(targets - slots, axis=-1).max() <= 0.95 * reach_m and apart >= separation_m + 1.0:
            return slots, targets


@click.command()
@click.option("-n", "count", type=click.IntRange(min=1), default=200, show_default=True, help="Scenarios.")
@click.option("--seed", type=int, default=1, show_default=True, help="Random seed of the scenarios.")
@click.option("--config", type=click.Path(dir_okay=False, exists=True), default=str(ROOT / "configs" / "demo.toml"),
              show_default=True, help="Law, safety (passenger_separation_m), rate and arrival radius from here.")
@click.option("--dim", type=click.Choice(["2", "3"]), default="3", show_default=True, help="3: NED; 2: the same in the plane.")
@click.option("--delay-ticks", type=click.IntRange(min=0), default=1, show_default=True,
              help="The others' states reach each passenger this many ticks old (with that age).")
@click.option("--spacing", type=(float, float), default=None,
              help="[m] range of the slots' spacing on the deck (default: D to D + 1.5; below D a pair is held, not pushed).")
@click.option("--duration", type=click.FloatRange(min=1.0), default=40.0, show_default=True, help="[s] flight time.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), help="Write every scenario's row here.")
def main(count: int, seed: int, config: str, dim: str, delay_ticks: int, spacing: tuple[float, float] | None, duration: float,
         json_path: str | None) -> int:
    cfg = load_config(config)
    law, safety = cfg.law.params(), cfg.safety.passenger()
    D, dt = cfg.safety.passenger_separation_m, 1.0 / cfg.mission.rate_hz
    rng = np.random.default_rng(seed)
    kinds = rng.choice(KINDS, size=count, p=[0.8, 0.1, 0.1])
    spacing = spacing or (D, D + 1.5)
    drawn = [scenario(rng, str(kind), D, law.separation_distance_m, spacing) for kind in kinds]
    n = int(dim)
    rows: list[dict] = [{} for _ in range(count)]
    wall, cpu = time.monotonic(), time.process_time()
    groups = [[i for i in range(count) if len(drawn[i][0]) == k] for k in (2, 3)]
    ticks = int(round(duration / dt))
    with tqdm(total=2 * ticks * sum(1 for g in groups if g), desc=f"{count} team flights", unit="tick") as bar:
        for group in (g for g in groups if g):
            slots = np.array([drawn[i][0][:, :n] for i in group])
            targets = np.array([drawn[i][1][:, :n] for i in group])
            start = pair_distances(slots).min(axis=-1)
            common = dict(arrival_radius_m=cfg.mission.arrival_radius_m, delay_ticks=delay_ticks)
            team = fly_team(slots, targets, law, safety, dt, duration, progress=bar.update, **common)
            alone = fly_team(slots, targets, law, safety, dt, duration, separate=False, progress=bar.update, **common)
            for j, i in enumerate(group):
                rows[i] = dict(index=i, kind=str(kinds[i]), passengers=len(drawn[i][0]),
                               min_distance_m=float(team.min_distance_m[j]), start_m=float(start[j]),
                               shortfall_m=float(team.shortfall_m[j]), violated=bool(team.shortfall_m[j] > TOLERANCE_M),
                               all_arrived_s=float(np.max(team.arrived_s[j])), deadlocked=bool(np.isnan(team.arrived_s[j]).any()),
                               infeasible_ticks=int(team.infeasible[j]), alone_min_distance_m=float(alone.min_distance_m[j]),
                               alone_all_arrived_s=float(np.max(alone.arrived_s[j])))
    wall, cpu = time.monotonic() - wall, time.process_time() - cpu
    click.echo(f"python -m bench.pairwise_mc -n {count} --seed {seed} --config {Path(config).name} --dim {dim} "
               f"--delay-ticks {delay_ticks} --spacing {spacing[0]:g} {spacing[1]:g} --duration {duration:g}")
    click.echo(f"D = passenger_separation_m = {D:g} m, violation: a pair closer than D - {TOLERANCE_M:g} m "
               f"(before it has been D apart: closer than its largest distance so far - {TOLERANCE_M:g} m); "
               f"cbf_gain {safety.cbf_gain:g}/s, {cfg.mission.rate_hz:g} Hz, speed <= {safety.max_speed_m_s} m/s, "
               f"accel <= {safety.max_accel_m_s2} m/s^2, b c = {law.separation_distance_m:g} m")
    head = f"{'kind':<11}{'n':>4}{'min dist m':>12}{'shortfall m':>13}{'violations':>12}{'deadlocks':>11}{'infeas.':>9}" \
           f"{'all arrived s p50/max':>23}{'alone: closer than D':>22}{'alone min m':>13}"
    click.echo(head)
    click.echo("-" * len(head))
    for kind in (*KINDS, "all"):
        sel = [r for r in rows if kind in ("all", r["kind"])]
        if not sel:
            continue
        arrived = [r["all_arrived_s"] for r in sel if not r["deadlocked"]]
        times = f"{np.median(arrived):.1f}/{np.max(arrived):.1f}" if arrived else "-"
        click.echo(f"{kind:<11}{len(sel):>4}{min(r['min_distance_m'] for r in sel):>12.3f}"
                   f"{max(r['shortfall_m'] for r in sel):>13.4f}"
                   f"{sum(r['violated'] for r in sel):>12}{sum(r['deadlocked'] for r in sel):>11}"
                   f"{sum(r['infeasible_ticks'] > 0 for r in sel):>9}{times:>23}"
                   f"{sum(r['alone_min_distance_m'] < D - TOLERANCE_M for r in sel):>22}"
                   f"{min(r['alone_min_distance_m'] for r in sel):>13.3f}")
    click.echo(f"cost: {wall:.1f} s wall, {cpu:.1f} s CPU (both runs)")
    if json_path:
        Path(json_path).write_text(json.dumps(dict(seed=seed, config=config, dim=n, rows=rows), indent=1))
    bad = sum(r["violated"] or r["deadlocked"] for r in rows)
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main(standalone_mode=False) or 0)
