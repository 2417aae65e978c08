"""A stalled controller on a real PX4 SITL: ``marsupial run`` stopped (SIGSTOP) for a while on
the recovery's approach, then continued (SIGCONT), as a companion computer stalls (garbage
collection, I/O, a busy CPU). The facts behind docs/recovery.md ("A stalled controller").

One flight per stall length: a fresh SIH quadrotor (its own network namespace) with the carrier
simulator, ``configs/px4_sitl.toml`` coming home (``final_action = "return"``, the holdoff's
settling relaxed: ``tests/px4_sitl/conftest.py``'s ``px4_return_config``). ``after`` wall seconds into the
first approach the controller is stopped for ``stall`` wall seconds. Printed as one JSON line per
flight: what PX4 did in the gap (the modes its HEARTBEATs showed on the GCS link, the longest gap
between the setpoints it received as the mission's tlog has them, how far and how fast it flew),
what the mission did after it (its events: the restart, the go-around and why, the next
approach), how it ended (docked, at which approach, the contact), and the first commands after
the gap against the vehicle's velocity (the jump).

Usage: ``python -m bench.px4_stall [--stall 1.0]... [--after 2.0] [--who mission|carrier] [--during APPROACH]``
(about 90-120 s a flight; ``--during RIDING``: the stall while the passenger rides).
Needs root and ``MARSUPIAL_PX4_SITL``. Run it under ``flock /tmp/marsupial-px4.lock`` on a shared machine.
"""
from __future__ import annotations

import json
import signal
import tempfile
import time
from pathlib import Path
from typing import Any

import click
import numpy as np

from mission.mavlink import px4
from mission.record.table import read_record
from sim.net import wait_for
from sim.sitl.px4 import build_dir, px4_flight, unavailable_reason
from tests.px4_sitl.conftest import TEN_MINUTE_BATTERY, px4_return_config

SPEED_FACTOR = 1.03
def _events(text: str) -> list[str]:
    keep = ("stalled", "go-around", "approach", "contact", "recovery falls back", "abort", "vehicle left OFFBOARD",
            "no vehicle position read", "carrier state", "separated at")
    return [line.split(": ", 1)[-1] for line in text.splitlines()
            if any(k in line for k in keep) and " INFO " in line or " WARNING " in line and "abort" in line]


def _setpoint_gaps(log_dir: Path) -> list[float]:
    """The gaps [s] between the mission's setpoints longer than 0.1 s, by their time_boot_ms (the
    mission's clock when sent)."""
    from mission.mavlink.env import mavlink

    data, i, times = (log_dir / "flight.tlog").read_bytes(), 0, []
    codec = mavlink.MAVLink(None)
    codec.robust_parsing = True
    while i + 8 < len(data):
        size = 12 + data[i + 9] + (13 if data[i + 10] & 0x01 else 0)
        for msg in codec.parse_buffer(data[i + 8:i + 8 + size]) or []:
            if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED" and msg.get_srcComponent() == 191:
                times.append(msg.time_boot_ms / 1000.0)
        i += 8 + size
    return [round(b - a, 3) for a, b in zip(times, times[1:]) if b - a > 0.1]


