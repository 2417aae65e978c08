"""How far PX4's SIH Ackermann rover moves while it stands, per way of telling it to stand: the
numbers behind the mavlink carrier backend's stop (``carrier.mavlink.stand``, docs/recovery.md,
"On real PX4").

Each run is a fresh rover (airframe 10045, real PX4 SITL, its own network namespace, the CI
test's speed loop ``sim.sitl.px4.ROVER_PARAMS``) armed in OFFBOARD: it drives north, its speed
ramped at 0.25 m/s^2 to ``--speed`` m/s until 9 s, is told to stop (1 mm/s along its heading)
until it stands (< 0.05 m/s), and then stands ``--stand`` s, told so one way:

- ``creep``: the 1 mm/s along its heading, in OFFBOARD (the backend's stop until now);
- ``position``: a position setpoint at the point where it came to rest, in OFFBOARD;
- ``hold``: PX4's Hold (AUTO.LOITER), then back to OFFBOARD on the 1 mm/s stop at the end.

Per run: how far the rest point is from where it was at the end (``final_m``) and at most
(``max_m``), its largest speed while standing, by its own estimate (LOCAL_POSITION_NED); and, for
``hold``, how long OFFBOARD took to come back. The load average when it started.

Usage: ``python -m bench.px4_rover_stand [--ways creep,position,hold] [--stand 70]``. About
``stand + 35`` s a run. Needs root and ``MARSUPIAL_PX4_SITL``; wrap in ``flock /tmp/marsupial-px4.lock``.
"""
from __future__ import annotations

import math
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import click
import numpy as np

from bench.px4_rover_ramp import TARGET, rover_in_offboard
from mission.flight_mode import FlightMode
from mission.mavlink import px4, setpoints
from sim.sitl.px4 import ROVER_PARAMS, unavailable_reason
from sim.testing.probe import Probe, SetpointStream

STOP_AT_S = 9.0
RAMP_M_S2 = 0.25
STOP_SPEED_M_S = 1e-3
REST_SPEED_M_S = 0.05
WAYS = ("creep", "position", "hold")


def _creep(probe: Probe) -> tuple[float, float, float]:
    att = probe.latest("ATTITUDE")
    yaw = 0.0 if att is None else float(att.yaw)
    return STOP_SPEED_M_S * math.cos(yaw), STOP_SPEED_M_S * math.sin(yaw), 0.0


def _set_mode(probe: Probe, mode: FlightMode) -> None:
    main, sub = px4.MODES[mode]
    probe.command(px4.MAV_CMD_DO_SET_MODE, (px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | 128, int(main), int(sub)), target=TARGET)


def _stand(probe: Probe, stream: SetpointStream, way: str, speed: float, stand_s: float) -> dict[str, Any]:
    t0 = time.monotonic()
    while (now := time.monotonic() - t0) < STOP_AT_S:
        stream.set(velocity_ned_m_s=(max(min(speed, RAMP_M_S2 * now), 1e-3), 0.0, 0.0), target=TARGET)
        time.sleep(0.02)
    while True:
        stream.set(velocity_ned_m_s=_creep(probe), target=TARGET)
        time.sleep(0.02)
        p = probe.latest("LOCAL_POSITION_NED")
        if math.hypot(p.vx, p.vy) < REST_SPEED_M_S or time.monotonic() - t0 > STOP_AT_S + 10.0:
            break
    rest = np.array([p.x, p.y])
    t_rest = time.monotonic()
    row: dict[str, Any] = {"way": way, "rest_after_s": round(t_rest - t0 - STOP_AT_S, 1)}
    if way == "position":
        stream.set(type_mask=setpoints.TYPE_MASK_POSITION, position_ned_m=(float(p.x), float(p.y), float(p.z)),
                   velocity_ned_m_s=(math.nan, math.nan, math.nan), target=TARGET)
    elif way == "hold":
        _set_mode(probe, FlightMode.HOLD)
        row["hold"] = probe.wait_mode("HOLD", 5.0)
    while time.monotonic() - t_rest < stand_s:
        if way == "creep":
            stream.set(velocity_ned_m_s=_creep(probe), target=TARGET)
        time.sleep(0.02)
    if way == "hold":
        stream.set(velocity_ned_m_s=_creep(probe), target=TARGET)
        t_back = time.monotonic()
        _set_mode(probe, FlightMode.OFFBOARD)
        row["offboard_back_s"] = round(time.monotonic() - t_back, 2) if probe.wait_mode("OFFBOARD", 5.0) else None
    pos = np.array([(tw - t_rest, m.x, m.y, m.vx, m.vy) for tw, m in probe.timed("LOCAL_POSITION_NED") if tw >= t_rest])
    np.save(Path(tempfile.gettempdir()) / f"px4_rover_stand_{way}_{int(time.time())}.npy", pos)  # for a re-analysis: t, x, y, vx, vy
    pos = pos[:, 1:]
    off = np.hypot(pos[:, 0] - rest[0], pos[:, 1] - rest[1])
    row.update(final_m=round(float(off[-1]), 3), max_m=round(float(off.max()), 3),
               max_speed=round(float(np.hypot(pos[:, 2], pos[:, 3]).max()), 3), mode=probe.mode())
    return row


def run_once(way: str, speed: float, stand_s: float, directory: Path) -> dict[str, Any]:
    """One rover, ``way``; its row."""
    load = os.getloadavg()[0]
    with rover_in_offboard(ROVER_PARAMS, directory, {32: 20000, 30: 20000}) as (probe, stream):
        row = _stand(probe, stream, way, speed, stand_s)
    row["load"] = round(load, 1)
    return row


@click.command()
@click.option("--ways", default=",".join(WAYS), show_default=True, help="comma-separated, one rover each")
@click.option("--speed", default=1.2, show_default=True, help="[m/s] speed when told to stop")
@click.option("--stand", "stand_s", default=70.0, show_default=True, help="[s] how long it stands")
def main(ways: str, speed: float, stand_s: float) -> None:
    why = unavailable_reason()
    if why:
        raise click.ClickException(why)
    rows = []
    with tempfile.TemporaryDirectory(dir=Path.cwd()) as scratch:  # not /tmp: PX4 gets a private one
        for k, way in enumerate(w.strip() for w in ways.split(",")):
            if way not in WAYS:
                raise click.BadParameter(f"{way!r}: one of {WAYS}")
            click.echo(f"{way} ...", err=True)
            directory = Path(scratch) / f"run{k}"
            directory.mkdir()
            rows.append(run_once(way, speed, stand_s, directory))
            click.echo(str(rows[-1]), err=True)
    cols = ("way", "rest_after_s", "final_m", "max_m", "max_speed", "offboard_back_s", "mode", "load")
    click.echo(" | ".join(cols))
    for r in rows:
        click.echo(" | ".join(str(r.get(c)) for c in cols))


if __name__ == "__main__":
    main()
