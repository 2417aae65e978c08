"""Fly the mission on real PX4 SITL N times and print the table of the real-PX4 targets (docs/flying-px4.md).

Each flight is a fresh PX4 (SIH quadrotor) in its own network namespace with the carrier
simulator and ``marsupial run`` beside it (:mod:`sim.sitl.px4`); ``--parallel 2`` flies two at
once (each PX4 in a namespace of its own). Per flight: P1-P3; the riding offset (largest distance
from the dock point while RIDING); the last metre (from first within 1 m of the target to
ARRIVED); the hover speed (mean horizontal speed while the reference sits on the target, until
the handover); the swing (farthest from the target after first coming within the arrival radius,
until the mission handed the vehicle to PX4's Hold); the relative command jump at separation; the
carrier's distance from the target at separation; where PX4's own Hold took it over the next 3 s
(``hold_m``, farthest from the target; not ours to steer, reported beside); PX4's clock against
wall time and the LOCAL_POSITION_NED rate that arrived [Hz of wall time]. A flight whose PX4 clock
ran outside 0.97-1.06x wall time is marked ``clock`` and left out of the verdict. Needs root and
``MARSUPIAL_PX4_SITL``.

``--set section.key=VALUE`` changes the configuration (a TOML value; repeatable), e.g.
``--set mission.position_lead=0`` or ``--set scenario.target=[-18.0,24.0,-5.0]``;
``--ground-truth`` also records PX4's estimate and SIH's true state (``truth.csv`` per flight,
:mod:`sim.sitl.ground_truth`).

``--vehicle mock`` flies the same configuration on the mock vehicle (``marsupial demo``) for the
comparison "the mock predicts PX4".

Usage: ``python -m bench.px4_flights [-n 5] [--config configs/px4_sitl.toml] [--set K=V ...]
[--parallel 1|2] [--vehicle px4|mock] [--out DIR] [--json F]`` (about 50-60 s of wall time per PX4
flight). Run it under ``flock /tmp/marsupial-px4.lock``.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import click

from mission.config.schema import load_config
from sim.sitl.px4 import build_dir, clock_ratio, px4_flight, unavailable_reason

ROOT = Path(__file__).resolve().parents[1]
TARGETS = {"riding_offset_m": 0.20, "last_metre_s": 4.0, "hover_m_s": 0.2, "swing_m": 0.5, "jump_m_s": 0.05, "sep_err_m": 0.01}
CLOCK_OK = (0.97, 1.06)
COLUMNS = ("rc", "p1", "p2", "p3", "riding_offset_m", "last_metre_s", "hover_m_s", "swing_m", "jump_m_s", "sep_err_m", "hold_m",
           "clock", "position_hz", "wall_s")


def patched_config(text: str, overrides: dict[str, str]) -> str:
    """``text`` (TOML) with ``section.key = value`` lines replaced, or added at the top of their
    section (``value`` a TOML literal)."""
    for dotted, value in overrides.items():
        section, key = dotted.rsplit(".", 1)
        header = re.search(rf"^\[{re.escape(section)}\]\s*$", text, flags=re.M)
        if header is None:
            text = f"{text.rstrip()}\n\n[{section}]\n{key} = {value}\n"
            continue
        nxt = re.search(r"^\[", text[header.end():], flags=re.M)
        end = header.end() + (nxt.start() if nxt else len(text) - header.end())
        body = text[header.end():end]
        line = re.compile(rf"^{re.escape(key)}\s*=.*$", flags=re.M)
        body = line.sub(f"{key} = {value}", body, count=1) if line.search(body) else f"\n{key} = {value}{body}"
        text = text[:header.end()] + body + text[end:]
    return text


def _row(s: dict[str, Any], rc: int, t0: float, directory: Path) -> dict[str, Any]:
    sep = s.get("carrier_target_distance_at_separation_m")
    return {"rc": rc, "wall_s": round(time.monotonic() - t0, 1), "p1": s.get("p1"), "p2": s.get("p2"), "p3": s.get("p3"),
            "riding_offset_m": s.get("max_offset_before_separation_m"), "last_metre_s": s.get("last_metre_s"),
            "hover_m_s": s.get("hover_speed_m_s"), "swing_m": s.get("max_target_distance_after_arrival_m"),
            "jump_m_s": s.get("relative_input_jump_m_s"), "sep_err_m": None if sep is None else round(abs(sep - 8.0), 4),
            "position_hz": s.get("position_rate_hz"), "dir": str(directory)}


def fly_once(config: Path, directory: Path, speed_factor: float, ground_truth_hz: float = 0.0) -> dict[str, Any]:
    """One flight; its row of the table."""
    cfg = load_config(config)
    t0 = time.monotonic()
    with px4_flight(directory, config, speed_factor=speed_factor, ground_truth_hz=ground_truth_hz) as f:
        rc = f.wait_mission(240.0)
        after = f.watch_after(cfg.scenario.target, 3.0) if rc == 0 else float("nan")
    path = f.log_dir / "summary.json"
    s = json.loads(path.read_text()) if path.exists() else {}
    clock = clock_ratio(f.log_dir / "flight.tlog") if (f.log_dir / "flight.tlog").exists() else None
    return {**_row(s, rc, t0, directory), "hold_m": round(after, 3), "clock": round((clock or {}).get("ratio", float("nan")), 3)}


def fly_mock(config: Path, directory: Path, speed: float) -> dict[str, Any]:
    """The same mission on the mock vehicle (``marsupial demo --config``, three processes, ``speed``
    its pace); its row."""
    t0 = time.monotonic()
    directory.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run([sys.executable, "-m", "mission.cli", "demo", "--config", str(config), "--speed", str(speed),
                           "--log-root", str(directory), "--plot", str(directory / "flight.png"), "--timeout", "300"],
                          capture_output=True, text=True, cwd=ROOT)
    s = json.loads((directory / "pair0" / "summary.json").read_text())
    return {**_row(s, proc.returncode, t0, directory), "hold_m": None, "clock": None}


def clock_ok(row: dict[str, Any]) -> bool:
    return row["clock"] is None or CLOCK_OK[0] <= row["clock"] <= CLOCK_OK[1]


def meets(row: dict[str, Any]) -> bool:
    return bool(row["rc"] == 0 and row["p1"] and row["p2"] and row["p3"] and all(
        row[k] is not None and row[k] <= v for k, v in TARGETS.items()))


def _fmt(value: Any) -> str:
    return f"{value:.3f}" if isinstance(value, float) else str(value)


@click.command()
@click.option("-n", "flights", type=int, default=5, show_default=True)
@click.option("--config", type=click.Path(dir_okay=False, exists=True), default=str(ROOT / "configs" / "px4_sitl.toml"),
              show_default=True)
@click.option("--set", "sets", multiple=True, metavar="SECTION.KEY=VALUE", help="Change the configuration (TOML value).")
@click.option("--out", type=click.Path(file_okay=False), default=None, help="Where the flights' logs go (default a temp dir).")
@click.option("--speed-factor", type=float, default=1.03, show_default=True, help="PX4_SIM_SPEED_FACTOR")
@click.option("--parallel", type=click.IntRange(1, 2), default=1, show_default=True, help="PX4 flights at once")
@click.option("--ground-truth", is_flag=True, help="Record PX4's estimate and SIH's truth at 50 Hz (truth.csv per flight).")
@click.option("--vehicle", type=click.Choice(["px4", "mock"]), default="px4", show_default=True,
              help="real PX4 SITL, or the mock vehicle (marsupial demo with the same config; 'clock' is its speed)")
@click.option("--mock-speed", type=float, default=2.0, show_default=True)
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None)
def main(flights: int, config: str, sets: tuple[str, ...], out: str | None, speed_factor: float, parallel: int,
         ground_truth: bool, vehicle: str, mock_speed: float, json_path: str | None) -> None:
    why = unavailable_reason() if vehicle == "px4" else None
    if why:
        raise click.ClickException(why)
    base = Path(out or f"/tmp/px4-flights-{os.getpid()}")
    base.mkdir(parents=True, exist_ok=True)
    cfg_path = Path(config)
    if sets:
        overrides = dict(s.split("=", 1) for s in sets)
        cfg_path = base / "config.toml"
        cfg_path.write_text(patched_config(Path(config).read_text(), overrides))
        load_config(cfg_path)  # a bad override fails here, naming the field
    click.echo(f"{'PX4 build ' + str(build_dir()) if vehicle == 'px4' else 'mock vehicle'}, config {config} {' '.join(sets)}, "
               f"{flights} flights ({parallel} at once), PX4_SIM_SPEED_FACTOR {speed_factor}, load {os.getloadavg()[0]:.1f}")
    click.echo("flight " + " ".join(f"{c:>15}" for c in COLUMNS) + "  targets")

    def one(i: int) -> dict[str, Any]:
        if vehicle == "px4":
            return fly_once(cfg_path, base / f"flight{i}", speed_factor, 50.0 if ground_truth else 0.0)
        return fly_mock(cfg_path, base / f"mock{i}", mock_speed)

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
            verdict = "clock" if not clock_ok(row) else ("met" if meets(row) else "MISSED")
            click.echo(f"{i:>6} " + " ".join(f"{_fmt(row[c]):>15}" for c in COLUMNS) + f"  {verdict}")
    good = [r for r in rows if clock_ok(r)]
    ok = sum(meets(r) for r in good)
    worst = {k: max((r[k] for r in good if r[k] is not None), default=None) for k in TARGETS}
    click.echo(f"{ok}/{len(good)} flights with PX4's clock within {CLOCK_OK} meet every target ({TARGETS}, P1-P3); "
               f"worst: {worst}; logs in {base}")
    if json_path:
        Path(json_path).write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
