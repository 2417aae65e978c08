"""``marsupial simulate``: a config flown in-process: a mission config (a ``[mission]`` section) as
the whole mission (:mod:`sim.batch.recovery`), the paper's configs by the paper's closed loop
(:mod:`sim.batch.closed_loop`); one run, or a Monte-Carlo batch. The output names which was flown
(``simulated``: :data:`MISSION_FLOWN` or :data:`PAPER_FLOWN`)."""
from __future__ import annotations

import json
import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import click
import numpy as np
from tqdm import tqdm

from mission.config.passenger import has_team, sole_passenger
from mission.errors import ConfigError
from mission.config.schema import Config, load_config
from sim.batch import closed_loop, recovery, recovery_mc
from sim.batch.closed_loop import ClosedLoopResult, as_flown, is_mission_config, model_from_config, random_scenarios, simulate_config
from mission.phases import Phase
from sim.vehicle.options import VehicleOptions

if TYPE_CHECKING:
    from mission.plots import Trajectories

log = logging.getLogger(__name__)


def trajectories_of(result: ClosedLoopResult, cfg: Config, i: int = 0, title: str = "") -> Trajectories:
    """The figure input of scenario ``i`` of a simulation result."""
    from mission.plots import Trajectories  # matplotlib is loaded only to draw

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
    """Simulate ``count`` random scenarios in one batch and summarise P1-P3 over them.

    ``worst_cases``: the failing scenarios first, then the largest final passenger-target
    distances (at most :data:`WORST_SHOWN`), each with its id (``index``; the same seed gives the
    same scenarios), its parameters (carrier start, target, the target's distance to the nearest
    obstacle surface) and its summary."""
    starts, targets = random_scenarios(cfg, count, seed)
    p2_tol = cfg.sim.p2_tolerance_m
    if is_mission_config(cfg):
        start, p2_tol = as_flown(cfg)
        starts = starts + start  # the law's carrier is the dock point, as flown
    steps = int(round(cfg.sim.duration_s / cfg.sim.dt_s))
    bar, update = _progress_bar(steps, f"{count} scenarios", show_progress)
    with bar:
        res = closed_loop.simulate(model_from_config(cfg, target=targets), starts, duration_s=cfg.sim.duration_s,
                       dt_s=cfg.sim.dt_s, record_every=max(steps // 200, 1), p1_tolerance_m=cfg.sim.p1_tolerance_m,
                       p2_tolerance_m=p2_tol, progress=update)
    ok = res.p1 & res.p2 & res.p3
    failing = np.flatnonzero(~ok)
    by_distance = [int(i) for i in np.argsort(-res.final_passenger_target_distance_m) if ok[i]]
    worst = [int(i) for i in failing[:WORST_SHOWN]] if len(failing) else by_distance[:3]
    obstacles = cfg.scenario.obstacle_set()
    target_clear = obstacles.clearance(res.target).min(axis=-1) if len(obstacles) else np.full(count, np.nan)
    return {
        "simulated": PAPER_FLOWN,
        "scenarios": count,
        "seed": seed,
        "fraction_p1": float(res.p1.mean()),
        "fraction_p2": float(res.p2.mean()),
        "fraction_p3": float(res.p3.mean()),
        "fraction_all": float(ok.mean()),
        "failing": len(failing),
        "max_relative_input_jump_m_s": _finite_max(res.relative_input_jump_m_s),
        "max_departure_delay_s": _finite_max(res.departure_delay_s),
        "min_carrier_target_distance_m": float(res.min_carrier_target_distance_m.min()),
        "worst_cases": [
            {"index": i, "carrier_start": starts[i].round(3).tolist(), "target": res.target[i].round(3).tolist(),
             "target_obstacle_clearance_m": None if np.isnan(target_clear[i]) else round(float(target_clear[i]), 3),
             **res.summary(i)} for i in worst
        ],
    }


WORST_SHOWN = 10


def is_recovery_config(cfg: Config) -> bool:
    """A flight that comes home (``mission.final_action = "return"``): its Monte-Carlo is the recovery's."""
    return is_mission_config(cfg) and cfg.mission.final_action == "return"


def run_recovery_monte_carlo(cfg: Config, name: str, count: int, seed: int, show_progress: bool,
                             plot_path: str | None, as_json: bool) -> int:
    """``count`` recoveries of ``cfg`` in random scenarios (:mod:`sim.batch.recovery`): the table
    (or JSON), the worst flight's figure at ``plot_path``; 0 when the targets hold, else 1."""
    scenarios = recovery_mc.random_scenarios(count, seed)
    bar = tqdm(total=count, desc=f"{count} recoveries", unit="flight", disable=not show_progress, leave=False)
    with bar:
        report, worst = recovery_mc.monte_carlo(cfg, scenarios, progress=lambda f: bar.update(1))
    report.seed = seed
    if plot_path and worst is not None:
        recovery.draw(worst, plot_path, f"{name}, seed {seed}, scenario #{worst.scenario.index} (the worst)")
    if as_json:
        click.echo(json.dumps(report.as_dict(), indent=2))
    else:
        lo, hi = recovery_mc.SPEED_RANGE_M_S
        legs = len(cfg.scenario.legs())
        what = f"missions of {legs} legs" if legs > 1 else "recoveries"
        click.echo(f"{count} {what} of {name} (seed {seed}; id = index, the same --seed replays them): the carrier "
                   f"at {lo:g}-{hi:g} m/s on a random heading, turning up to {recovery_mc.TURN_MAX_DEG:g} deg during the "
                   f"first approach")
        click.echo(recovery_mc.format_report(report))
        click.echo(f"simulated: {MISSION_FLOWN} (the mission's phase machine on the mock's dynamics, the built-in carrier)")
        missed = [r for r in report.rows if recovery_mc.badness(r)[0]]
        for r in missed[:WORST_SHOWN]:
            click.echo(f"  #{r['index']:<4} carrier {r['speed_m_s']:.2f} m/s on {r['heading_deg']:.0f} deg, turn "
                       f"{r['turn_deg']:+.0f} deg at {r['turn_rate_deg_s']:.0f} deg/s after {r['turn_after_s']:.1f} s: "
                       f"{r['outcome']}, {r['attempts']} attempts, ended {r['end_phase']}"
                       f"{'' if r['deck_violations'] == 0 else ', deck violations ' + str(r['deck_violations'])}"
                       f"{''.join(f', leg {leg_broken_p(leg)}' for leg in r['legs'] if leg_broken_p(leg))}")
        if plot_path and worst is not None:
            click.echo(f"the worst flight's recovery (#{worst.scenario.index}) drawn to {plot_path}")
    return 0 if recovery_mc.report_ok(report) else 1


def leg_broken_p(leg: dict) -> str:
    """``"<k> broke P1"`` (the properties a leg of a flight's row did not hold), or ``""``."""
    broken = [p.upper() for p in ("p1", "p2", "p3") if not leg.get(p)]
    return f"{leg['leg'] + 1} broke {'/'.join(broken)}" if broken else ""


#: What ``simulate`` flew, named in its output (the JSON's ``simulated``, the table's last line).
MISSION_FLOWN = "mission"  # the mission's phase machine on the mock's dynamics (sim.batch.recovery)
PAPER_FLOWN = "paper"  # the paper's closed loop (sim.batch.closed_loop)


def has_legs(cfg: Config) -> bool:
    """A mission of several targets (``scenario.targets``): simulated whole, leg by leg."""
    return is_mission_config(cfg) and len(cfg.scenario.legs()) > 1


def not_flown_whole(cfg: Config) -> str | None:
    """Why the mission simulation cannot fly ``cfg`` whole (its carrier or its ride is not
    modelled: :class:`sim.batch.recovery.KinematicCarrier`, :func:`sim.batch.recovery.as_simulated`),
    or None when it can."""
    if cfg.carrier.kinematics != "holonomic":
        return f"carrier.kinematics = {cfg.carrier.kinematics!r} (the simulation drives the built-in holonomic carrier)"
    if cfg.scenario.carrier_mode != "stop":
        return f"scenario.carrier_mode = {cfg.scenario.carrier_mode!r} (the simulation's carrier stops once the passenger left)"
    if cfg.mission.ride == "deck":
        return "mission.ride = 'deck' (the simulation's mock dynamics have no deck)"
    return None


def flies_mission(cfg: Config) -> bool:
    """``simulate`` (one run) flies ``cfg`` as the whole mission: a mission config, unless it has
    one target and a carrier or ride the mission simulation does not model (then the paper's
    closed loop of what ``run`` flies, as before; several targets are refused instead, naming
    the field)."""
    return is_mission_config(cfg) and (has_legs(cfg) or not_flown_whole(cfg) is None)


def mission_ok(flight: recovery.Flight) -> bool:
    """The flown mission completed (DONE) and every leg (the one target) held P1-P3; a passenger
    that comes home docked again."""
    s = flight.summary
    legs = s.get("legs") or [s]
    held = all(leg.get("p1") and leg.get("p2") and leg.get("p3") for leg in legs)
    returns = flight.record.info.get("final_action") == "return"
    return bool(held and (flight.docked or not returns) and flight.state.phase is Phase.DONE)


def run_mission(cfg: Config, name: str, plot_path: str | None, as_json: bool, estimate_error: float = 0.0,
                seed: int = 0) -> int:
    """Fly the whole mission once, as configured (:func:`sim.batch.recovery.fly` with the
    configured recovery course; one target or several, any final action), the vehicle's estimate
    erring ``estimate_error`` times PX4 SITL's, drawn from ``seed`` (as ``marsupial demo``'s
    mock vehicle does: the same seed, the same flight); print the demo's
    table, one column per leg (or the summary as JSON, ``simulated`` = :data:`MISSION_FLOWN`),
    draw each leg's figure; 0 when every leg held P1-P3 and the mission completed (a passenger
    that comes home docked again), else 1."""
    flight = recovery.fly(cfg, recovery.configured(estimate_error, seed))
    s = {**flight.summary, "simulated": MISSION_FLOWN}
    ok = mission_ok(flight)
    written = plot_mission(flight, Path(plot_path), name) if plot_path else []
    if as_json:
        click.echo(json.dumps(s, indent=2, default=float))
    else:
        from sim.demo import format_table, recovery_cells  # the demo's table: one column per leg, the same rows

        click.echo(format_table([{**s, **recovery_cells(s), "pair": name,
                                  "mission_exit_code": 0 if s["phase"] == "DONE" else None}]))
        end = f"{s['phase']}" + ("" if s["reason"] is None else f" ({s['reason']}: {s['detail']})")
        click.echo(f"mission ended {end} after {float(flight.record.t[-1]):.2f} s; largest command jump at a phase "
                   f"switch {s.get('max_phase_switch_jump_m_s') or 0.0:.3f} m/s; deck violations "
                   f"{s.get('deck_violations') or 0} (true position {flight.true_deck_violations})")
        click.echo(f"simulated: {MISSION_FLOWN} (the mission's phase machine on the mock's dynamics, the built-in carrier)")
        for out in written:
            click.echo(f"plot written to {out}")
    return 0 if ok else 1


def run_team(cfg: Config, name: str, plot_path: str | None, as_json: bool, estimate_error: float = 0.0,
             seed: int = 0) -> int:
    """Fly a team of several passengers once (:mod:`sim.batch.team_mission`): the demo's table, one
    column per passenger and leg, then where each separated, the least distance between two
    passengers, the carrier's closest approach to every target and the targets it served (or the
    report as JSON, ``simulated`` = "team"); the figure at ``plot_path``. 0 when every leg held
    P1-P3, each passenger separated at its own target, the carrier kept out of every keep-out and
    every passenger's mission completed; else 1."""
    from sim.batch import team_mission

    if cfg.mission.ride == "deck" and not as_json:
        click.echo(f"{name}: the simulation has no deck: flying the team riding hovering "
                   f"{team_mission.HOVER_RAISE_M:g} m above its slots (mission.ride = \"hover\")", err=True)
    world = team_mission.fly_team(cfg, estimate_error=estimate_error, seed=seed)
    report = team_mission.team_ok_report(world)
    ok = report["ok"]
    if plot_path:
        written = team_mission.draw_team(world, plot_path, f"{name}: one carrier, {len(world.members)} passengers")
    if as_json:
        click.echo(json.dumps(report, indent=2, default=float))
        return 0 if ok else 1
    from sim.demo import format_table, recovery_cells  # the demo's table: one column per passenger and leg

    click.echo(format_table([{**s, **recovery_cells(s), "pair": who, "mission_exit_code": 0 if s["phase"] == "DONE" else None}
                             for who, s in report["passengers"].items()]))
    for who, s in report["passengers"].items():
        for sep in s["separations"]:
            click.echo(f"{who} leg {sep['leg'] + 1}: separated at t = {sep['t_s']:.2f} s, dock point "
                       f"{sep['dock_target_distance_m']:.3f} m from its target {sep['own_target']} (nearest target "
                       f"{sep['nearest_target']}, carrier heading for {sep['carrier_heading_for']})")
        click.echo(f"{who}: ended {s['phase']}" + ("" if s["reason"] is None else f" ({s['reason']}: {s['detail']})")
                   + f"; largest command jump at a phase switch {s.get('max_phase_switch_jump_m_s') or 0.0:.3f} m/s")
    c = report["carrier"]
    click.echo(f"least distance between two passengers {report['pair_min_distance_m']:.3f} m at t = "
               f"{report['pair_min_distance_t_s']:.2f} s ({' and '.join(report['pair_min_phases'])}; true positions; "
               f"the pairwise barrier keeps safety.passenger_separation_m = {cfg.safety.passenger_separation_m:g} m "
               f"in NAVIGATING, + safety.margin_m = {cfg.safety.margin_m:g} m in the recovery's air phases, "
               f"team.passenger_span_m = {cfg.team.passenger_span_m:g} m on the deck's approach)")
    click.echo("carrier closest to each target: " + ", ".join(f"{k}: {d:.3f} m" for k, d in enumerate(c["closest_m"]))
               + f" (P3 guard radius {c['guard_radius_m']:.3f} m; inside a keep-out: {any(c['inside_keep_out'])})")
    click.echo("carrier served: " + " -> ".join(f"{x['target']} {x['mode']} ({x['t_s']:.1f} s)" for x in c["served"]))
    click.echo("simulated: team (each passenger's phase machine on its mock's dynamics, the built-in carrier driven "
               "by the team carrier)")
    if plot_path:
        click.echo(f"plot written to {written}")
    return 0 if ok else 1


def plot_mission(flight: recovery.Flight, path: Path, name: str) -> list[Path]:
    """The flown mission's figures: each leg's paper figure (``<stem>-leg<k>``) for several
    targets, else the paper's figure at ``path``; and the recovery's figure
    (``<stem>-recovery``) of a passenger that came home."""
    from mission.plots import plot_legs, plot_run, record_trajectories

    written = plot_legs(flight.record, path, name)
    if not written:
        tr = record_trajectories(flight.record, f"{name}: separation and navigation")
        if tr is not None:
            written.append(plot_run(tr, path))
    drawn = recovery.draw(flight, path.with_name(f"{path.stem}-recovery{path.suffix}"), name)
    return written + ([] if drawn is None else [Path(drawn)])


def _finite_max(values: np.ndarray) -> float | None:
    """Largest finite value (None when no scenario has one, e.g. none separated)."""
    finite = values[np.isfinite(values)]
    return float(finite.max()) if finite.size else None


def format_case(w: dict) -> str:
    """One worst case on one line: id, parameters, verdict."""
    held = " ".join(f"{p.upper()} {'ok' if w[p] else 'FAILED'}" for p in ("p1", "p2", "p3"))
    clear = "" if w["target_obstacle_clearance_m"] is None else f", target {w['target_obstacle_clearance_m']:.2f} m from an obstacle"
    sep = w["separation_time_s"]
    return (f"  #{w['index']:<5} carrier start {w['carrier_start']}, target {w['target']}{clear}: "
            f"separation {'never' if sep is None else f'at t = {sep:.2f} s'}, "
            f"final |e_pt| {w['final_passenger_target_distance_m']:.4f} m; {held}")


@click.command("simulate")
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object (the summary) on stdout.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), help="Write the paper's figures (PNG/PDF/SVG by suffix).")
@click.option("--monte-carlo", "count", type=click.IntRange(min=1), help="Simulate N random scenarios that satisfy the assumptions.")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Random seed: of --monte-carlo's scenarios; of a mission flight's vehicle estimate errors (as "
                   "`marsupial demo --seed`: pair 1's vehicle draws from SEED).")
