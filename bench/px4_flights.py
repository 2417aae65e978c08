"""Fly the mission on real PX4 SITL N times in a row and print the table of the real-PX4 targets (docs/flying-px4.md).

Each flight is a fresh PX4 (SIH quadrotor) in its own network namespace with the carrier
simulator and ``marsupial run`` beside it (:mod:`sim.sitl.px4`). Per flight: P1-P3, the riding
offset (largest distance from the dock point while RIDING), the swing at the target (farthest
from it after first coming within the arrival radius, until the mission handed the vehicle to
PX4's Hold), the relative command jump at separation, where PX4's own Hold took it over the next
3 s (``hold_m``, farthest from the target; not ours to steer, reported beside), PX4's clock
against wall time and the LOCAL_POSITION_NED rate that arrived [Hz of wall time]. Needs root and ``MARSUPIAL_PX4_SITL``.

``--vehicle mock`` flies the same configuration on the mock vehicle (``marsupial demo``) for the
comparison "the mock predicts PX4".

Usage: ``python -m bench.px4_flights [-n 5] [--config configs/px4_sitl.toml] [--vehicle px4|mock]
[--out DIR] [--json F]`` (about 40-60 s of wall time per PX4 flight).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import click

from mission.config.schema import load_config
from sim.sitl.px4 import build_dir, clock_ratio, px4_flight, unavailable_reason

ROOT = Path(__file__).resolve().parents[1]
TARGETS = {"riding_offset_m": 0.25, "swing_m": 0.5, "jump_m_s": 0.05}


def fly_once(config: Path, directory: Path, speed_factor: float) -> dict[str, Any]:
    """One flight; its row of the table."""
    cfg = load_config(config)
    t0 = time.monotonic()
    with px4_flight(directory, config, speed_factor=speed_factor) as f:
        rc = f.wait_mission(240.0)
        after = f.watch_after(cfg.scenario.target, 3.0) if rc == 0 else float("nan")
    s = json.loads((f.log_dir / "summary.json").read_text())
    clock = clock_ratio(f.log_dir / "flight.tlog") or {}
    return {"rc": rc, "wall_s": round(time.monotonic() - t0, 1), "p1": s.get("p1"), "p2": s.get("p2"), "p3": s.get("p3"),
            "riding_offset_m": s.get("max_offset_before_separation_m"), "swing_m": s.get("max_target_distance_after_arrival_m"),
            "hold_m": round(after, 3),
            "jump_m_s": s.get("relative_input_jump_m_s"), "sep_m": s.get("carrier_target_distance_at_separation_m"),
            "clock": round(clock.get("ratio", float("nan")), 3), "position_hz": s.get("position_rate_hz"),
            "dir": str(directory)}


def _fmt(value: Any) -> str:
    return f"{value:.3f}" if isinstance(value, float) else str(value)


def fly_mock(config: Path, directory: Path, speed: float) -> dict[str, Any]:
    """The same mission on the mock vehicle (``marsupial demo --config``, three processes); its row."""
    t0 = time.monotonic()
    directory.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run([sys.executable, "-m", "mission.cli", "demo", "--config", str(config), "--speed", str(speed),
                           "--log-root", str(directory), "--plot", str(directory / "flight.png"), "--timeout", "300"],
                          capture_output=True, text=True, cwd=ROOT)
    s = json.loads((directory / "pair0" / "summary.json").read_text())
    return {"rc": proc.returncode, "wall_s": round(time.monotonic() - t0, 1), "p1": s.get("p1"), "p2": s.get("p2"),
            "p3": s.get("p3"), "riding_offset_m": s.get("max_offset_before_separation_m"),
            "swing_m": s.get("max_target_distance_after_arrival_m"), "hold_m": None,
            "jump_m_s": s.get("relative_input_jump_m_s"), "sep_m": s.get("carrier_target_distance_at_separation_m"),
            "clock": speed, "position_hz": s.get("position_rate_hz"), "dir": str(directory)}


def meets(row: dict[str, Any]) -> bool:
    return bool(row["rc"] == 0 and row["p1"] and row["p2"] and row["p3"] and all(
        row[k] is not None and row[k] <= v for k, v in TARGETS.items()))


@click.command()
@click.option("-n", "flights", type=int, default=5, show_default=True)
@click.option("--config", type=click.Path(dir_okay=False, exists=True), default=str(ROOT / "configs" / "px4_sitl.toml"),
              show_default=True)
@click.option("--out", type=click.Path(file_okay=False), default=None, help="Where the flights' logs go (default a temp dir).")
@click.option("--speed-factor", type=float, default=1.03, show_default=True, help="PX4_SIM_SPEED_FACTOR")
@click.option("--vehicle", type=click.Choice(["px4", "mock"]), default="px4", show_default=True,
              help="real PX4 SITL, or the mock vehicle (marsupial demo with the same config; 'clock' is its speed)")
@click.option("--mock-speed", type=float, default=2.0, show_default=True)
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None)
def main(flights: int, config: str, out: str | None, speed_factor: float, vehicle: str, mock_speed: float,
         json_path: str | None) -> None:
    why = unavailable_reason() if vehicle == "px4" else None
    if why:
        raise click.ClickException(why)
    base = Path(out or f"/tmp/px4-flights-{os.getpid()}")
    click.echo(f"{'PX4 build ' + str(build_dir()) if vehicle == 'px4' else 'mock vehicle'}, config {config}, {flights} flights, PX4_SIM_SPEED_FACTOR {speed_factor}, "
               f"load {os.getloadavg()[0]:.1f}")
    cols = ("rc", "p1", "p2", "p3", "riding_offset_m", "swing_m", "jump_m_s", "hold_m", "sep_m", "clock", "position_hz", "wall_s")
    click.echo("flight " + " ".join(f"{c:>15}" for c in cols) + "  targets")
    rows = []
    for i in range(flights):
        if vehicle == "px4":
            row = fly_once(Path(config), base / f"flight{i}", speed_factor)
        else:
            row = fly_mock(Path(config), base / f"mock{i}", mock_speed)
        rows.append(row)
        click.echo(f"{i:>6} " + " ".join(f"{_fmt(row[c]):>15}" for c in cols) + ("  met" if meets(row) else "  MISSED"))
    ok = sum(meets(r) for r in rows)
    worst = {k: max((r[k] for r in rows if r[k] is not None), default=None) for k in TARGETS}
    click.echo(f"{ok}/{flights} flights meet every target (riding offset <= 0.25 m, swing <= 0.5 m, jump <= 0.05 m/s, P1-P3); "
               f"worst: {worst}; logs in {base}")
    if json_path:
        Path(json_path).write_text(json.dumps(rows, indent=2))


if __name__ == "__main__":
    main()
