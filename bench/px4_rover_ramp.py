"""How PX4's SIH Ackermann rover answers a ramped speed command, per set of its speed-loop
parameters: the numbers behind the rover's ``PX4_PARAM_*`` in ``tests/px4_sitl/test_carrier_rover.py``.

Each run is a fresh rover (airframe 10045, real PX4 SITL, its own network namespace) armed in
OFFBOARD and sent velocity setpoints at 30 Hz towards bearing 36.9 deg (the rover pair's target;
it starts facing north): a ramp of ``--ramp`` m/s^2 to 1 m/s, held until 12 s. Per run: the
time it broke free (first above 0.3 m/s), its peak speed in the first 4 s (the leap when it
breaks free), its speed from 4 to 12 s (mean, min, max), PX4's clock over wall time, and the
load average when it started (the machine is shared; PX4 is real time).

Usage: ``python -m bench.px4_rover_ramp [--ramp 1.0] [--plot FILE] [--set "RO_SPEED_P=0.5 ..."]...``;
without ``--set``: airframe 10045's own parameters, then the test's. About 35 s per run. Needs
root and ``MARSUPIAL_PX4_SITL``.
"""
from __future__ import annotations

import math
import os
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import click
import numpy as np

from mission.mavlink import px4
from sim.sitl.px4 import NetNamespace, Px4Sitl, build_dir, unavailable_reason, wait_armable
from sim.testing.probe import Probe, SetpointStream

BEARING_RAD = math.atan2(18.0, 24.0)  # configs/px4_sitl_rover.toml: target [24, 18] from the origin
TARGET = (2, 1)  # instance 1: sysid 2
DEFAULT_SETS = ("", "RO_MAX_THR_SPEED=4 RO_SPEED_P=0.5 RO_SPEED_I=0.1 RO_ACCEL_LIM=6 RO_DECEL_LIM=6")


def _asked(t_s: float, ramp: float) -> float:
    return min(1.0, ramp * t_s)


@contextmanager
def rover_in_offboard(params: dict[str, float], directory: Path, intervals_us: dict[int, int]) -> Iterator[tuple[Probe, SetpointStream]]:
    """A fresh SIH Ackermann rover (airframe 10045, instance 1, its own network namespace) with
    ``params`` (PX4_PARAM_<name>), armed in OFFBOARD on 30 Hz velocity setpoints (1 mm/s north
    until the caller sets others), its messages at ``intervals_us`` ({message id: [us]}): the
    probe on its offboard link and the setpoint stream. Everything stops on leaving."""
    ns = NetNamespace()
    rover = Px4Sitl(build_dir() or Path("."), directory / "rootfs", ns, instance=1, airframe=10045, speed_factor=1.08,
                    out_dir=directory, params=params)
    try:
        rover.start()
        probe = ns.inside(lambda: Probe(bind="127.0.0.1:14541", vehicle=("127.0.0.1", 14581)))
        try:
            probe.start_heartbeats()
            wait_armable(probe, 60.0)
            stream = SetpointStream(probe, 1 / 30, velocity_ned_m_s=(1e-3, 0.0, 0.0), target=TARGET)
            try:
                time.sleep(1.0)  # setpoints before OFFBOARD, as PX4 needs
                for msg_id, interval in intervals_us.items():
                    probe.command(px4.MAV_CMD_SET_MESSAGE_INTERVAL, (msg_id, interval), target=TARGET)
                probe.command(px4.MAV_CMD_COMPONENT_ARM_DISARM, (1.0,), target=TARGET)
                main, sub = px4.MODES["OFFBOARD"]
                probe.command(px4.MAV_CMD_DO_SET_MODE, (px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | 128, int(main), int(sub)),
                              target=TARGET)
                if not probe.wait_mode("OFFBOARD", 5.0):
                    raise RuntimeError(f"the rover did not take OFFBOARD (mode {probe.mode()})")
                yield probe, stream
            finally:
                stream.stop()
        finally:
            probe.close()
    finally:
        rover.stop()
        ns.close()


