"""The recovery's Monte-Carlo in full (docs/recovery.md): N whole missions of a configuration that
comes home, each in a random scenario (carrier 0-2 m/s on any heading, a turn of up to 45 deg
during the first approach), flown in-process on the mock's dynamics (:mod:`sim.batch.recovery`),
with the table of the targets and what it cost.

Usage: ``python -m bench.recovery_mc [-n 200] [--seed 1] [--config configs/recovery.toml]
[--estimate-error 1] [--only 102,175] [--json F] [--plot F]`` (about 1 s of CPU per scenario, 5 s
for the two-target cycle; on a busy machine the wall time is several times that).
``--estimate-error``: the vehicle's estimate errs as PX4 SITL's does (1: as much), each scenario
with its own seed (no shared flight before the recovery). ``--only``: fly only these scenarios
(their numbers, ``#i`` in the report) of the ``-n`` drawn, to look at one again.
Each scenario's row (``--json``) has the carrier's closest approach to each target and to any
(``closest_to_targets_m``, ``closest_any_target_m``: its true position against every target,
whichever leg it served); the closest five are printed. Each leg's riding offset (P1's figure,
``max_offset_before_separation_m``), and per scenario, while the passenger rides the dock point
(RIDING or TRANSIT), its largest offset and the largest step of the carrier's velocity between two
ticks (``ridden_offset_m``, ``ridden_carrier_step_m_s``). Exit code 0 when the targets hold.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import click
from tqdm import tqdm

from mission.config.schema import load_config
from sim.batch import recovery, recovery_mc

ROOT = Path(__file__).resolve().parents[1]


@click.command()
@click.option("-n", "count", type=click.IntRange(min=1), default=200, show_default=True, help="Scenarios.")
@click.option("--seed", type=int, default=1, show_default=True, help="Random seed of the scenarios.")
@click.option("--config", type=click.Path(dir_okay=False, exists=True), default=str(ROOT / "configs" / "recovery.toml"),
              show_default=True)
@click.option("--estimate-error", type=click.FloatRange(min=0.0), default=0.0, show_default=True,
              help="The vehicle's estimate errs as PX4 SITL's does, this many times as much (1: PX4 SITL's; 0: exact, as the demo's mock).")
@click.option("--only", type=str, default=None, help="Fly only these scenarios of the -n drawn (comma-separated numbers).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), help="Write the report (every scenario's row) here.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), help="Draw the worst flight's recovery here.")
def main(count: int, seed: int, config: str, estimate_error: float, only: str | None, json_path: str | None,
         plot_path: str | None) -> int:
    cfg = load_config(config)
    drawn = count
    scenarios = recovery_mc.random_scenarios(count, seed, estimate_error)
    if only:
        wanted = {int(i) for i in only.split(",")}
        scenarios = [sc for sc in scenarios if sc.index in wanted]
        if len(scenarios) != len(wanted):
            raise click.BadParameter(f"scenarios are numbered 0..{count - 1}", param_hint="--only")
        count = len(scenarios)
    wall, cpu = time.monotonic(), time.process_time()
    with tqdm(total=count, desc=f"{count} recoveries", unit="flight") as bar:
        report, worst = recovery_mc.monte_carlo(cfg, scenarios, progress=lambda f: bar.update(1))
    wall, cpu = time.monotonic() - wall, time.process_time() - cpu
    report.seed = seed
    click.echo(f"python -m bench.recovery_mc -n {drawn} --seed {seed} "
               f"--config {Path(config).name}{f' --estimate-error {estimate_error:g}' if estimate_error else ''}"
               f"{f' --only {only}' if only else ''}")
    click.echo(recovery_mc.format_report(report))
    for r in report.rows:
        if recovery_mc.badness(r)[0]:
            broken = {"legs_broken": [leg["leg"] + 1 for leg in r["legs"] if not (leg["p1"] and leg["p2"] and leg["p3"])]}
            click.echo(f"  missed #{r['index']}: {json.dumps({**{k: r[k] for k in ('speed_m_s', 'heading_deg', 'turn_deg', 'turn_rate_deg_s', 'turn_after_s', 'outcome', 'attempts', 'end_phase', 'deck_violations')}, **(broken if r['legs'] else {})})}")
    closest = sorted((r["closest_any_target_m"], r["index"]) for r in report.rows if r.get("closest_any_target_m") is not None)
    if closest:
        click.echo("the carrier's closest approach to any target, per scenario (the closest five): "
                   + ", ".join(f"#{i} {d:.3f} m" for d, i in closest[:5]))
    sim_s = sum(r["flight_time_s"] for r in report.rows)
    click.echo(f"cost: {cpu:.1f} s CPU ({cpu / count:.2f} s per scenario, {sim_s / cpu:.0f}x simulated time per CPU "
               f"second), {wall:.1f} s wall; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    if json_path:
        out = report.as_dict()
        out.update(cpu_s=round(cpu, 2), wall_s=round(wall, 2), config=str(config), estimate_error=estimate_error)
        Path(json_path).write_text(json.dumps(out, indent=2))
    if plot_path and worst is not None:
        drawn = recovery.draw(worst, plot_path, f"scenario #{worst.scenario.index} of seed {seed} (the worst)")
        click.echo(f"the worst flight (#{worst.scenario.index}) drawn to {drawn}")
    return 0 if recovery_mc.report_ok(report) else 1


if __name__ == "__main__":
    raise SystemExit(main(standalone_mode=False))
