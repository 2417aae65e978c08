"""Fly relative navigation on real PX4 SITL: a SIH quadrotor passenger docking on the SIH rover
carrier with no shared frame (docs/relnav.md, "On real PX4 SITL").

One flight per call of :func:`fly`: two fresh PX4s in one network namespace (:mod:`sim.sitl.px4`;
the quadrotor on instance 0 with a 10-minute battery, the rover on ``carrier.mavlink.target_system
- 1`` with its speed loop closed), then in the namespace ``marsupial carrier FILE`` (the rover's
``mavlink`` backend wrapped in the world's carrier GNSS errors, ``world.carrier_gnss``: its
published state carries a bias of metres), the camera node ``python -m sim.sitl.camera FILE``
(frames rendered from SIH's truth of both vehicles, :mod:`sim.sitl.camera`; it also records both
truths) and ``marsupial run FILE``. ``--seed`` draws the carrier's GNSS errors
(``world.carrier_gnss.seed``) and the camera's sensor noise.

Per leg it prints: docked, approaches, the contact error by the estimate (the mission's own
figure) and in TRUTH (at the contact's time, the passenger's true horizontal position against the
rover's true position plus ``mission.dock_offset_ned_m``, SIH's truth as the camera node received
it, on ``CLOCK_MONOTONIC``; the mission's record put on that clock through its flight log's epoch,
as :mod:`bench.px4_team`), the true riding offset (the same difference while RIDING in that leg:
median and max, horizontal; with the time into the ride of the max and the rover's true speed
then), the rover's true closest approach to the leg's target over the whole flight (3D, as P3's
figure, and horizontal), and the carrier's GNSS error as published (its published position
against the rover's truth at the publication's log time: median horizontal, over the flight).
``--table DIR...`` prints the legs of flights already flown, one line each, and their count
against the targets (:func:`leg_meets`).

The bench stops the mission :data:`bench.px4_team.HOME_S` after it entered HOME (the last leg
docked, riding the carrier while it parks) if it has not ended by then. HOME hands the vehicle to
Hold once the carrier's mean speed over its velocity window is under 0.1 m/s with the vehicle
within the contact conditions for the dwell; before that rule counted the window's mean
(docs/relnav.md), the filter's noisy speed over the parked rover kept HOME going for 138 s (seed 10).

Usage (root, ``MARSUPIAL_PX4_SITL``; one flight a call, about 3-4 min of wall time):
``flock /work/wt/px4.lock nice -n 15 python -m bench.px4_relnav --out DIR [--config configs/px4_sitl_relnav.toml] [--seed N]``.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import click
import numpy as np

from bench.px4_flights import ROVER_BATTERY, dockings
from bench.px4_team import (HOME_S, OFFBOARD_PORT, STATUS_TOPIC, Progress, _at, _home_set, _on_monotonic,
                            _read_truth, instance_of, start_px4s, true_offset_m)
from mission.config.schema import load_config
from mission.flightdata.read import read_messages
from sim.net import stop_process, wait_for
from sim.sitl import ground_truth
from sim.sitl.px4 import (QUAD_AIRFRAME, ROVER_AIRFRAME, ROVER_PARAMS, NetNamespace, build_dir, clock_ratio_of,
                          patched_config, unavailable_reason)

ROOT = Path(__file__).resolve().parents[1]
CONTACT_M = 0.2  # [m] the PX4 target of docs/relnav.md: true contact error
ATTEMPTS = 2  # ... docked within this many approaches
RIDING_M = 0.3  # [m] ... and the true riding offset, horizontal, at most this all the ride long
CLOSEST_M = 7.0  # [m] ... and the rover truly never closer than this to the leg's target (b c - margin, less 0.5 m)
PAIR_DIR = "pair0"


def _popen(ns: NetNamespace, directory: Path, name: str, module: str, args: list[str],
           stack: ExitStack) -> subprocess.Popen[bytes]:
    out, err = open(directory / f"{name}.out", "ab"), open(directory / f"{name}.err", "ab")
    stack.callback(err.close)
    stack.callback(out.close)
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    proc = subprocess.Popen(ns.command([sys.executable, "-m", module, *args]), stdout=out, stderr=err, env=env, cwd=ROOT,
                            stdin=subprocess.DEVNULL)
    stack.callback(stop_process, proc)
    return proc


def published_error(directory: Path, offset_s: float, rover_truth: np.ndarray) -> dict[str, Any] | None:
    """The carrier's published position minus the rover's truth at its log time [m], horizontal:
    median over the flight and over its first 10 s (``carrier.mcap``'s status; None without it)."""
    path = directory / "carrier.mcap"
    if not path.exists() or len(rover_truth) < 2:
        return None
    rows = []
    for _, _, log_ns, data in read_messages(path, topics={STATUS_TOPIC}).messages:
        st = json.loads(data)
        if st.get("published") and st.get("position"):
            p = st["position"]
            rows.append((log_ns * 1e-9 - offset_s, p["n"], p["e"]))
    r = np.asarray(rows).reshape(-1, 3)
    r = r[(r[:, 0] >= rover_truth[0, 0]) & (r[:, 0] <= rover_truth[-1, 0])]
    if not len(r):
        return None
    err = r[:, 1:3] - _at(rover_truth, r[:, 0])[:, :2]
    size = np.hypot(err[:, 0], err[:, 1])
    first = r[:, 0] < r[0, 0] + 10.0
    return {"median_m": round(float(np.median(size)), 3), "first_10s_m": round(float(np.median(size[first])), 3),
            "first_10s_ne_m": [round(float(v), 2) for v in np.median(err[first], axis=0)]}


def _rover_velocity(path: Path) -> np.ndarray:
    """The rover's true horizontal velocity [m/s] as rows ``t, north, east`` (``truth-rover.csv``)."""
    if not path.exists():
        return np.zeros((0, 3))
    c = ground_truth.read_csv(path)
    rows = np.column_stack([c["t_rx_s"], c["true_vx"], c["true_vy"]])
    return rows[np.isfinite(rows).all(axis=1)]


def analyse(config: Path, directory: Path, offset_s: float) -> dict[str, Any]:
    """The flight's legs and figures (module docstring) from its logs and the camera node's truth."""
    cfg = load_config(config)
    log_dir = directory / PAIR_DIR
    s = json.loads((log_dir / "summary.json").read_text()) if (log_dir / "summary.json").exists() else {}
    est, truth = {}, {}
    for name in ("passenger", "rover"):
        path = directory / f"truth-{name}.csv"
        est[name], truth[name] = _read_truth(path) if path.exists() else (np.zeros((0, 5)), np.zeros((0, 5)))
    have_truth = len(truth["passenger"]) > 1 and len(truth["rover"]) > 1
    rover_v = _rover_velocity(directory / "truth-rover.csv")
    slot = np.asarray(cfg.mission.dock_offset_ned_m, dtype=float)
    rec = _on_monotonic(log_dir, offset_s)

    def true_offset(t: np.ndarray) -> np.ndarray:
        return true_offset_m(truth["passenger"], truth["rover"], slot, t)

    legs = []
    leg_records = {leg.k: leg.record for leg in rec[0].legs()} if rec is not None else {}
    targets = [np.asarray(t, dtype=float) for t in cfg.scenario.legs()]
    for d, leg in zip(dockings(s, cfg.law.b * cfg.law.c), s.get("legs") or [s]):
        contact = leg.get("contact") or {}
        true_err = riding = closest = None
        if contact and rec is not None and have_truth:
            true_err = round(float(true_offset(np.array([contact["time_s"] + rec[1]]))[0]), 3)
        lr = leg_records.get(d["leg"])
        if lr is not None and rec is not None and have_truth:
            t = lr.t[lr.phase == "RIDING"] + rec[1]
            if len(t):
                off = true_offset(t)
                k = int(off.argmax())
                v = np.column_stack([np.interp(t[k:k + 1], rover_v[:, 0], rover_v[:, j]) for j in (1, 2)])[0]
                riding = [round(float(np.median(off)), 3), round(float(off[k]), 3), round(float(t[k] - t[0]), 1),
                          round(float(np.hypot(*v)), 2)]
        if d["leg"] is not None and d["leg"] < len(targets) and len(truth["rover"]):
            gap = truth["rover"][:, 2:5] - targets[d["leg"]]
            closest = [round(float(np.linalg.norm(gap, axis=1).min()), 2), round(float(np.hypot(gap[:, 0], gap[:, 1]).min()), 2)]
        legs.append({**d, "true_error_m": true_err, "true_riding_m": riding, "true_closest_m": closest,
                     "estimate_error_at_contact_m": contact.get("estimate_error_m")})
    map_check = None
    if rec is not None and len(est["passenger"]):
        x = rec[0].vec("x_p")
        ok = np.isfinite(x).all(axis=1)
        if ok.sum():
            map_check = round(float(np.median(np.linalg.norm(x[ok] - _at(est["passenger"], rec[0].t[ok] + rec[1]), axis=1))), 3)
    clocks = {n: round(clock_ratio_of(e[:, 0], e[:, 1]), 3) if len(e) > 10 else None for n, e in est.items()}
    camera = json.loads((directory / "camera.json").read_text()) if (directory / "camera.json").exists() else {}
    return {"legs": legs, "published_error": published_error(directory, offset_s, truth["rover"]), "clocks": clocks,
            "map_check_m": map_check, "camera": camera, "feeds": s.get("feeds"), "outcome": s.get("recovery_outcome")}


def fly(config: Path, directory: Path, seed: int, speed_factor: float = 1.08,
        overrides: dict[str, str] | None = None, camera_on: bool = True) -> dict[str, Any]:
    """One flight of ``config`` (seeded ``seed``; ``overrides`` ``section.key`` -> TOML value) on two
    fresh PX4s; its figures (:func:`analyse`). ``camera_on`` False: no camera node (no marker, no
    truth recorded)."""
    directory.mkdir(parents=True, exist_ok=True)
    text = patched_config(config.read_text(), {**(overrides or {}), "world.carrier_gnss.seed": str(seed)})
    flown = directory / "config.toml"
    flown.write_text(text)
    cfg = load_config(flown)
    build = build_dir()
    assert build is not None
    rover_sysid = cfg.carrier.mavlink.target_system
    passenger_sysid = cfg.mavlink.target_system
    if rover_sysid is None or passenger_sysid is None:
        raise click.ClickException("mavlink.target_system and carrier.mavlink.target_system must name the PX4s")
    load = os.getloadavg()
    t0 = time.monotonic()
    codes: dict[str, int | None] = {}
    with ExitStack() as stack:
        vehicles = [("passenger", instance_of(passenger_sysid), QUAD_AIRFRAME, ROVER_BATTERY),
                    ("rover", instance_of(rover_sysid), ROVER_AIRFRAME, ROVER_PARAMS)]
        ns = start_px4s(stack, build, vehicles, speed_factor, directory)
        for _, instance, _, _ in vehicles:
            path = directory / f"px4-{instance}.out"
            wait_for(lambda: _home_set(path), 90.0, f"'home set' in {path.name}")
        armable_s = time.monotonic() - t0
        offset_s = time.time() - time.monotonic()
        endpoint = "tcp/127.0.0.1:7450"
        carrier = _popen(ns, directory, "carrier", "mission.cli", [
            "-v", "carrier", str(flown), "--zenoh-listen", endpoint, "--summary", str(directory / "carrier.json"),
            "--mcap", str(directory / "carrier.mcap")], stack)
        camera = _popen(ns, directory, "camera", "sim.sitl.camera", [
            str(flown), "--vehicle-sysid", str(passenger_sysid), "--carrier-sysid", str(rover_sysid), "--seed", str(seed),
            "--truth-dir", str(directory), "--zenoh-connect", endpoint], stack) if camera_on else None
        mission = _popen(ns, directory, PAIR_DIR, "mission.cli", [
            "-v", "run", str(flown), "--mavlink", f"udpin:127.0.0.1:{OFFBOARD_PORT + instance_of(passenger_sysid)}",
            "--zenoh-connect", endpoint, "--log-dir", str(directory / PAIR_DIR)], stack)
        progress = Progress(directory, [PAIR_DIR], t0)
        deadline = time.monotonic() + cfg.mission.max_duration_s + 60.0
        home_since = None
        while mission.poll() is None and time.monotonic() < deadline:
            progress.poll()
            if home_since is None and "] phase HOME" in (directory / f"{PAIR_DIR}.out").read_text(errors="replace"):
                home_since = time.monotonic()
            if home_since is not None and time.monotonic() - home_since > HOME_S:
                click.echo(f"  {HOME_S:g} s in HOME after the last dock: the mission is stopped (module docstring)")
                stop_process(mission, 30.0)
                break
            time.sleep(1.0)
        progress.poll()
        if mission.poll() is None:
            click.echo("  the mission still ran at its deadline: stopped")
            stop_process(mission, 30.0)
        codes["mission"] = mission.returncode
        stop_process(carrier, 10.0)  # writes carrier.json
        codes["carrier"] = carrier.returncode
        if camera is not None:
            stop_process(camera, 20.0)  # writes the truth and camera.json
            codes["camera"] = camera.returncode
    (directory / "clock_offset.json").write_text(json.dumps({"unix_minus_monotonic_s": offset_s}) + "\n")
    return {**analyse(flown, directory, offset_s), "seed": seed, "exit_codes": codes, "armable_after_s": round(armable_s, 1),
            "wall_s": round(time.monotonic() - t0, 1), "load_before": [round(x, 2) for x in load],
            "load_after": [round(x, 2) for x in os.getloadavg()], "dir": str(directory)}


def leg_meets(leg: dict[str, Any]) -> bool:
    """The PX4 targets for one leg (docs/relnav.md, "On real PX4 SITL"): docked within 2 approaches,
    true contact error <= 0.2 m, true riding offset <= 0.3 m all the ride long, the rover truly never
    within 7.0 m of the leg's target."""
    riding, closest = leg.get("true_riding_m"), leg.get("true_closest_m")
    return bool(leg["docked"] and leg["attempts"] is not None and leg["attempts"] <= ATTEMPTS
                and leg["true_error_m"] is not None and leg["true_error_m"] <= CONTACT_M
                and riding is not None and riding[1] <= RIDING_M and closest is not None and closest[0] >= CLOSEST_M)


def table(dirs: list[Path]) -> list[str]:
    """One line per leg of the flights in ``dirs`` (each one's ``row.json``), then the count."""
    lines = ["| seed | leg | approaches | true contact [m] | true riding median / max [m] (at s into the ride, rover m/s) "
             "| rover's true closest, 3D / horizontal [m] | meets |", "|---|---|---|---|---|---|---|"]
    met = total = 0
    for d in dirs:
        row = json.loads((d / "row.json").read_text())
        for leg in row["legs"]:
            r, c = leg.get("true_riding_m") or [None] * 4, leg.get("true_closest_m") or [None, None]
            ok = leg_meets(leg)
            met, total = met + ok, total + 1
            lines.append(f"| {row.get('seed')} | {leg['leg']} | {_fmt(leg.get('attempts'))} | {_fmt(leg.get('true_error_m'))} "
                         f"| {_fmt(r[0])} / {_fmt(r[1])} ({_fmt(r[2] if len(r) > 2 else None)} s, {_fmt(r[3] if len(r) > 3 else None)}) "
                         f"| {_fmt(c[0])} / {_fmt(c[1])} | {'yes' if ok else 'no'} |")
    lines.append(f"{met}/{total} legs meet every target (docked within {ATTEMPTS} approaches, true contact <= {CONTACT_M} m, "
                 f"true riding <= {RIDING_M} m, the rover >= {CLOSEST_M} m from the target)")
    return lines


def _fmt(v: Any) -> str:
    return f"{v:.3f}" if isinstance(v, float) else "-" if v is None else str(v)


COLUMNS = ("leg", "outcome", "docked", "attempts", "error_m", "true_error_m", "true_riding_m", "true_closest_m", "p1", "p2", "p3")


def report(row: dict[str, Any]) -> list[str]:
    lines = ["  " + " ".join(f"{c:>14}" for c in COLUMNS)]
    for leg in row["legs"]:
        lines.append("  " + " ".join(f"{_fmt(leg.get(c)):>14}" for c in COLUMNS))
    cam = row.get("camera") or {}
    lines.append(f"  carrier's published GNSS error (vs the rover's truth): {row.get('published_error')}")
    lines.append(f"  camera: {cam.get('frames_sent')} frames of {cam.get('captured')} captures; marker feed "
                 f"{(row.get('feeds') or {}).get('marker') if isinstance(row.get('feeds'), dict) else row.get('feeds')}")
    lines.append(f"  PX4 clocks {row['clocks']}; record-to-truth map check {row['map_check_m']} m; exit codes "
                 f"{row.get('exit_codes')}; load {row.get('load_before')} -> {row.get('load_after')}; {row.get('wall_s')} s; "
                 f"outcome {row.get('outcome')}")
    return lines


@click.command()
@click.option("--config", type=click.Path(dir_okay=False, exists=True), default=str(ROOT / "configs" / "px4_sitl_relnav.toml"),
              show_default=True)
@click.option("--out", type=click.Path(file_okay=False), help="The flight's logs and its row (row.json).")
@click.option("--seed", type=int, default=0, show_default=True, help="world.carrier_gnss.seed and the camera's noise")
@click.option("--speed-factor", type=float, default=1.08, show_default=True, help="PX4_SIM_SPEED_FACTOR of both PX4s")
@click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE", help="Change the configuration (TOML value).")
@click.option("--no-camera", is_flag=True, help="No camera node: the marker never seen (and no truth recorded).")
@click.option("--analyse", "again", is_flag=True, help="Do not fly: analyse the flight already in --out again.")
@click.option("--table", "tabled", is_flag=True, help="Do not fly: print the legs of the flights FLOWN (their row.json).")
@click.argument("flown", nargs=-1, type=click.Path(file_okay=False, exists=True))
def main(config: str, out: str | None, seed: int, speed_factor: float, sets: tuple[str, ...], no_camera: bool, again: bool,
         tabled: bool, flown: tuple[str, ...]) -> None:
    """Fly CONFIG's relative navigation once on real PX4 SITL and print its legs (``--table FLOWN...``:
    print the legs of flights already flown, one line each)."""
    if tabled:
        for line in table([Path(d) for d in flown]):
            click.echo(line)
        return
    if out is None:
        raise click.UsageError("--out is required to fly or analyse")
    directory = Path(out).resolve()
    if again:
        row_path = directory / "row.json"  # a flight the bench did not finish (a test's) has none
        row = json.loads(row_path.read_text()) if row_path.exists() else {}
        offset_s = json.loads((directory / "clock_offset.json").read_text())["unix_minus_monotonic_s"]
        row.update(analyse(directory / "config.toml", directory, offset_s))
    else:
        why = unavailable_reason()
        if why:
            raise click.ClickException(why)
        click.echo(f"PX4 build {build_dir()}, config {config}, seed {seed}, load {os.getloadavg()}")
        row = fly(Path(config).resolve(), directory, seed, speed_factor, dict(x.split("=", 1) for x in sets),
                  camera_on=not no_camera)
    (directory / "row.json").write_text(json.dumps(row, indent=1, default=str) + "\n")
    for line in report(row):
        click.echo(line)
    click.echo(f"{sum(leg_meets(leg) for leg in row['legs'])}/{len(row['legs'])} legs docked within {ATTEMPTS} approaches "
               f"at a true contact error <= {CONTACT_M} m, riding <= {RIDING_M} m, the rover >= {CLOSEST_M} m from "
               f"the target; logs in {out}")


if __name__ == "__main__":
    main()
