"""How PX4's SIH Ackermann rover stops and turns: the numbers behind the P3 guard's model of it
(``carrier.brake_decel_m_s2``, ``carrier.brake_delay_s``, ``carrier.turn_radius_m``,
``carrier.turn_reserve_m`` in ``configs/px4_sitl_cycle.toml``; docs/safety.md, "The guard's model
of the carrier").

Each run is a fresh rover (airframe 10045, real PX4 SITL, its own network namespace, its speed
loop closed as in the CI test: ``sim.sitl.px4.ROVER_PARAMS``) armed in OFFBOARD and sent velocity
setpoints at 30 Hz, as the carrier sends them:

1. from standstill, facing north: north, the asked speed ramped at 0.25 m/s^2 (``carrier.start_accel_m_s2``) to
   ``--speed`` m/s, held until 9 s;
2. at 9 s, "stop": 1 mm/s along its own heading (the mavlink backend's stop) until 15 s;
3. at 15 s, from standstill, a turn away: south at ``--turn-speed`` m/s (the tracking law's
   Ackermann floor, ``min_speed_fraction`` of the course speed) until 27 s.

Per run: the speed when told to stop, the delay until it slowed by 0.1 m/s, its mean deceleration
from then until it stood (< 0.05 m/s), the distance it drove after the stop and the deceleration
``a`` that distance implies with that delay (``v d + v^2 / 2 a``); for the turn: how far it drove
forward (north, towards what it faced) before it turned away, how far sideways, and its turning
radius (median of speed / yaw rate while it turned faster than 0.2 rad/s). PX4's clock over wall
time and the load average.

Usage: ``python -m bench.px4_rover_stop [-n 3] [--speed 1.2] [--turn-speed 0.36]``. About 45 s a
run. Needs root and ``MARSUPIAL_PX4_SITL``; wrap in ``flock /tmp/marsupial-px4.lock``.
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
from sim.sitl.px4 import ROVER_PARAMS, unavailable_reason
from sim.testing.probe import Probe, SetpointStream

STOP_AT_S, TURN_AT_S, END_S = 9.0, 15.0, 27.0
RAMP_M_S2 = 0.25
STOP_SPEED_M_S = 1e-3


def _fly(probe: Probe, stream: SetpointStream, speed: float, turn_speed: float) -> tuple[float, int]:
    """Ramp, stop, turn away (the module's three parts) on a rover in OFFBOARD; (t0 wall [s], mark)."""
    mark, t0 = probe.mark(), time.monotonic()
    while (now := time.monotonic() - t0) < END_S:
        if now < STOP_AT_S:
            v = (max(min(speed, RAMP_M_S2 * now), 1e-3), 0.0)
        elif now < TURN_AT_S:
            att = probe.latest("ATTITUDE")
            yaw = 0.0 if att is None else float(att.yaw)
            v = (STOP_SPEED_M_S * math.cos(yaw), STOP_SPEED_M_S * math.sin(yaw))
        else:
            v = (-turn_speed, 0.0)
        stream.set(velocity_ned_m_s=(v[0], v[1], 0.0), target=TARGET)
        time.sleep(0.02)
    return t0, mark


def _series(probe: Probe, t0: float) -> tuple[np.ndarray, np.ndarray]:
    pos = np.array([(tw - t0, m.time_boot_ms / 1e3, m.x, m.y, m.vx, m.vy)
                    for tw, m in probe.timed("LOCAL_POSITION_NED") if tw >= t0])
    att = np.array([(tw - t0, m.yaw, m.yawspeed) for tw, m in probe.timed("ATTITUDE") if tw >= t0])
    return pos, att


def analyse(pos: np.ndarray, att: np.ndarray) -> dict[str, Any]:
    """The row of one run from its LOCAL_POSITION_NED ``pos`` (t, boot, x, y, vx, vy) and ATTITUDE
    ``att`` (t, yaw, yawspeed) series, times [s] from OFFBOARD."""
    t, x, y = pos[:, 0], pos[:, 2], pos[:, 3]
    speed = np.hypot(pos[:, 4], pos[:, 5])
    before = (t > STOP_AT_S - 0.5) & (t <= STOP_AT_S)
    v0 = float(speed[before].mean())
    after = np.flatnonzero(t > STOP_AT_S)
    slowed = after[speed[after] < v0 - 0.1]
    stood = after[speed[after] < 0.05]
    row: dict[str, Any] = {"v0": round(v0, 2)}
    if slowed.size and stood.size:
        i1, i2 = int(slowed[0]), int(stood[0])
        delay = float(t[i1]) - STOP_AT_S
        path = np.hypot(np.diff(x[after[0] - 1:i2 + 1]), np.diff(y[after[0] - 1:i2 + 1])).sum()
        decel = (v0 - 0.05) / max(float(t[i2] - t[i1]), 1e-3)
        rest = float(path) - v0 * delay
        row.update(delay_s=round(delay, 2), decel=round(decel, 2), stop_m=round(float(path), 2),
                   a_eff=round(v0 * v0 / (2 * rest), 2) if rest > 0 else None)
    turn = t > TURN_AT_S
    x_turn, y_turn = float(x[turn][0]), float(y[turn][0])
    row.update(forward_m=round(float(x[turn].max()) - x_turn, 2), side_m=round(float(np.abs(y[turn] - y_turn).max()), 2))
    at = att[:, 0]
    rate = np.interp(t, at, att[:, 2])
    turning = turn & (np.abs(rate) > 0.2) & (speed > 0.1)
    row["radius_m"] = round(float(np.median(speed[turning] / np.abs(rate[turning]))), 2) if turning.any() else None
    row["min_radius_m"] = round(float(np.min(speed[turning] / np.abs(rate[turning]))), 2) if turning.any() else None
    row["turn_s"] = None
    yaw = np.interp(t, at, np.unwrap(att[:, 1]))
    away = np.flatnonzero(turn & (np.abs(np.cos(yaw)) < 1.0) & (np.cos(yaw) < -0.9))
    if away.size:
        row["turn_s"] = round(float(t[away[0]]) - TURN_AT_S, 1)
    row["clock"] = round(float((pos[-1, 1] - pos[0, 1]) / (pos[-1, 0] - pos[0, 0])), 3)
    return row


def run_once(speed: float, turn_speed: float, directory: Path) -> dict[str, Any]:
    """One rover with the CI test's speed-loop parameters; its row."""
    load = os.getloadavg()[0]
    with rover_in_offboard(ROVER_PARAMS, directory, {32: 20000, 30: 20000}) as (probe, stream):  # LOCAL_POSITION_NED, ATTITUDE 50 Hz
        t0, _ = _fly(probe, stream, speed, turn_speed)
        pos, att = _series(probe, t0)
    np.savez(directory.parent.parent / f"px4_rover_stop_{int(time.time())}.npz", pos=pos, att=att)  # for a re-analysis
    row = analyse(pos, att)
    row["load"] = round(load, 1)
    return row


@click.command()
@click.option("-n", "runs", default=3, show_default=True, help="rovers flown")
@click.option("--speed", default=1.2, show_default=True, help="[m/s] speed when told to stop")
@click.option("--turn-speed", default=0.36, show_default=True, help="[m/s] speed asked on the turn away")
def main(runs: int, speed: float, turn_speed: float) -> None:
    why = unavailable_reason()
    if why:
        raise click.ClickException(why)
    rows = []
    with tempfile.TemporaryDirectory(dir=Path.cwd()) as scratch:  # not /tmp: PX4 gets a private one
        for k in range(runs):
            click.echo(f"run {k + 1}/{runs} ...", err=True)
            directory = Path(scratch) / f"run{k}"
            directory.mkdir()
            rows.append(run_once(speed, turn_speed, directory))
            click.echo(str(rows[-1]), err=True)
    cols = ("v0", "delay_s", "decel", "stop_m", "a_eff", "forward_m", "side_m", "radius_m", "min_radius_m", "turn_s",
            "clock", "load")
    click.echo(" | ".join(cols))
    for r in rows:
        click.echo(" | ".join(str(r.get(c)) for c in cols))


if __name__ == "__main__":
    main()
