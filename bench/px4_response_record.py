"""Record how a fresh real PX4 SITL (SIH quadrotor) answers a sequence of offboard setpoints.

The in-repo twin of ``record_responses.py`` of ../shared/px4_sitl (which recorded
``tests/data/px4_responses/original`` and ``repeat``): one fresh PX4 in a network namespace of its
own (:mod:`sim.sitl.px4`, ``PX4_SIM_SPEED_FACTOR`` 1.03), this module's child process inside it
sending the setpoints at 50 Hz over PX4's onboard link with pymavlink, PX4's default stream rates,
and writing one CSV row per LOCAL_POSITION_NED in the same columns (:func:`sim.sitl.replay.load_recording`
reads it) plus SIH's true velocity at that row (``true_v*_m_s``: HIL_STATE_QUATERNION, PX4's
ground-truth stream, asked at 50 Hz; NaN before the first).

``--sequence unseen`` flies a sequence that neither the airframe fit nor the estimate-error fit
saw: other step sizes and directions, a slower carrier ramp east, sines east at other
frequencies, 20 s at rest under a zero *velocity* setpoint and 20 s holding a *position*
(the estimate's error under both, with the truth beside it). ``--sequence original`` flies the
recorded one again. ``--sequence axes`` flies setpoints full on some axes only (position and
acceleration north and east with the vertical velocity only, then the other way round: type_mask
3332 and 3267), the kinds tracking sends while the safety filter acts on one axis.

Usage: ``flock /tmp/marsupial-px4.lock python -m bench.px4_response_record OUT.csv [--sequence unseen]``
(real time, about 3 minutes; needs root and ``MARSUPIAL_PX4_SITL``).
"""
from __future__ import annotations

import gzip
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

COLUMNS = ("t_s,segment,setpoint_kind,sp_x_m,sp_y_m,sp_z_m,sp_vx_m_s,sp_vy_m_s,sp_vz_m_s,sp_ax_m_s2,sp_ay_m_s2,"
           "sp_az_m_s2,x_m,y_m,z_m,vx_m_s,vy_m_s,vz_m_s,px4_time_boot_ms,true_vx_m_s,true_vy_m_s,true_vz_m_s")
RATE_HZ = 50.0
VELOCITY_MASK = 0x0DC7  # velocity only (3527)
FULL_MASK = 1024 | 2048  # position + velocity + acceleration, yaw ignored (3072)
# position + acceleration on some axes only, velocity on all (mission.mavlink.setpoints: 3332, 3267)
MASKS = {"velocity": VELOCITY_MASK, "pos_vel_acc": FULL_MASK, "pos_horizontal": FULL_MASK | 4 | 256,
         "pos_vertical": FULL_MASK | 1 | 2 | 64 | 128}