@click.option("--estimate-error", type=click.FloatRange(min=0.0), default=VehicleOptions.estimate_error,
              show_default=True, metavar="SCALE",
              help="A mission flight's vehicle estimate errs this many times as PX4 SITL's does (as `marsupial demo "
                   "--estimate-error`; 0: exact).")
@click.option("--no-progress", is_flag=True, help="Hide the progress bar.")
def simulate(config: str, as_json: bool, plot_path: str | None, count: int | None, seed: int, no_progress: bool,
             estimate_error: float) -> int:
    """Fly CONFIG (a TOML file, see configs/) in-process: a mission config as the whole mission, the
    paper's configs by the paper's closed loop; the output says which (JSON ``simulated``:
    "mission" or "paper"; the table's last line).

    \b
    A file with a [mission] section describes a flight (one target or several, any
    mission.final_action): simulate flies the whole mission, as the lockstep demo flies it, by
    the mission's phase machine on the mock vehicle's dynamics with the built-in holonomic carrier
    driving its configured recovery course: join, ride, separate, target, then the final action
    (for "return": task, return, dock, and ride on to the next target). It prints the demo's
    table, one column per leg (separation, relative jump, final distance, contact, P1-P3);
    --plot draws the paper's figure (each leg's: <stem>-leg<k>) and the recovery's
    (<stem>-recovery). With several targets the top-level figures are per leg only, the largest of
    the legs, or of the whole flight, never of target 1 alone (JSON ``top_level_figures``). Exit
    code 0 when every leg held P1-P3, the mission completed and a passenger that comes home
    docked again. The deck ride (mission.ride = "deck") and a carrier other than the built-in
    holonomic one are refused (exit 2).

    \b
    A file with a [team] of several passengers (configs/team.toml) flies the whole team once
    (sim/batch/team_mission.py: every passenger's phase machine on its own mock dynamics, the
    built-in carrier serving them in the mission's order; a deck-riding team hovers 1 m above its
    slots): the table with one column per passenger and leg, where each separated and which
    target the carrier announced, the least distance between two passengers, the carrier's
    closest approach to every target; --plot draws the tracks and the pairwise distance. Exit
    code 0 when every leg held P1-P3, each passenger separated at its own target, the carrier
    kept out of every keep-out and every passenger's mission completed. --monte-carlo is
    refused for a team (exit 2).

    \b
    A file without one (configs/paper_*.toml) is the paper's closed loop: the separation time,
    the carrier-target distance at separation, the relative input just after separation and its
    jump across it, the final passenger-target distance, the closest carrier-target approach,
    obstacle clearance, peak speed, and P1-P3 of the paper's Definition 1: P1 |e_pc| <=
    sim.p1_tolerance_m before separation and the passenger leaves (> 0.1 m) after it; P2 the
    final |e_pt| <= sim.p2_tolerance_m; P3 |e_tc| > 0 throughout. Time t = 0 is the start of
    riding (the passenger docked), as in the paper and in `run`'s summary.

    \b
    --monte-carlo N: random scenarios. The paper's closed loop draws random targets (those the
    passenger cannot reach, inside an obstacle's keep-out disc: radius + safety.margin_m +
    sim.p2_tolerance_m, are drawn again) and prints the failing scenarios (or else the worst)
    with their id and parameters; for a mission that does not come home it models what `run`
    flies (the passenger rides the dock point from the start of riding; P2 within
    mission.arrival_radius_m). A mission that comes home (mission.final_action = "return") has
    the recovery's Monte-Carlo: each scenario the whole mission, every leg, the carrier on a
    random recovery course (0-2 m/s, any heading) turning up to 45 deg during the first approach
    (docs/recovery.md): the share docked at the first attempt and within two, the fallbacks and
    their reasons, the contact figures and deck violations (with several targets the share of
    flights in which every leg held P1-P3); --plot draws the worst flight's approach. Exit code
    0 when >= 99 % docked within 2 attempts, every other one fell back safely and none touched
    the deck outside the contact conditions.

    \b
    A file that leaves a [safety] speed or acceleration limit unset is simulated with the paper's
    unsaturated law there, and simulate says so on stderr.

    Exit code 0 when P1-P3 hold (for every scenario with --monte-carlo), 1 otherwise, 2 on a bad
    config.
    """
    loaded = load_config(config)
    if has_team(loaded) and len(loaded.team.passengers) > 1:
        if count is not None:
            raise ConfigError("--monte-carlo", count, "a team of several passengers is simulated once: no random team scenarios yet (docs/team.md)")
        return run_team(loaded, Path(config).stem, plot_path, as_json, estimate_error, seed)
    cfg = sole_passenger(loaded, "simulated by `marsupial simulate`")  # a team of one: its passenger's
    unsaturated = [f"safety.{name}" for name in ("passenger_max_speed_m_s", "passenger_max_accel_m_s2",
                                                  "carrier_max_speed_m_s", "carrier_max_accel_m_s2")
                   if getattr(cfg.safety, name) is None]
    if unsaturated:  # on stderr, also with --json: the paper's runs are unsaturated on purpose
        click.echo(f"{Path(config).name} leaves {', '.join(unsaturated)} unset: simulating the paper's unsaturated "
                   "law there (its 3D run peaks above 300 m/s); `marsupial run` and `marsupial carrier` refuse such a "
                   "file", err=True)
    if is_mission_config(cfg) and count is None and not flies_mission(cfg):
        click.echo(f"{Path(config).name}: {not_flown_whole(cfg)}: simulating the paper's closed loop of what "
                   f"`marsupial run` flies instead (simulated: {PAPER_FLOWN})", err=True)
    elif is_mission_config(cfg) and count is None and not as_json:
        legs = len(cfg.scenario.legs())
        returns = cfg.mission.final_action == "return"
        what = (f"lists {legs} targets: simulating the whole mission, every leg (ride, separate, target, task, return, "
                "dock, ride on)" if legs > 1 else "has a [mission] section: simulating the whole mission (join, ride, "
                "separate, target, " + ("task, return, dock)" if returns else f"then {cfg.mission.final_action})"))
        click.echo(f"{Path(config).name} {what}, by the mission's phase machine on the mock vehicle's dynamics with "
                   "the built-in holonomic carrier" + (" driving its configured recovery course" if returns else ""),
                   err=True)
    elif has_legs(cfg) and not as_json:
        click.echo(f"{Path(config).name} lists {len(cfg.scenario.legs())} targets: simulating the whole mission, every "
                   "leg (ride, separate, target, task, return, dock, ride on), by the mission's phase machine on the mock "
                   "vehicle's dynamics with the built-in holonomic carrier on random recovery courses", err=True)
    elif is_mission_config(cfg) and not as_json and not (count is not None and is_recovery_config(cfg)):
        start, p2_tol = as_flown(cfg)
        click.echo(f"{Path(config).name} has a [mission] section: the paper's closed loop of what `marsupial run` "
                   f"flies, for the Monte-Carlo: the passenger "
                   f"rides the dock point (carrier + mission.dock_offset_ned_m, starting at {np.round(start, 3).tolist()}) "
                   f"from t = 0, the start of riding (take-off and JOIN are not simulated); P2 = within "
                   f"mission.arrival_radius_m = {p2_tol:g} m", err=True)
    show = not no_progress and sys.stderr.isatty() and not as_json or (not no_progress and count is not None)
    if count is not None and is_recovery_config(cfg):
        return run_recovery_monte_carlo(cfg, Path(config).name, count, seed, show, plot_path, as_json)
    if flies_mission(cfg) and count is None:
        return run_mission(cfg, Path(config).stem, plot_path, as_json, estimate_error, seed)
    if count is not None:
        report = run_monte_carlo(cfg, count, seed, show)
        if as_json:
            click.echo(json.dumps(report, indent=2))
        else:
            click.echo(f"{count} scenarios (seed {seed}): P1 {report['fraction_p1']:.1%}  P2 {report['fraction_p2']:.1%}  "
                       f"P3 {report['fraction_p3']:.1%}  all {report['fraction_all']:.1%}")
            if report["failing"]:
                shown = min(report["failing"], WORST_SHOWN)
                click.echo(f"{report['failing']} failing scenarios (first {shown}; id = index, same --seed replays them):")
            else:
                click.echo("largest final passenger-target distances (id = index, same --seed replays them):")
            for w in report["worst_cases"]:
                click.echo(format_case(w))
            click.echo(f"simulated: {PAPER_FLOWN} (the paper's closed loop)")
        return 0 if report["fraction_all"] == 1.0 else 1
    steps = int(round(cfg.sim.duration_s / cfg.sim.dt_s))
    bar, update = _progress_bar(steps, Path(config).stem, show)
    with bar:
        result = simulate_config(cfg, progress=update)
    summary = {**result.summary(), "simulated": PAPER_FLOWN}
    if plot_path:
        from mission.plots import plot_run

        out = plot_run(trajectories_of(result, cfg, title=f"{Path(config).stem}: separation and navigation"), plot_path)
        log.info("wrote %s", out)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        width = max(len(k) for k in summary)
        for key, value in summary.items():
            click.echo(f"{key:<{width}}  {value}")  # the last row: simulated  paper
        if plot_path:
            click.echo(f"plot written to {plot_path}")
    return 0 if summary["p1"] and summary["p2"] and summary["p3"] else 1
