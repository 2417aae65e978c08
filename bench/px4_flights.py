"""Fly the mission on real PX4 SITL N times and print the table of the real-PX4 targets (docs/flying-px4.md).

Each flight is a fresh PX4 (SIH quadrotor) in its own network namespace with the carrier
simulator and ``marsupial run`` beside it (:mod:`sim.sitl.px4`); ``--parallel 2`` flies two at
once (each PX4 in a namespace of its own). Per flight: P1-P3; the riding offset (largest distance
from the dock point while RIDING; ``riding_2tick_m`` that held for two ticks: a one-tick spike is a
sample read late after a stall); the last metre (from first within 1 m of the target to
ARRIVED); the hover speed (mean horizontal speed while the reference sits on the target, until
the handover); the swing (farthest from the target after first coming within the arrival radius,
until the mission handed the vehicle to PX4's Hold; with several targets the worst leg's, each
against its own target while the reference sat on it); the relative command jump at separation;
the carrier's distance from the target at separation against b c (``sep_err_m``; with several
targets the worst leg's); where PX4's own Hold took it over the next 3 s
(``hold_m``, farthest from the target; not ours to steer, reported beside); PX4's clock against
wall time and the LOCAL_POSITION_NED rate that arrived [Hz of wall time]. A flight whose PX4 clock
ran outside 0.97-1.06x wall time is marked ``clock``, one whose controller or carrier process
stalled for over 0.3 s while flying (``stall_s``: a late tick or an old carrier state; a loaded
machine, not the loop) ``stall``; both are left out of the verdict. Needs root and
``MARSUPIAL_PX4_SITL``.

``--set section.key=VALUE`` changes the configuration (a TOML value; repeatable), e.g.
``--set mission.position_lead=0`` or ``--set scenario.target=[-18.0,24.0,-5.0]``;
``--ground-truth`` also records PX4's estimate and SIH's true state (``truth.csv`` per flight,
:mod:`sim.sitl.ground_truth`).

``--vehicle mock`` flies the same configuration on the mock vehicle (``marsupial demo``) for the
comparison "the mock predicts PX4".

``--rover`` flies the carrier as a second PX4, the SIH Ackermann rover (``configs/px4_sitl_cycle.toml``
unless ``--config`` names another, ``carrier.backend = "mavlink"``), with a 10-minute battery on the quadrotor (``SIM_BAT_DRAIN``
600 s: SITL's own empties in 60 s). A mission that comes home (``mission.final_action =
"return"``) also prints one row per docking (each leg of several targets): its outcome, the
approaches it took, the contact (horizontal error, horizontal and vertical relative speed), the
carrier's speed on the approach, that leg's P1-P3, the carrier's closest approach to the leg's target, its swing and separation
error (per leg: against the leg's own target), and whether PX4's home followed the carrier
(:meth:`sim.sitl.px4.Px4Flight.home_following`); the targets ``RECOVERY_TARGETS``; and per flight
the carrier's closest approach to each target over the whole flight (``closest_each_m``). With
``--rover`` SIH's truth of both vehicles is recorded (``--no-ground-truth``: not) and each flight
also prints its legs against it (:func:`true_figures`, ``TRUE_TARGETS``): the mission's figures
are in two PX4 EKF frames, which disagree by decimetres (docs/recovery.md, "Against SIH's truth").

Usage: ``python -m bench.px4_flights [-n 5] [--config configs/px4_sitl.toml] [--set K=V ...]
[--parallel 1|2] [--vehicle px4|mock] [--rover] [--out DIR] [--json F]`` (about 50-60 s of wall time per PX4
flight). Run it under ``flock /tmp/marsupial-px4.lock``.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import click
import numpy as np

from mission.config.schema import Config, load_config
from mission.phases.phase import FLYING, Phase
from mission.record.figures import summarise
from mission.record.table import read_record
from sim.sitl.px4 import build_dir, clock_ratio, patched_config, px4_flight, unavailable_reason

ROOT = Path(__file__).resolve().parents[1]
TARGETS = {"riding_offset_m": 0.20, "last_metre_s": 4.0, "hover_m_s": 0.2, "swing_m": 0.5, "jump_m_s": 0.05, "sep_err_m": 0.01}
CLOCK_OK = (0.97, 1.06)
STALL_S = 0.3  # a controller tick later than this, or a carrier state this old, while flying: the machine stalled [s]
# A docking on real PX4 (docs/recovery.md, "On real PX4"): approaches, contact error [m], relative
# horizontal speed [m/s], the carrier's slowest on the approach [m/s]; PX4's home within this of
# the carrier's track (HOME_LAG_S) [m]
RECOVERY_TARGETS = {"attempts": 2, "error_m": 0.2, "h_speed_m_s": 0.3}
CARRIER_MIN_SPEED_M_S = 1.0
# The rover pair's targets against SIH's truth [m]: contact error, riding offset, the rover's closest approach (3D)
TRUE_TARGETS = {"contact_m": 0.2, "riding_m": 0.3, "closest_m": 7.0}
HOME_M = 1.0
ROVER_BATTERY = {"SIM_BAT_DRAIN": 600.0}
COLUMNS = ("rc", "p1", "p2", "p3", "riding_offset_m", "riding_2tick_m", "last_metre_s", "hover_m_s", "swing_m", "jump_m_s", "sep_err_m", "hold_m",
           "carrier_closest_m", "clock", "stall_s", "position_hz", "wall_s")


def stall_s(log_dir: Path) -> float | None:
    """The longest the flight was stalled while flying after JOIN [s] (RIDING to ARRIVED, and
    every phase of coming home and of the next legs): the larger of the longest gap between
    controller ticks beyond one period and the oldest carrier state used while riding (a stalled
    carrier or controller process, not the loop: such flights are left out)."""
    if not (log_dir / "record.csv").exists():
        return None
    r = read_record(log_dir)
    flying = np.isin(r.phase, sorted(p.value for p in FLYING - {Phase.JOIN}))
    if flying.sum() < 2:
        return None
    t = r.t[flying]
    gap = float(np.diff(t).max() - np.median(np.diff(t)))
    age = r.cols["carrier_age_s"][r.phase == "RIDING"]
    age = age[np.isfinite(age)]
    return round(max(gap, float(age.max()) if age.size else 0.0), 3)


def riding_sustained_m(log_dir: Path) -> float | None:
    """The riding offset held for at least two ticks [m] (the summary's ``riding_offset_held_m``,
    the worst leg's): a one-tick spike is no vehicle's motion (0.3-0.6 m and back within 20 ms)
    but a sample read late after a stall of the machine (the vehicle's or the carrier's)."""
    if not (log_dir / "record.csv").exists():
        return None
    held = summarise(log_dir).get("riding_offset_held_m")
    return None if held is None else round(float(held), 3)


def closest_each_m(log_dir: Path) -> list[float | None] | None:
    """The carrier's closest approach [m] to each target of the flight over the whole flight (the
    carrier's position as the passenger's controller received it, 3D), whichever leg it served;
    None without a record."""
    if not (log_dir / "record.csv").exists():
        return None
    r = read_record(log_dir)
    x_c = r.vec("x_c")
    x_c = x_c[np.isfinite(x_c).all(axis=1)]
    targets = r.info.get("targets") or [r.info["target_ned_m"]]
    return [round(float(np.linalg.norm(x_c - np.asarray(t, dtype=float), axis=1).min()), 3) if len(x_c) else None
            for t in targets]


def swing_and_sep_err(s: dict[str, Any], sep_m: float) -> tuple[float | None, float | None]:
    """The swing [m] and the separation error [m] of a flight's summary ``s``, ``sep_m`` [m] (b c)
    the separation distance promised. One target: the swing is the farthest from the target after
    first coming within the arrival radius (until the handover to Hold). Several targets (``legs``):
    each leg against its own target, the worst leg: its farthest from the target while the
    reference sat on it (``max_target_distance_at_target_m``, until it left to come home: a leg's
    record goes on through the return, tens of metres away), and its carrier's distance from the
    target at separation against ``sep_m``."""
    legs = [leg for leg in s.get("legs") or [] if "p1" in leg]
    if not legs:
        sep = s.get("carrier_target_distance_at_separation_m")
        return s.get("max_target_distance_after_arrival_m"), None if sep is None else round(abs(sep - sep_m), 4)
    swings = [leg["max_target_distance_at_target_m"] for leg in legs if leg.get("max_target_distance_at_target_m") is not None]
    errs = [abs(leg["carrier_target_distance_at_separation_m"] - sep_m) for leg in legs
            if leg.get("carrier_target_distance_at_separation_m") is not None]
    return (round(max(swings), 4) if swings else None), (round(max(errs), 4) if errs else None)


def _row(s: dict[str, Any], rc: int, t0: float, directory: Path, sep_m: float = 8.0) -> dict[str, Any]:
    swing, sep_err = swing_and_sep_err(s, sep_m)
    return {"rc": rc, "wall_s": round(time.monotonic() - t0, 1), "p1": s.get("p1"), "p2": s.get("p2"), "p3": s.get("p3"),
            "riding_offset_m": s.get("max_offset_before_separation_m"), "last_metre_s": s.get("last_metre_s"),
            "hover_m_s": s.get("hover_speed_m_s"), "swing_m": swing,
            "jump_m_s": s.get("relative_input_jump_m_s"), "sep_err_m": sep_err,
            "position_hz": s.get("position_rate_hz"), "dir": str(directory)}



def dockings(s: dict[str, Any], sep_m: float = 8.0) -> list[dict[str, Any]]:
    """One row per docking of a mission that came home (each leg of several targets), its swing and
    separation error against its own target (:func:`swing_and_sep_err`) and the carrier's closest
    approach to that target [m] (``closest_m``)."""
    legs = s.get("legs") or [{**s, "leg": 0, "outcome": s.get("recovery_outcome")}]
    rows = []
    for leg in legs:
        c = leg.get("contact") or {}
        speed = leg.get("carrier_speed_on_approach_m_s") or [None, None]
        swing, sep_err = swing_and_sep_err({"legs": [leg]} if "p1" in leg else {}, sep_m)
        rows.append({"leg": leg.get("leg"), "outcome": leg.get("outcome"), "docked": bool(c), "attempts": c.get("attempts"),
                     "error_m": c.get("horizontal_error_m"), "h_speed_m_s": c.get("horizontal_relative_speed_m_s"),
                     "v_speed_m_s": c.get("vertical_relative_speed_m_s"), "carrier_min_m_s": speed[0],
                     "carrier_max_m_s": speed[1], "p1": leg.get("p1"), "p2": leg.get("p2"), "p3": leg.get("p3"),
                     "riding_offset_m": leg.get("max_offset_before_separation_m"), "jump_m_s": leg.get("relative_input_jump_m_s"),
                     "deck_violations": leg.get("deck_violations"), "closest_m": leg.get("min_carrier_target_distance_m"),
                     "swing_m": swing, "sep_err_m": sep_err})
    return rows


def docking_meets(d: dict[str, Any], home: dict[str, Any] | None) -> bool:
    return bool(d["docked"] and d["p1"] and d["p2"] and d["p3"] and not d["deck_violations"]
                and all(d[k] is not None and d[k] <= v for k, v in RECOVERY_TARGETS.items())
                and d["carrier_min_m_s"] is not None and d["carrier_min_m_s"] >= CARRIER_MIN_SPEED_M_S - 0.05
                and (home is None or (home["max_lagged_m"] is not None and home["max_lagged_m"] <= HOME_M)))


def true_figures(cfg: Config, directory: Path, log_dir: Path, offset_s: float) -> dict[str, Any] | None:
    """With the rover and ``--ground-truth`` (``truth.csv``, ``truth-rover.csv``: both of SIH's truths
    in the quadrotor's EKF frame, :meth:`sim.sitl.px4.Px4Flight.write_ground_truth`): per leg the
    true horizontal contact error (the quadrotor against the rover's truth plus the dock offset at the
    contact's time) and the true riding offset (its largest over the leg's RIDING, and when, s into
    the ride) [m]; the rover's true closest approach to each target over the flight, 3D [m]; and the
    map check: the median distance [m] between the record's own estimate and PX4's as the observer
    heard it at the mapped time (millimetres when ``offset_s`` [s], which puts the record's wall
    clock on the observer's monotonic one, is right). None without them."""
    from bench.px4_team import _at, _on_monotonic, _read_truth, true_offset_m  # (px4_team imports this module)

    paths = directory / "truth.csv", directory / "truth-rover.csv"
    rec = _on_monotonic(log_dir, offset_s)
    if rec is None or not all(p.exists() for p in paths):
        return None
    (quad_est, quad), (_, rover) = (_read_truth(p) for p in paths)
    if len(quad) < 2 or len(rover) < 2:
        return None
    record, shift = rec
    x = record.vec("x_p")
    ok = np.isfinite(x).all(axis=1)  # the record's own estimate against PX4's as the observer heard it: the clocks' map
    map_check = round(float(np.median(np.linalg.norm(x[ok] - _at(quad_est, record.t[ok] + shift), axis=1))), 3) if ok.any() else None
    slot = np.asarray(cfg.mission.dock_offset_ned_m, dtype=float)

    def offset(t: np.ndarray) -> np.ndarray:
        return true_offset_m(quad, rover, slot, t)

    s = json.loads((log_dir / "summary.json").read_text()) if (log_dir / "summary.json").exists() else {}
    contacts = {leg.get("leg", 0): (leg.get("contact") or {}).get("time_s") for leg in s.get("legs") or [s]}
    legs = []
    for leg in record.legs():
        if leg.record is None:  # not flown
            continue
        t = leg.record.t[leg.record.phase == "RIDING"] + shift
        riding = None
        if len(t):
            off = offset(t)
            k = int(off.argmax())
            riding = [round(float(off[k]), 3), round(float(t[k] - t[0]), 1)]
        tc = contacts.get(leg.k)
        legs.append({"leg": leg.k, "true_riding_m": riding,
                     "true_contact_m": None if tc is None else round(float(offset(np.array([tc + shift]))[0]), 3)})
    targets = [np.asarray(t, dtype=float) for t in cfg.scenario.legs()]
    closest = [round(float(np.linalg.norm(rover[:, 2:5] - t, axis=1).min()), 3) for t in targets]
    return {"legs": legs, "true_closest_each_m": closest, "map_check_m": map_check}


def true_meets(leg: dict[str, Any], truth: dict[str, Any]) -> bool:
    """A leg of :func:`true_figures` docked within :data:`TRUE_TARGETS` against SIH's truth (the
    rover's closest approach to the leg's own target)."""
    closest = truth["true_closest_each_m"]
    return bool(leg["true_contact_m"] is not None and leg["true_contact_m"] <= TRUE_TARGETS["contact_m"]
                and leg["true_riding_m"] is not None and leg["true_riding_m"][0] <= TRUE_TARGETS["riding_m"]
                and leg["leg"] < len(closest) and closest[leg["leg"]] >= TRUE_TARGETS["closest_m"])


def fly_once(config: Path, directory: Path, speed_factor: float, ground_truth_hz: float = 0.0,
             rover: bool = False) -> dict[str, Any]:
    """One flight; its row of the table."""
    cfg = load_config(config)
    t0 = time.monotonic()
    with px4_flight(directory, config, speed_factor=speed_factor, ground_truth_hz=ground_truth_hz, rover=rover,
                    px4_params=ROVER_BATTERY if rover else {},
                    carrier_args=("--summary", str(directory / "carrier.json"), "--mcap", str(directory / "carrier.mcap"))
                    if rover else ()) as f:
        rc = f.wait_mission(400.0)
        comes_home = cfg.mission.final_action == "return"
        after = f.watch_after(cfg.scenario.target, 3.0) if rc == 0 and not comes_home else float("nan")
        home = f.home_following() if rover else None
    path = f.log_dir / "summary.json"
    s = json.loads(path.read_text()) if path.exists() else {}
    clock = clock_ratio(f.log_dir / "flight.tlog") if (f.log_dir / "flight.tlog").exists() else None
    sep_m = cfg.law.b * cfg.law.c
    carrier_path = directory / "carrier.json"
    carrier = json.loads(carrier_path.read_text()) if rover and carrier_path.exists() else {}
    return {**_row(s, rc, t0, directory, sep_m), "hold_m": round(after, 3), "clock": round((clock or {}).get("ratio", float("nan")), 3),
            "stall_s": stall_s(f.log_dir), "riding_2tick_m": riding_sustained_m(f.log_dir), "home": home,
            "carrier_closest_m": carrier.get("closest_target_distance_m"), "closest_each_m": closest_each_m(f.log_dir),
            "dockings": dockings(s, sep_m) if s.get("docked_again") is not None or s.get("legs") else None,
            "truth": true_figures(cfg, directory, f.log_dir, f.monotonic_offset_s) if rover and ground_truth_hz > 0 else None}


def fly_mock(config: Path, directory: Path, speed: float, seed: int) -> dict[str, Any]:
    """The same mission on the mock vehicle as shipped (``marsupial demo --config``, three processes,
    ``speed`` its pace, its estimate's errors drawn from ``seed``); its row."""
    t0 = time.monotonic()
    directory.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run([sys.executable, "-m", "mission.cli", "demo", "--config", str(config), "--speed", str(speed),
                           "--log-root", str(directory), "--plot", str(directory / "flight.png"), "--timeout", "300",
                           "--seed", str(seed)],
                          capture_output=True, text=True, cwd=ROOT)
    s = json.loads((directory / "pair0" / "summary.json").read_text())
    law = load_config(config).law
    return {**_row(s, proc.returncode, t0, directory, law.b * law.c), "hold_m": None, "clock": None, "stall_s": stall_s(directory / "pair0"),
            "riding_2tick_m": riding_sustained_m(directory / "pair0")}


def clock_ok(row: dict[str, Any]) -> bool:
    return row["clock"] is None or CLOCK_OK[0] <= row["clock"] <= CLOCK_OK[1]


def usable(row: dict[str, Any]) -> bool:
    """PX4's clock near wall time and no stall of the machine (``STALL_S``) while flying."""
    return clock_ok(row) and (row["stall_s"] is None or row["stall_s"] <= STALL_S)


def meets(row: dict[str, Any]) -> bool:
    return bool(row["rc"] == 0 and row["p1"] and row["p2"] and row["p3"] and all(
        row[k] is not None and row[k] <= v for k, v in TARGETS.items()))


def _fmt(value: Any) -> str:
    return f"{value:.3f}" if isinstance(value, float) else str(value)


@click.command()
@click.option("-n", "flights", type=int, default=5, show_default=True)
@click.option("--config", type=click.Path(dir_okay=False, exists=True), default=None,
              help="[default: configs/px4_sitl.toml, configs/px4_sitl_cycle.toml with --rover]")
@click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE", help="Change the configuration (TOML value).")
@click.option("--out", type=click.Path(file_okay=False), default=None, help="Where the flights' logs go (default a temp dir).")
@click.option("--speed-factor", type=float, default=None, help="PX4_SIM_SPEED_FACTOR [default: 1.03, 1.08 with --rover]")
@click.option("--parallel", type=click.IntRange(1, 2), default=1, show_default=True, help="PX4 flights at once")
@click.option("--ground-truth/--no-ground-truth", default=None,
              help="Record PX4's estimate and SIH's truth at 50 Hz (truth.csv per flight; with --rover also "
                   "truth-rover.csv, and the dockings judged against the truth too) [default: on with --rover]")
@click.option("--vehicle", type=click.Choice(["px4", "mock"]), default="px4", show_default=True,
              help="real PX4 SITL, or the mock vehicle (marsupial demo with the same config; 'clock' is its speed)")
@click.option("--mock-speed", type=float, default=2.0, show_default=True)
@click.option("--rover", is_flag=True, help="The carrier a second PX4, the SIH rover (configs/px4_sitl_cycle.toml); "
              "PX4_SIM_SPEED_FACTOR 1.08 unless given")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None)
@click.option("--compare", "compare_path", type=click.Path(dir_okay=False, exists=True), default=None,
              help="Print these flights' mean riding offset, last metre and hover speed against a figures file's "
                   "(--record-figures; tests/data/px4_hold_figures.json) and the ratio, within +-30 %?")
@click.option("--record-figures", type=click.Path(dir_okay=False), default=None,
              help="Write the usable flights' riding offset, last metre and hover speed (and their means) to this "
                   "JSON file: tests/data/px4_hold_figures.json, what the mock is held to.")
def main(flights: int, config: str | None, sets: tuple[str, ...], out: str | None, speed_factor: float | None, parallel: int,
         ground_truth: bool | None, vehicle: str, mock_speed: float, rover: bool, json_path: str | None,
         record_figures: str | None, compare_path: str | None) -> None:
    why = unavailable_reason() if vehicle == "px4" else None
    if why:
        raise click.ClickException(why)
    speed_factor = speed_factor if speed_factor is not None else 1.08 if rover else 1.03
    ground_truth = rover if ground_truth is None else ground_truth  # two PX4 EKFs: the estimates are not the truth
    config = config or str(ROOT / "configs" / ("px4_sitl_cycle.toml" if rover else "px4_sitl.toml"))
    base = Path(out or f"/tmp/px4-flights-{os.getpid()}")
    base.mkdir(parents=True, exist_ok=True)
    cfg_path = Path(config).resolve()  # the flight's processes run from the repository
    if sets:
        overrides = dict(s.split("=", 1) for s in sets)
        cfg_path = base / "config.toml"
        cfg_path.write_text(patched_config(Path(config).read_text(), overrides))
        load_config(cfg_path)  # a bad override fails here, naming the field
    click.echo(f"{'PX4 build ' + str(build_dir()) if vehicle == 'px4' else 'mock vehicle'}, config {config} {' '.join(sets)}, "
               f"{flights} flights ({parallel} at once), PX4_SIM_SPEED_FACTOR {speed_factor}, load {os.getloadavg()[0]:.1f}")
    click.echo("flight " + " ".join(f"{c:>15}" for c in COLUMNS) + "  targets")

    def one(i: int) -> dict[str, Any]:
        try:
            if vehicle == "px4":
                row = fly_once(cfg_path, base / f"flight{i}", speed_factor, 50.0 if ground_truth else 0.0, rover)
            else:
                row = fly_mock(cfg_path, base / f"mock{i}", mock_speed, seed=i + 1)
        except Exception as exc:  # a PX4 that did not start on a loaded machine: the flight is marked, the rest fly
            row = {**{c: None for c in COLUMNS}, "clock": float("nan"), "error": f"{type(exc).__name__}: {exc}",
                   "dir": str(base / f"flight{i}")}
        (base / f"row{i}.json").write_text(json.dumps(row, indent=1, default=str))
        return row

    rows: list[dict[str, Any]] = []
    with ThreadPoolExecutor(max_workers=parallel) as pool:
        futures = []
        for i in range(flights):
            futures.append(pool.submit(one, i))
            if parallel > 1 and i < parallel:
                time.sleep(2.0)  # the two PX4s do not start in the same second
        for i, fut in enumerate(futures):
            row = fut.result()
            rows.append(row)
            verdict = "clock" if not clock_ok(row) else "stall" if not usable(row) else ("met" if meets(row) else "MISSED")
            click.echo(f"{i:>6} " + " ".join(f"{_fmt(row.get(c)):>15}" for c in COLUMNS) + f"  {verdict}")
    if any(r.get("dockings") is not None for r in rows):
        print_dockings(rows)
    good = [r for r in rows if usable(r)]
    ok = sum(meets(r) for r in good)
    worst = {k: max((r[k] for r in good if r[k] is not None), default=None) for k in TARGETS}
    click.echo(f"{ok}/{len(good)} flights with PX4's clock within {CLOCK_OK} and no stall over {STALL_S} s meet every target "
               f"({TARGETS}, P1-P3); worst: {worst}; logs in {base}")
    if json_path:
        Path(json_path).write_text(json.dumps(rows, indent=2))
    if compare_path:
        click.echo(compare_table(good, json.loads(Path(compare_path).read_text()), compare_path))
    if record_figures:
        write_figures(Path(record_figures), [Path(r["dir"]) / "flight" for r in good],
                      f"python -m bench.px4_flights -n {flights} --config {config} " + " ".join(f"--set {x}" for x in sets))


DOCKING_COLUMNS = ("leg", "outcome", "attempts", "error_m", "h_speed_m_s", "v_speed_m_s", "carrier_min_m_s", "carrier_max_m_s",
                   "p1", "p2", "p3", "riding_offset_m", "jump_m_s", "deck_violations", "closest_m", "swing_m", "sep_err_m")


def print_dockings(rows: list[dict[str, Any]]) -> None:
    """The dockings' table: one row per docking, PX4's home per flight, and the verdict."""
    click.echo("flight " + " ".join(f"{c:>15}" for c in DOCKING_COLUMNS) + "  home (homes, moved, max lagged, final m)  targets")
    met = total = true_met = true_total = 0
    for i, row in enumerate(rows):
        home = row.get("home")
        h = "-" if home is None else f"{home['homes']}, {home['moved_m']}, {home['max_lagged_m']}, {home['final_m']}"
        for d in row.get("dockings") or []:
            ok = docking_meets(d, home)
            met, total = met + ok, total + 1
            click.echo(f"{i:>6} " + " ".join(f"{_fmt(d[c]):>15}" for c in DOCKING_COLUMNS) + f"  {h:>40}  {'met' if ok else 'MISSED'}")
        truth = row.get("truth")
        if truth is not None:
            verdicts = [true_meets(d, truth) for d in truth["legs"]]
            true_met, true_total = true_met + sum(verdicts), true_total + len(verdicts)
            click.echo(f"{i:>6} against SIH's truth: per leg (riding max [m], s into the ride; contact [m]) "
                       + "; ".join(f"{d['leg']}: {d['true_riding_m']}; {d['true_contact_m']} {'met' if ok else 'MISSED'}"
                                   for d, ok in zip(truth["legs"], verdicts))
                       + f"; the rover's closest to each target, 3D [m]: {truth['true_closest_each_m']} "
                       f"(record-to-truth map check {truth.get('map_check_m')} m)")
        if row.get("closest_each_m") is not None:
            click.echo(f"{i:>6} the carrier's closest approach to each target over the flight [m]: {row['closest_each_m']} "
                       f"(its own figure, to any: {_fmt(row.get('carrier_closest_m'))}; stall {_fmt(row.get('stall_s'))} s)")
    click.echo(f"{met}/{total} dockings meet every target ({RECOVERY_TARGETS}, the carrier at >= {CARRIER_MIN_SPEED_M_S} m/s "
               f"on the approach, P1-P3 of the leg, no deck violation, PX4's home, when read, within {HOME_M} m of the carrier's track)")
    if true_total:
        click.echo(f"{true_met}/{true_total} legs meet the targets against SIH's truth ({TRUE_TARGETS})")


FIGURES = ("max_offset_before_separation_m", "last_metre_s", "hover_speed_m_s")


ROW_OF_FIGURE = {"max_offset_before_separation_m": "riding_2tick_m", "last_metre_s": "last_metre_s",
                 "hover_speed_m_s": "hover_m_s"}
FIDELITY = 0.3  # the mock is PX4-faithful within this fraction of PX4's figure [-]


def compare_table(rows: list[dict[str, Any]], figures: dict[str, Any], source: str) -> str:
    """These flights' mean of each figure (the riding offset as held for two ticks) against the
    mean of ``figures`` (:func:`write_figures`' file), their ratio and whether within ``FIDELITY``."""
    lines = [f"{'figure':32s} {'these (mean)':>13s} {'reference':>10s} {'ratio':>6s}  within +-{FIDELITY:.0%}  "
             f"({len(rows)} flights here, {len(figures['flights'])} in {source})"]
    for name in FIGURES:
        mine = [r[ROW_OF_FIGURE[name]] for r in rows if r.get(ROW_OF_FIGURE[name]) is not None]
        ref = figures["mean"][name]
        mean = float(np.mean(mine)) if mine else float("nan")
        ratio = mean / ref
        lines.append(f"{name:32s} {mean:13.3f} {ref:10.3f} {ratio:6.2f}  {'yes' if abs(ratio - 1) <= FIDELITY else 'NO'}"
                     f"  (range {min(mine, default=float('nan')):.3f}-{max(mine, default=float('nan')):.3f})")
    return "\n".join(lines)


def write_figures(path: Path, log_dirs: list[Path], command: str) -> None:
    """The figures the mock is held to, per flight and their means (``summary.json`` keys; the
    riding offset as held for two ticks, :func:`riding_sustained_m`: the mock, in lockstep, never
    reads a late sample)."""
    flights = []
    for log_dir in log_dirs:
        s = json.loads((log_dir / "summary.json").read_text())
        figures = {**{k: s.get(k) for k in FIGURES}, "max_offset_before_separation_m": riding_sustained_m(log_dir)}
        if all(v is not None for v in figures.values()):
            flights.append(figures)
    path.write_text(json.dumps({
        "what": "real PX4 SITL flights of configs/px4_sitl.toml (SIH quadrotor, PX4_SIM_SPEED_FACTOR 1.03); the flights "
                "whose PX4 clock ran off or whose processes stalled left out; riding offset as held for two ticks "
                "(bench/px4_flights.py)",
        "command": command, "flights": flights,
        "mean": {k: round(float(np.mean([f[k] for f in flights])), 4) for k in FIGURES}}, indent=2) + "\n")


if __name__ == "__main__":
    main()