class Recorder:
    """The child: one pymavlink link to PX4's onboard port, the setpoint in force, the rows."""

    def __init__(self, out: Any) -> None:
        from pymavlink import mavutil

        self.m = mavutil.mavlink_connection("udpin:0.0.0.0:14540", source_system=255, source_component=190)
        self.out = out
        self.t0 = time.monotonic()
        self.next = 0.0
        self.segment = "preflight"
        self.kind = "velocity"
        self.p = [math.nan] * 3
        self.v = [0.0, 0.0, 0.0]
        self.a = [math.nan] * 3
        self.pos: tuple[float, float, float] | None = None
        self.truth = (math.nan, math.nan, math.nan)
        self.armed = False
        out.write(COLUMNS + "\n")

    def now(self) -> float:
        return time.monotonic() - self.t0

    def pump(self, until: float) -> None:
        while (left := until - self.now()) > 0:
            msg = self.m.recv_match(blocking=True, timeout=min(left, 0.005))
            if msg is None or msg.get_srcSystem() != 1:
                continue
            kind = msg.get_type()
            if kind == "LOCAL_POSITION_NED":
                self.pos = (msg.x, msg.y, msg.z)
                cells = [f"{self.now():.4f}", self.segment, self.kind, *(f"{x:.4f}" for x in (*self.p, *self.v, *self.a)),
                         *(f"{x:.4f}" for x in (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz)), str(msg.time_boot_ms),
                         *(f"{x:.4f}" for x in self.truth)]
                self.out.write(",".join(cells) + "\n")
            elif kind == "HIL_STATE_QUATERNION":
                self.truth = (msg.vx * 0.01, msg.vy * 0.01, msg.vz * 0.01)
            elif kind == "HEARTBEAT" and msg.autopilot == 12:
                self.armed = bool(msg.base_mode & 128)
            elif kind == "STATUSTEXT":
                click.echo(f"PX4: {msg.text}", err=True)

    def send(self) -> None:
        from pymavlink.dialects.v20 import common as mav

        mask = MASKS[self.kind]
        p = [0.0 if mask & bit else x for x, bit in zip(self.p, (1, 2, 4))]  # ignored fields go as 0
        a = [0.0 if mask & bit else x for x, bit in zip(self.a, (64, 128, 256))]
        self.m.mav.send(mav.MAVLink_set_position_target_local_ned_message(
            int(self.now() * 1000) & 0xFFFFFFFF, 1, 1, mav.MAV_FRAME_LOCAL_NED, mask, *p, *self.v, *a, 0, 0))

    def stream(self, duration_s: float, fn: Callable[[float], None] | None = None) -> None:
        """Send at RATE_HZ for ``duration_s``; ``fn(tau)`` sets the setpoint before each send."""
        start = self.now()
        self.next = max(self.next, start)
        while (tau := self.now() - start) < duration_s:
            if fn is not None:
                fn(tau)
            self.send()
            self.next += 1.0 / RATE_HZ
            self.pump(self.next)

    def command(self, command: int, *params: float) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self.m.mav.command_long_send(1, 1, command, 0, *p)

    def velocity(self, name: str, v: tuple[float, float, float], duration_s: float, stop_s: float = 4.0) -> None:
        """A velocity step, then ``stop_s`` of zero velocity."""
        self.segment, self.kind, self.v = name, "velocity", list(v)
        self.stream(duration_s)
        self.segment, self.v = name + "_stop", [0.0, 0.0, 0.0]
        self.stream(stop_s)


def fly_unseen(r: Recorder) -> None:
    """The sequence that no fit saw (the module docstring)."""
    r.velocity("step_west_1p5", (0.0, -1.5, 0.0), 5.0)
    r.velocity("step_diag_1_m2", (1.0, -2.0, 0.0), 3.0)
    r.velocity("step_south_0p7", (-0.7, 0.0, 0.0), 4.0)
    r.velocity("step_up_0p5", (0.0, 0.0, -0.5), 3.0)
    r.velocity("step_diag_down", (1.0, 1.0, 0.5), 2.0)
    r.segment, r.v = "rest_velocity", [0.0, 0.0, 0.0]
    r.stream(20.0)
    acc, cruise_v, total_s = 0.5, 1.5, 12.0

    def ramp(tau: float) -> tuple[float, float, float]:
        ta = cruise_v / acc
        tc = total_s - 2 * ta
        if tau < ta:
            return acc * tau, acc, 0.5 * acc * tau * tau
        if tau < ta + tc:
            return cruise_v, 0.0, 0.5 * acc * ta * ta + cruise_v * (tau - ta)
        if tau < total_s:
            s = tau - ta - tc
            return cruise_v - acc * s, -acc, 0.5 * acc * ta * ta + cruise_v * tc + cruise_v * s - 0.5 * acc * s * s
        return 0.0, 0.0, acc * ta * ta + cruise_v * tc

    r.segment, r.kind = "ramp_east_pos_vel_acc", "pos_vel_acc"
    assert r.pos is not None
    p0 = list(r.pos)

    def full(tau: float) -> None:
        v, a, s = ramp(tau)
        r.p, r.v, r.a = [p0[0], p0[1] + s, p0[2]], [0.0, v, 0.0], [0.0, a, 0.0]

    r.stream(total_s, full)
    r.segment = "hold_position"
    r.stream(20.0, lambda tau: full(total_s + tau))
    r.kind, r.p, r.a, r.v = "velocity", [math.nan] * 3, [math.nan] * 3, [0.0, 0.0, 0.0]
    r.segment = "ramp_west_velocity_only"
    r.stream(total_s, lambda tau: setattr(r, "v", [0.0, -ramp(tau)[0], 0.0]))
    r.segment, r.v = "ramp_west_velocity_only_stop", [0.0, 0.0, 0.0]
    r.stream(4.0)
    for f, amp in ((0.35, 0.8), (0.7, 1.2)):
        r.segment = f"sine_east_{amp}m_s_{f}hz"
        r.stream(8.0, lambda tau, f=f, amp=amp: setattr(r, "v", [0.0, amp * math.sin(2 * math.pi * f * tau), 0.0]))
        r.segment, r.v = f"sine_east_{f}hz_stop", [0.0, 0.0, 0.0]
        r.stream(3.0)


