"""The team's Monte-Carlo (docs/team.md "The team's Monte-Carlo"): ``-n`` random team
scenarios (2-3 passengers, 2-4 targets satisfying the paper's assumptions), each a whole mission
flown in-process by every passenger's own step (:mod:`sim.batch.team_mc`), then the table of
the issue's targets.

Usage: ``python -m bench.team_mc [-n 200] [--seed 1] [--config configs/team.toml]
[--estimate-error 1] [--only 3,17] [--json F]``. Exit code 0 when the targets hold (>= 99 % of
legs docked within 2 approaches, no pairwise violation, every leg that did not dock safe, P1-P3
on every leg, no switch step over 0.05 m/s, the carrier never inside a keep-out).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import click

from mission.config.schema import load_config
from sim.batch import team_mc

ROOT = Path(__file__).resolve().parents[1]
STEP_LIMIT_M_S = 0.05  # [m/s] the most the command may step at a switch (docs/team.md)


@click.command()
@click.option("-n", "count", type=click.IntRange(min=1), default=200, show_default=True, help="Scenarios.")
@click.option("--seed", type=int, default=1, show_default=True, help="Random seed of the scenarios.")
@click.option("--config", type=click.Path(dir_okay=False, exists=True), default=str(ROOT / "configs" / "team.toml"),
              show_default=True)
@click.option("--estimate-error", type=click.FloatRange(min=0.0), default=1.0, show_default=True,
              help="Each vehicle's estimate errs as PX4 SITL's, this many times as much.")
@click.option("--only", type=str, default=None, help="Fly only these scenarios of the -n drawn (comma-separated).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), help="Write every scenario's row here.")
def main(count: int, seed: int, config: str, estimate_error: float, only: str | None, json_path: str | None) -> None:
    base = load_config(config).model_dump(exclude_unset=True)
    drawn = team_mc.scenarios(count, seed, base)
    if only:
        wanted = {int(i) for i in only.split(",")}
        drawn = [sc for sc in drawn if sc.index in wanted]
    rows = []
    wall, cpu = time.monotonic(), time.process_time()
    for k, sc in enumerate(drawn):
        row = team_mc.fly(sc, estimate_error)
        rows.append(row)
        bad = [leg for leg in row["legs"] if not leg["within_2"]]
        note = "" if not bad and not row["violation"] else (
            f"  <- {len(bad)} leg(s) not docked within 2; violation {row['violation']}"
            + (f" at {row['worst_pair']}" if row["violation"] else ""))
        click.echo(f"[{k + 1}/{len(drawn)}] #{sc.index}: {sc.n_passengers} passengers, {sc.n_targets} targets, "
                   f"{row['duration_s']:.0f} s flown, pair min in air {row['pair_min_air_m']} m, "
                   f"{time.monotonic() - wall:.0f} s wall{note}", err=True)
        if json_path:
            Path(json_path).write_text(json.dumps({"rows": rows}, indent=1, default=str))
    wall, cpu = time.monotonic() - wall, time.process_time() - cpu
    t = team_mc.table(rows)
    t.update(seed=seed, estimate_error=estimate_error, wall_s=round(wall, 1), cpu_s=round(cpu, 1),
             cpu_s_per_scenario=round(cpu / max(len(rows), 1), 2))
    width = max(len(k) for k in t)
    for key, value in t.items():
        click.echo(f"{key:<{width}}  {value}")
    ok = (t["legs_docked_within_2_pct"] >= 99.0 and t["pairwise_violations"] == 0
          and t["not_docked_safe"] == t["legs_not_docked"] and t["p1_p3_all_legs"] == t["legs"]
          and (t["largest_phase_switch_step_m_s"] or 0.0) <= STEP_LIMIT_M_S
          and t["largest_queue_switch_step_m_s"] <= STEP_LIMIT_M_S and t["carrier_inside_keep_out"] == 0)
    click.echo(f"targets: {'met' if ok else 'MISSED'}")
    if json_path:
        Path(json_path).write_text(json.dumps({"table": t, "rows": rows}, indent=1, default=str))
    raise SystemExit(0 if ok else 1)


if __name__ == "__main__":
    main()
