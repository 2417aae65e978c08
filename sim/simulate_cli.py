"""``marsupial simulate``: the paper's closed loop from a config (one run, or a Monte-Carlo batch)."""
from __future__ import annotations

import json
import logging
import sys
from pathlib import Path

import click
import numpy as np
from tqdm import tqdm

from mission.config import Config, load_config
from sim import closed_loop
from sim.closed_loop import ClosedLoopResult, model_from_config, random_scenarios, simulate_config
from mission.plots import Trajectories, plot_run

log = logging.getLogger(__name__)


def trajectories_of(result: ClosedLoopResult, cfg: Config, i: int = 0, title: str = "") -> Trajectories:
    """The figure input of scenario ``i`` of a simulation result."""
    T = result.separation_time_s[i]
    return Trajectories(
        t=result.t, x_c=result.x_c[:, i], x_p=result.x_p[:, i], target=result.target[i],
        separation_time_s=None if np.isnan(T) else float(T),
        obstacles=[(np.array(o.center), o.radius) for o in cfg.scenario.obstacles],
        frame=cfg.scenario.frame, title=title, bc_m=cfg.law.params().separation_distance_m,
    )


def _progress_bar(total_steps: int, desc: str, enabled: bool):
    bar = tqdm(total=total_steps, desc=desc, unit="step", disable=not enabled, leave=False)
    done = [0]

    def update(k: int) -> None:
        bar.update(k - done[0])
        done[0] = k

    return bar, update


def run_monte_carlo(cfg: Config, count: int, seed: int, show_progress: bool) -> dict:
    """Simulate ``count`` random scenarios in one batch and summarise P1-P3 over them."""
    starts, targets = random_scenarios(cfg, count, seed)
    steps = int(round(cfg.sim.duration_s / cfg.sim.dt_s))
    bar, update = _progress_bar(steps, f"{count} scenarios", show_progress)
    with bar:
        res = closed_loop.simulate(model_from_config(cfg, target=targets), starts, duration_s=cfg.sim.duration_s,
                       dt_s=cfg.sim.dt_s, record_every=max(steps // 200, 1), p1_tolerance_m=cfg.sim.p1_tolerance_m,
                       p2_tolerance_m=cfg.sim.p2_tolerance_m, progress=update)
    ok = res.p1 & res.p2 & res.p3
    worst = np.argsort(-res.final_passenger_target_distance_m)[:3]
    return {
        "scenarios": count,
        "seed": seed,
        "fraction_p1": float(res.p1.mean()),
        "fraction_p2": float(res.p2.mean()),
        "fraction_p3": float(res.p3.mean()),
        "fraction_all": float(ok.mean()),
        "max_relative_input_jump_m_s": float(np.nanmax(res.relative_input_jump_m_s)),
        "max_departure_delay_s": float(np.nanmax(res.departure_delay_s)),
        "min_carrier_target_distance_m": float(res.min_carrier_target_distance_m.min()),
        "worst_cases": [
            {"index": int(i), "target": res.target[i].round(3).tolist(), **res.summary(int(i))} for i in worst
        ],
    }


@click.command("simulate")
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (the summary) on stdout.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), help="Write the paper's figures (PNG/PDF/SVG by suffix).")
@click.option("--monte-carlo", "count", type=click.IntRange(min=1), help="Simulate N random scenarios that satisfy the assumptions.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed of --monte-carlo.")
@click.option("--no-progress", is_flag=True, help="Hide the progress bar.")
def simulate(config: str, as_json: bool, plot_path: str | None, count: int | None, seed: int, no_progress: bool) -> int:
    """Integrate the closed loop of the paper for CONFIG (a TOML file, see configs/).

    Reports the separation time, the carrier-target distance at separation, the relative input
    just after separation and its jump across it, the final passenger-target distance, the
    closest carrier-target approach, obstacle clearance, peak speed, and P1-P3 of the paper's
    Definition 1: P1 |e_pc| <= sim.p1_tolerance_m before separation and the passenger leaves
    (> 0.1 m) after it; P2 the final |e_pt| <= sim.p2_tolerance_m; P3 |e_tc| > 0 throughout.
    Exit code 0 when P1-P3 hold (for every scenario with --monte-carlo), 1 otherwise, 2 on a bad
    config.
    """
    cfg = load_config(config)
    show = not no_progress and sys.stderr.isatty() and not as_json or (not no_progress and count is not None)
    if count is not None:
        report = run_monte_carlo(cfg, count, seed, show)
        if as_json:
            click.echo(json.dumps(report, indent=2))
        else:
            click.echo(f"{count} scenarios (seed {seed}): P1 {report['fraction_p1']:.1%}  P2 {report['fraction_p2']:.1%}  "
                       f"P3 {report['fraction_p3']:.1%}  all {report['fraction_all']:.1%}")
            click.echo("worst final passenger-target distances: "
                       + ", ".join(f"{w['final_passenger_target_distance_m']:.4f} m" for w in report["worst_cases"]))
        return 0 if report["fraction_all"] == 1.0 else 1
    steps = int(round(cfg.sim.duration_s / cfg.sim.dt_s))
    bar, update = _progress_bar(steps, Path(config).stem, show)
    with bar:
        result = simulate_config(cfg, progress=update)
    summary = result.summary()
    if plot_path:
        out = plot_run(trajectories_of(result, cfg, title=f"{Path(config).stem}: separation and navigation"), plot_path)
        log.info("wrote %s", out)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        width = max(len(k) for k in summary)
        for key, value in summary.items():
            click.echo(f"{key:<{width}}  {value}")
        if plot_path:
            click.echo(f"plot written to {plot_path}")
    return 0 if summary["p1"] and summary["p2"] and summary["p3"] else 1