def fly_original(r: Recorder) -> None:
    """The sequence of ``record_responses.py`` (tests/data/px4_responses/README.md)."""
    for name, v, dur in (("step_north_2", (2, 0, 0), 4.0), ("step_east_2", (0, 2, 0), 4.0), ("step_diag_4p2", (-3, 3, 0), 4.0),
                         ("step_up_1", (0, 0, -1), 3.0), ("step_down_1", (0, 0, 1), 3.0)):
        r.velocity(name, v, dur)

    def ramp(tau: float) -> tuple[float, float, float]:
        if tau < 2.0:
            return tau, 1.0, 0.5 * tau * tau
        if tau < 8.0:
            return 2.0, 0.0, 2.0 + 2.0 * (tau - 2.0)
        if tau < 10.0:
            s = tau - 8.0
            return 2.0 - s, -1.0, 14.0 + 2.0 * s - 0.5 * s * s
        return 0.0, 0.0, 16.0

    r.segment = "ramp_velocity_only"
    r.stream(10.0, lambda tau: setattr(r, "v", [ramp(tau)[0], 0.0, 0.0]))
    r.segment, r.v = "ramp_velocity_only_stop", [0.0, 0.0, 0.0]
    r.stream(4.0)
    assert r.pos is not None
    p0 = list(r.pos)
    r.segment, r.kind = "ramp_pos_vel_acc", "pos_vel_acc"

    def full(tau: float) -> None:
        v, a, s = ramp(tau)
        r.p, r.v, r.a = [p0[0] + s, p0[1], p0[2]], [v, 0.0, 0.0], [a, 0.0, 0.0]

    r.stream(10.0, full)
    r.segment = "ramp_pos_vel_acc_stop"
    r.stream(4.0, lambda tau: full(10.0 + tau))
    r.kind, r.p, r.a, r.v = "velocity", [math.nan] * 3, [math.nan] * 3, [0.0, 0.0, 0.0]
    for f in (0.25, 0.5, 1.0):
        r.segment = f"sine_north_1m_s_{f}hz"
        r.stream(8.0, lambda tau, f=f: setattr(r, "v", [math.sin(2 * math.pi * f * tau), 0.0, 0.0]))
        r.segment, r.v = f"sine_north_{f}hz_stop", [0.0, 0.0, 0.0]
        r.stream(3.0)


def gaps(path: Path) -> dict[str, tuple[float, float]]:
    """Per segment of a recording: the largest gap [s] between rows on PX4's clock (LOCAL_POSITION_NED
    lost or late: 0.034 s is PX4's 29.5 Hz) and the largest lateness of the recorder (a row's wall
    gap less its PX4 gap: the recorder stalled, so the setpoint it logged is not the one PX4 flew).
    Over ~0.1 s the replay of that segment is not the flight's."""
    opener: Any = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt") as f:
        header = f.readline().strip().split(",")
        rows = [line.strip().split(",") for line in f if line.strip()]
    col = {name: i for i, name in enumerate(header)}
    out: dict[str, tuple[float, float]] = {}
    seg_rows: dict[str, list[tuple[float, float]]] = {}
    for r in rows:
        seg_rows.setdefault(r[col["segment"]], []).append((float(r[col["t_s"]]), float(r[col["px4_time_boot_ms"]]) / 1000.0))
    for name, pairs in seg_rows.items():
        if len(pairs) > 2:
            px4 = [p for _, p in pairs]
            skew = [w - p for w, p in pairs]
            out[name] = (max(b - a for a, b in zip(px4, px4[1:])), max(b - a for a, b in zip(skew, skew[1:])))
    return out