def fly(directory: Path, stall_s: float, after_s: float, who: str = "mission", during: str = "APPROACH") -> dict[str, Any]:
    """One flight with one stall of ``who`` (``mission``: ``marsupial run``; ``carrier``: the
    carrier simulator) ``after_s`` into the phase ``during``; its JSON row."""
    directory.mkdir(parents=True, exist_ok=True)
    config = px4_return_config(directory)
    t0 = time.monotonic()
    with px4_flight(directory / "f", config, build=build_dir() or Path("."), speed_factor=SPEED_FACTOR,
                    px4_params=TEN_MINUTE_BATTERY) as f:
        mission = f.procs["mission"]
        wait_for(lambda: f"phase {during}" in f.text("mission.out") or mission.poll() is not None, 200.0,
                 f"the mission in {during}")
        assert mission.poll() is None, f.text("mission.out")[-2000:] + f.text("mission.err")[-2000:]
        time.sleep(after_s)  # the fault's own timing: into the phase (the stall is measured below)
        stopped = time.monotonic()
        f.procs[who].send_signal(signal.SIGSTOP)
        time.sleep(stall_s)
        f.procs[who].send_signal(signal.SIGCONT)
        stopped_s = time.monotonic() - stopped
        rc = f.wait_mission(300.0)
        beats = [(t, px4.mode_name(m.custom_mode)) for t, m in f.gcs.timed("HEARTBEAT")
                 if m.get_srcSystem() == 1 and m.get_srcComponent() == 1 and m.autopilot == px4.MAV_AUTOPILOT_PX4]
        modes: list[tuple[float, str]] = []  # (since the stop [s, wall], mode) at each change
        for t, mode in beats:
            if stopped <= t <= stopped + stall_s + 5.0 and (not modes or modes[-1][1] != mode):
                modes.append((round(t - stopped, 2), mode))
        lp = [(t - stopped, np.array([m.vx, m.vy, m.vz])) for t, m in f.gcs.timed("LOCAL_POSITION_NED")
              if m.get_srcSystem() == 1 and -1.0 <= t - stopped <= stopped_s + 1.0]
        texts = [m.text for t, m in f.gcs.timed("STATUSTEXT") if t >= stopped]
        events = _events(f.text("mission.err") + f.text("mission.out"))
    s = json.loads((f.log_dir / "summary.json").read_text()) if (f.log_dir / "summary.json").exists() else {}
    rec = read_record(f.log_dir)
    t = rec.t
    gap_i = int(np.argmax(np.diff(t))) + 1
    u_cmd, v_p = rec.vec("u_cmd"), rec.vec("v_p")
    first = [{"t_s": round(float(t[k]), 3), "phase": str(rec.phase[k]), "u_cmd": u_cmd[k].round(3).tolist(),
              "v_p": v_p[k].round(3).tolist()} for k in range(gap_i - 1, gap_i + 3)]
    speeds = [(round(float(tt), 2), round(float(np.linalg.norm(v[:2])), 2)) for tt, v in lp]
    contact = s.get("contact") or {}
    return {
        "stalled": who, "during": during, "stall_asked_s": stall_s, "stopped_s": round(stopped_s, 3), "tick_gap_s": round(float(np.diff(t).max()), 3),
        "setpoint_gaps_s": _setpoint_gaps(f.log_dir), "px4_modes_after_stop": modes, "statustext": texts,
        "px4_horizontal_speed_m_s": speeds[::5],  # (since the stop [s, wall], |v| [m/s]) from 1 s before to 1 s after
        "events_after_stop": [e for e in events if "approach 1 begins" not in e][:12],
        "first_ticks_after_gap": first,
        "max_cmd_minus_vehicle_after_gap_m_s": round(float(max(np.linalg.norm(u_cmd[k] - v_p[k])
                                                              for k in range(gap_i, gap_i + 10))), 3),
        "exit": rc, "phase": s.get("phase"), "reason": s.get("reason"), "detail": s.get("detail"),
        "recovery_outcome": s.get("recovery_outcome"), "attempts": contact.get("attempts"),
        "contact_error_m": contact.get("horizontal_error_m"), "contact_speed_m_s": contact.get("horizontal_relative_speed_m_s"),
        "deck_violations": s.get("deck_violations"), "max_phase_switch_jump_m_s": s.get("max_phase_switch_jump_m_s"),
        "max_stall_command_offset_m_s": s.get("max_stall_command_offset_m_s"),
        "max_carrier_age_s": round(float(np.nanmax(rec.cols["carrier_age_s"])), 3) if len(t) else None,
        "p1": s.get("p1"), "max_offset_before_separation_m": s.get("max_offset_before_separation_m"),
        "carrier_target_distance_at_separation_m": s.get("carrier_target_distance_at_separation_m"),
        "loop_overruns": s.get("loop_overruns"), "wall_s": round(time.monotonic() - t0, 1), "dir": str(directory),
    }


@click.command()
@click.option("--stall", "stalls", type=float, multiple=True, default=(1.0,), show_default=True,
              help="How long the controller is stopped [s, wall] (repeatable: one flight each).")
@click.option("--after", "after_s", type=float, default=2.0, show_default=True,
              help="How far into the first approach the stall comes [s, wall].")
@click.option("--who", type=click.Choice(["mission", "carrier"]), default="mission", show_default=True,
              help="Which process stalls: marsupial run, or the carrier simulator.")
@click.option("--during", default="APPROACH", show_default=True,
              help="The phase the stall comes in (RIDING: before separation; ARRIVED: at the target).")
@click.option("--out", type=click.Path(), default=None, help="Keep the flights' folders here.")
def main(stalls: tuple[float, ...], after_s: float, who: str, during: str, out: str | None) -> None:
    reason = unavailable_reason()
    if reason:
        raise click.ClickException(reason)
    root = Path(out) if out else Path(tempfile.mkdtemp(prefix="px4_stall_"))
    for i, stall in enumerate(stalls):
        print(json.dumps(fly(root / f"stall{i}", stall, after_s, who, during)), flush=True)


if __name__ == "__main__":
    main()
