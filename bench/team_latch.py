"""A passenger's command per tick around its first separation in the team flown in-process
(:class:`sim.batch.team_mission.TeamWorld`; docs/team.md, "The carrier of a team, and the team flown
in-process"): with the pairwise rows phased in as configured, with them in at once
(``safety.passenger_separation_phase_in_s = 0``) and without the neighbours.

Per tick: the phase; ``|du|`` [m/s] the change of the command sent (the setpoint's velocity);
``lack`` [m/s] how far the previous command was from meeting the full neighbour row (half the
pair's closing speed along their line as the samples show it, less the barrier's allowance);
``w`` [-] the share of the rows in force (:func:`mission.core.safety.phase_in_weight`); ``corr``
[m/s] the barrier's correction of the command after the acceleration limit.

Usage: ``python -m bench.team_latch [--config configs/team.toml] [--passenger alpha]
[--estimate-error 1] [--seed 0] [--before 3] [--after 6]``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import click
import numpy as np

from mission.config.schema import Config, from_dict, load_config
from mission.core import safety, tick as tick_module
from mission.phases import Phase
from sim.batch.team_mission import TeamWorld
from sim.vehicle.estimator import PX4_SITL_SCALE

ROOT = Path(__file__).resolve().parents[1]


def with_phase_in(cfg: Config, phase_in_s: float) -> Config:
    """``cfg`` with ``safety.passenger_separation_phase_in_s`` [s] set."""
    data = {key: dict(value) if isinstance(value, dict) else value
            for key, value in cfg.model_dump(exclude_unset=True).items()}
    data["safety"] = {**data.get("safety", {}), "passenger_separation_phase_in_s": phase_in_s}
    return from_dict(data)


def fly(cfg: Config, who: int, estimate_error: float, seed: int, share: bool, after: int) -> list[dict[str, Any]]:
    """Passenger ``who``'s ticks up to ``after`` ticks past its first separation."""
    seen: list[tuple[float, float, float] | None] = []
    plain = tick_module.filter_velocity

    def watched(x, u_des, obstacles, cfg_, u_prev=None, dt_s=None, **kw):
        r = plain(x, u_des, obstacles, cfg_, u_prev, dt_s, **kw)
        nb, since = kw.get("neighbours"), kw.get("since_separation_s")
        rows = None if nb is None or u_prev is None else safety.neighbour_rows(np.asarray(x, float), u_prev, nb, cfg_)
        if rows is None:
            seen.append(None)
            return r
        used = safety.neighbour_rows(np.asarray(x, float), u_prev, nb, cfg_, since)
        A, b = rows
        accelerated = safety.limit_accel(safety.veer_right(np.asarray(u_des, float), *used), u_prev,
                                         cfg_.max_accel_m_s2, dt_s)
        lack = float(np.max(np.maximum(b - A @ u_prev, 0.0) / np.linalg.norm(A, axis=-1)))
        w = 1.0 if since is None or cfg_.separation_phase_in_s <= 0 else float(
            safety.phase_in_weight(since, cfg_.separation_phase_in_s))
        seen.append((lack, w, float(np.linalg.norm(r.u - accelerated))))
        return r

    setattr(tick_module, "filter_velocity", watched)  # (the tick's filter, watched: the run is otherwise as flown)
    try:
        world = TeamWorld(cfg, estimate_error=estimate_error, seed=seed, share_neighbours=share)
        out: list[dict[str, Any]] = []
        latch = None
        while not world.done and (latch is None or len(out) <= latch + after):
            before, start = world.members[who].state.phase, len(seen)
            world.tick()
            m = world.members[who]
            mine = next((c for c in seen[start:] if c is not None), None)
            out.append({"t": world.t[-1], "phase": m.state.phase.value,
                        "u": np.array(m.state.u_cmd) if m.state.u_cmd is not None else np.full(3, np.nan), "row": mine})
            if latch is None and m.state.phase is Phase.SEPARATED and before is not Phase.SEPARATED:
                latch = len(out) - 1
    finally:
        setattr(tick_module, "filter_velocity", plain)
    return out


@click.command()
@click.option("--config", type=click.Path(dir_okay=False, exists=True), default=str(ROOT / "configs" / "team.toml"),
              show_default=True)
@click.option("--passenger", default="alpha", show_default=True, help="Whose first separation.")
@click.option("--estimate-error", type=click.FloatRange(min=0.0), default=PX4_SITL_SCALE, show_default=True,
              help="x PX4 SITL's estimate errors (as `marsupial simulate`).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--before", type=click.IntRange(min=1), default=3, show_default=True, help="Ticks shown before the latch.")
@click.option("--after", type=click.IntRange(min=1), default=6, show_default=True, help="Ticks shown after it.")
def main(config: str, passenger: str, estimate_error: float, seed: int, before: int, after: int) -> None:
    cfg = load_config(config)
    who = [p.name for p in cfg.team.passengers].index(passenger)
    runs = {f"phased in over {cfg.safety.passenger_separation_phase_in_s:g} s": fly(cfg, who, estimate_error, seed, True, after),
            "in at once": fly(with_phase_in(cfg, 0.0), who, estimate_error, seed, True, after),
            "no neighbours": fly(cfg, who, estimate_error, seed, False, after)}
    first = next(iter(runs.values()))
    latch = next(i for i, r in enumerate(first) if r["phase"] == Phase.SEPARATED.value
                 and first[i - 1]["phase"] != Phase.SEPARATED.value)
    click.echo(f"{passenger}, {Path(config).name}, estimate error x{estimate_error:g}, seed {seed}; "
               "per run: |du| [m/s], lack [m/s], w [-], corr [m/s]")
    click.echo(f"{'t [s]':>7} {'phase':<11}" + "".join(f"{name:>34}" for name in runs))
    for i in range(max(latch - before, 1), latch + after + 1):
        cells = []
        for rows in runs.values():
            r, du = rows[i], float(np.linalg.norm(rows[i]["u"] - rows[i - 1]["u"]))
            row = "-" if r["row"] is None else "{:.4f} {:.3f} {:.4f}".format(*r["row"])
            cells.append(f"{du:.4f} {row:>20}")
        click.echo(f"{first[i]['t']:>7.2f} {first[i]['phase']:<11}" + "".join(f"{c:>34}" for c in cells))


if __name__ == "__main__":
    main()