def fly_axes(r: Recorder) -> None:
    """Setpoints full on some axes only (``Setpoint.position_axes``): 6 s holding north and east
    at the start while climbing at 0.5 m/s on a velocity-only down axis, then 6 s holding the height
    while going east at 1 m/s on velocity-only north and east; each followed by 4 s of a full hold."""
    assert r.pos is not None
    p0 = list(r.pos)
    r.segment, r.kind = "hold_horizontal_climb_0p5", "pos_horizontal"
    r.p, r.v, r.a = [p0[0], p0[1], 0.0], [0.0, 0.0, -0.5], [0.0, 0.0, 0.0]
    r.stream(6.0)
    assert r.pos is not None
    p1 = list(r.pos)
    r.segment, r.kind, r.p, r.v = "hold_after_climb", "pos_vel_acc", [p0[0], p0[1], p1[2]], [0.0, 0.0, 0.0]
    r.stream(4.0)
    r.segment, r.kind = "hold_height_east_1", "pos_vertical"
    r.p, r.v, r.a = [0.0, 0.0, p1[2]], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]
    r.stream(6.0)
    assert r.pos is not None
    r.segment, r.kind, r.p, r.v = "hold_after_east", "pos_vel_acc", [r.pos[0], r.pos[1], p1[2]], [0.0, 0.0, 0.0]
    r.stream(4.0)


SEQUENCES = {"unseen": fly_unseen, "original": fly_original, "axes": fly_axes}


def child(out_path: Path, sequence: str) -> None:
    """Inside PX4's namespace: arm, take OFFBOARD, climb to 5 m, settle, fly the sequence, land."""
    from pymavlink.dialects.v20 import common as mav

    with open(out_path, "w") as out:
        r = Recorder(out)
        if r.m.wait_heartbeat(timeout=30) is None:
            raise SystemExit("no PX4 heartbeat")
        r.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, 115, 20000)  # HIL_STATE_QUATERNION (ground truth) at 50 Hz
        r.pump(r.now() + 6.0)
        if r.pos is None:
            raise SystemExit("no LOCAL_POSITION_NED")
        r.segment = "prestream"
        r.stream(1.0)
        for _ in range(30):  # PX4's health checks may still be settling on a loaded machine
            r.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            r.stream(0.5)
            r.command(mav.MAV_CMD_DO_SET_MODE, 1, 6, 0)
            r.stream(0.5)
            if r.armed:
                break
        if not r.armed:
            raise SystemExit("PX4 did not arm")
        r.segment, r.v = "climb", [0.0, 0.0, -1.5]
        t_climb = r.now()
        while r.pos[2] > -5.0 and r.now() - t_climb < 15.0:
            r.stream(0.02)
        r.segment, r.v = "settle", [0.0, 0.0, 0.0]
        r.stream(4.0)
        SEQUENCES[sequence](r)
        r.segment = "land"
        r.command(mav.MAV_CMD_NAV_LAND)
        r.pump(r.now() + 10.0)


@click.command()
@click.argument("out_csv", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--sequence", type=click.Choice(sorted(SEQUENCES)), default="unseen", show_default=True)
@click.option("--speed-factor", type=float, default=1.03, show_default=True, help="PX4_SIM_SPEED_FACTOR")
@click.option("--child", "is_child", is_flag=True, hidden=True)
def main(out_csv: Path, sequence: str, speed_factor: float, is_child: bool) -> None:
    """Record PX4's answer to the sequence into OUT_CSV (gzipped if it ends in .gz)."""
    if is_child:
        child(out_csv, sequence)
        return
    from sim.sitl.px4 import NetNamespace, Px4Sitl, build_dir, unavailable_reason

    reason = unavailable_reason()
    if reason:
        raise SystemExit(reason)
    build = build_dir()
    assert build is not None
    plain = out_csv.with_suffix("") if out_csv.suffix == ".gz" else out_csv
    plain.parent.mkdir(parents=True, exist_ok=True)
    with NetNamespace() as ns:
        rootfs = Path(f"/var/tmp/{ns.name}")
        sitl = Px4Sitl(build, rootfs / "rootfs", ns, speed_factor=speed_factor, out_dir=plain.parent)
        try:
            sitl.start()
            time.sleep(2.0)
            env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
            subprocess.run(ns.command([sys.executable, "-m", "bench.px4_response_record", str(plain), "--sequence", sequence,
                                       "--child"]), check=True, env=env)
        finally:
            sitl.stop()
            import shutil
            shutil.rmtree(rootfs, ignore_errors=True)
    if out_csv.suffix == ".gz":
        with open(plain, "rb") as src, gzip.open(out_csv, "wb") as dst:
            dst.write(src.read())
        plain.unlink()
    click.echo(f"wrote {out_csv}")
    for name, (gap, skew) in gaps(out_csv).items():
        flag = "  <- stalled: not a clean replay" if gap > 0.1 or skew > 0.1 else ""
        click.echo(f"  {name:30s} largest row gap {gap:.3f} s, recorder late by {skew:.3f} s{flag}")


if __name__ == "__main__":
    main()