def ramp_once(params: dict[str, float], ramp: float, directory: Path) -> dict[str, Any]:
    """One rover, ``params`` set through PX4_PARAM_<name>; its row (and trace, for the plot)."""
    load = os.getloadavg()[0]
    with rover_in_offboard(params, directory, {32: 20000}) as (probe, stream):  # LOCAL_POSITION_NED 50 Hz
        mark, t0 = probe.mark(), time.monotonic()
        while (now := time.monotonic() - t0) < 12.0:
            ask = max(_asked(now, ramp), 1e-3)
            stream.set(velocity_ned_m_s=(ask * math.cos(BEARING_RAD), ask * math.sin(BEARING_RAD), 0.0), target=TARGET)
            time.sleep(0.02)
        samples = [(tw - t0, m.time_boot_ms / 1e3, math.hypot(m.vx, m.vy))
                   for i, tw, m in probe.history["LOCAL_POSITION_NED"] if i > mark]
    a = np.array(samples)
    t, speed = a[:, 0], a[:, 2]
    moving = np.flatnonzero(speed > 0.3)
    cruise = speed[(t > 4.0) & (t < 12.0)]
    return {"params": " ".join(f"{k}={v:g}" for k, v in params.items()) or "airframe 10045",
            "free_s": round(float(t[moving[0]]), 2) if moving.size else None,
            "peak_m_s": round(float(speed[t < 4.0].max()), 2), "cruise_mean": round(float(cruise.mean()), 3),
            "cruise_min": round(float(cruise.min()), 2), "cruise_max": round(float(cruise.max()), 2),
            "clock": round(float((a[-1, 1] - a[0, 1]) / (a[-1, 0] - a[0, 0])), 3), "load": round(load, 1),
            "trace": (t, speed)}


@click.command()
@click.option("--set", "sets", multiple=True, help="PX4 parameters of one run, 'NAME=VALUE ...' (repeatable)")
@click.option("--ramp", default=1.0, show_default=True, help="[m/s^2] ramp of the asked speed to 1 m/s")
@click.option("--plot", type=click.Path(path_type=Path), default=None, help="write the speed traces to this PNG")
def main(sets: tuple[str, ...], ramp: float, plot: Path | None) -> None:
    why = unavailable_reason()
    if why:
        raise click.ClickException(why)
    rows = []
    with tempfile.TemporaryDirectory(dir=Path.cwd()) as scratch:  # not /tmp: PX4 gets a private one
        for k, text in enumerate(sets or DEFAULT_SETS):
            params = {name: float(value) for name, value in (item.split("=", 1) for item in text.split())}
            click.echo(f"run {k + 1}/{len(sets or DEFAULT_SETS)}: {text or 'airframe 10045'} ...", err=True)
            directory = Path(scratch) / f"run{k}"
            directory.mkdir()
            rows.append(ramp_once(params, ramp, directory))
    cols = ("params", "free_s", "peak_m_s", "cruise_mean", "cruise_min", "cruise_max", "clock", "load")
    click.echo(" | ".join(cols))
    for r in rows:
        click.echo(" | ".join(str(r[c]) for c in cols))
    if plot is not None:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(9, 4))
        for r in rows:
            ax.plot(*r["trace"], label=r["params"])
        tt = np.linspace(0.0, 12.0, 200)
        ax.plot(tt, [_asked(x, ramp) for x in tt], "k--", label="asked")
        ax.set(xlabel="t since OFFBOARD [s]", ylabel="speed [m/s]", title=f"SIH Ackermann rover, {ramp:g} m/s^2 ramp")
        ax.grid()
        ax.legend(fontsize=7)
        fig.savefig(plot, dpi=80)
        click.echo(f"plot: {plot}", err=True)


if __name__ == "__main__":
    main()
