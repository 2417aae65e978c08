"""PX4 holding a point: its estimate against SIH's true state, alone and under our tracking terms.

One fresh real PX4 SITL (SIH quadrotor) in a network namespace of its own (:mod:`sim.sitl.px4`),
flown by this script over PX4's onboard link at 50 Hz: climb to 5 m on a position setpoint, settle,
then hold one point for ``--hold-s`` seconds under each *law* in turn. A law is what
:func:`mission.core.tracking.setpoint` sends with the reference still (``u_ref = a_ref = 0``):

- ``px4``: the point itself as position setpoint, zero velocity and acceleration (PX4 alone);
- ``vel``: zero velocity only (type_mask 3527: PX4 alone, holding velocity, not position);
- ``lead=L``: the position ``x_ref + L (x_ref - x_p)`` on PX4's latest estimate ``x_p`` (our lead);
- ``lead=L,int=K``: plus our windowed integral into the acceleration (``K`` [1/s^2]);
- ``lead=L,damp=D``: plus our velocity damping ``-D v_p`` in the acceleration;
- ``lead=L,bias=TAU`` (or ``px4,bias=TAU``: lead 0): the estimator's velocity less its position's
  rate, low-passed with ``TAU`` [s] (:mod:`mission.core.consistent_velocity`), compensated
  through the position (``mission.bias_compensation_s`` = 1 / MPC_XY_P);
- ``slow=V``: the reference moves along north at ``V`` [m/s] back and forth over 3 m, flown
  as position + velocity (the slow motion of the last metre), with the shipped lead 2.6.

PX4 streams LOCAL_POSITION_NED (its estimate) and HIL_STATE_QUATERNION (its GROUND_TRUTH stream:
SIH's true position and velocity, the ``vehicle_*_groundtruth`` topics) at 50 Hz, both asked with
SET_MESSAGE_INTERVAL; the true position is projected about PX4's EKF origin (GPS_GLOBAL_ORIGIN)
with PX4's projection. Per law, over the hold after its first 5 s: the mean and peak horizontal
speed, estimated and true; the horizontal spread about the point (RMS, max), estimated and true;
the estimate's error (estimate - truth, its mean removed: RMS of position and velocity); and the
spectra (power in bands of the horizontal position and velocity, estimate, truth and error).

Usage: ``python -m bench.px4_hold [--laws px4,lead=2.6,...] [--hold-s 30] [--out DIR] [--json F]``
(real time: ~30 s plus ``hold-s`` per law). Needs root and ``MARSUPIAL_PX4_SITL``; run it under
``flock /tmp/marsupial-px4.lock``.
"""
from __future__ import annotations

import json
import math
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click
import numpy as np

from mission.core.consistent_velocity import PositionConsistentVelocity
from mission.core.tracking import TrackingGains, setpoint, update_integral
from mission.mavlink import px4
from sim.sitl import ground_truth
from sim.sitl.px4 import NetNamespace, Px4Sitl, build_dir, clock_ratio_of, unavailable_reason

RATE_HZ = 50.0
PX4_XY_P = 0.95  # MPC_XY_P, PX4's default
HOVER_D_M = -5.0
BANDS_HZ = ((0.0, 0.1), (0.1, 0.3), (0.3, 1.0), (1.0, 3.0), (3.0, 25.0))


@dataclass(frozen=True)
class Law:
    """What one hold segment sends (see the module docstring)."""

    name: str
    gains: TrackingGains
    slow_m_s: float = 0.0  # the reference moves back and forth along north at this speed [m/s]
    bias_tau_s: float = 0.0  # > 0: the estimator's velocity bias measured (this time constant) and compensated


# The gains every law starts from: no pull, no term on; a law sets what it names.
BASE_GAINS = dict(kind="velocity", position_gain_per_s=0.0, position_lead=0.0, integral_gain=0.0, integral_limit=2.0,
                  drag_ff_per_s=0.0, integral_window_m=0.5, damping_per_s=0.0, bias_compensation_s=0.0,
                  accel_lead_s=0.0, accel_lead_filter_s=0.1, accel_limit_m_s2=None, slow_lag_m=None, stop_lag_m=None)


def parse_law(text: str) -> Law:
    """``px4`` | ``vel`` | ``lead=L[,int=K][,damp=D][,bias=TAU][,slow=V]`` (``px4,bias=TAU``: lead 0)
    -> :class:`Law`."""
    if text == "vel":
        return Law(text, TrackingGains(**BASE_GAINS))
    fields = dict(part.split("=", 1) if "=" in part else (part, "") for part in text.split(","))
    lead = 0.0 if "px4" in fields else float(fields.get("lead", 2.6))
    tau = float(fields.get("bias", 0.0))
    gains = TrackingGains(**{**BASE_GAINS, "kind": "full", "position_lead": lead,
                             "integral_gain": float(fields.get("int", 0.0)),
                             "damping_per_s": float(fields.get("damp", 0.0)),
                             "bias_compensation_s": 1.0 / PX4_XY_P if tau > 0 else 0.0})
    return Law(text, gains, float(fields.get("slow", 0.0)), tau)


def reference(law: Law, point: np.ndarray, tau_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The reference (position [m], velocity [m/s]) ``tau_s`` into a law's segment: still, or a
    triangle wave along north over 3 m at ``law.slow_m_s``."""
    if law.slow_m_s <= 0:
        return point.copy(), np.zeros(3)
    span = 3.0
    period = 2 * span / law.slow_m_s
    phase = (tau_s % period) / period
    out = phase < 0.5
    s = (phase * 2 if out else (1 - phase) * 2) * span
    v = law.slow_m_s if out else -law.slow_m_s
    return point + np.array([s, 0.0, 0.0]), np.array([v, 0.0, 0.0])


class Flyer:
    """The 50 Hz setpoint loop over PX4's onboard link (a :class:`sim.testing.probe.Probe`)."""

    def __init__(self, probe: Any) -> None:
        self.probe = probe
        self.law: Law | None = None
        self.point = np.array([0.0, 0.0, HOVER_D_M])
        self.integral = np.zeros(3)
        self.fix: PositionConsistentVelocity | None = None
        self.segment = "climb"
        self.since = time.monotonic()
        self.marks: list[tuple[float, str]] = [(self.since, self.segment)]
        self.sent: list[tuple[float, str, np.ndarray, np.ndarray, np.ndarray]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="px4-hold", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def begin(self, segment: str, law: Law | None) -> None:
        self.law, self.segment, self.since = law, segment, time.monotonic()
        self.integral = np.zeros(3)
        self.fix = PositionConsistentVelocity(law.bias_tau_s) if law is not None and law.bias_tau_s > 0 else None
        self.marks.append((self.since, segment))

    def _estimate(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None] | None:
        """PX4's latest position and velocity (made consistent with the position when the law
        asks) and the velocity bias taken off (None without)."""
        lp = self.probe.latest("LOCAL_POSITION_NED")
        if lp is None:
            return None
        x, v = np.array([lp.x, lp.y, lp.z]), np.array([lp.vx, lp.vy, lp.vz])
        if self.fix is None:
            return x, v, None
        fixed = self.fix.update(lp.time_boot_ms * 1e-3, x, v)
        return x, fixed, v - fixed

    def _run(self) -> None:
        period = 1.0 / RATE_HZ
        nxt = time.monotonic()
        while not self._stop.is_set():
            est = self._estimate()
            law = self.law
            if est is None:
                p, v, a = self.point, np.zeros(3), np.zeros(3)
            elif law is None:
                p, v, a = self.point, np.zeros(3), np.zeros(3)
            else:
                x_p, v_p, bias = est
                x_ref, u_ref = reference(law, self.point, time.monotonic() - self.since)
                sp = setpoint(x_ref, u_ref, np.zeros(3), x_p, u_ref, self.integral, law.gains, v_p, bias)
                p = x_ref if sp.position_ned_m is None else sp.position_ned_m
                a = np.zeros(3) if sp.acceleration_ned_m_s2 is None else sp.acceleration_ned_m_s2
                v = sp.velocity_ned_m_s
                self.integral = update_integral(self.integral, x_ref, x_p, law.gains, period)
            if law is not None and law.gains.kind == "velocity":
                msg = self.probe.setpoint_message((0.0, 0.0, 0.0))
            else:
                msg = self.probe.setpoint_message(tuple(v), type_mask=px4.TYPE_MASK_POSITION_VELOCITY_ACCELERATION,
                                                  position_ned_m=tuple(p), acceleration_ned_m_s2=tuple(a))
            try:
                self.probe.send(msg)
            except (OSError, RuntimeError):
                pass
            self.sent.append((time.monotonic(), self.segment, p.copy(), np.asarray(v, float).copy(), np.asarray(a, float).copy()))
            nxt += period
            self._stop.wait(max(0.0, nxt - time.monotonic()))


def _welch(x: np.ndarray, fs: float, seg: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """One-sided power spectral density [unit^2/Hz] of ``x`` (Hann windows, half overlap)."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    seg = min(seg, len(x))
    win = np.hanning(seg)
    scale = fs * (win ** 2).sum()
    psd = np.zeros(seg // 2 + 1)
    count = 0
    for start in range(0, len(x) - seg + 1, seg // 2):
        chunk = x[start:start + seg] - x[start:start + seg].mean()
        psd += np.abs(np.fft.rfft(chunk * win)) ** 2 / scale
        count += 1
    psd = psd / max(count, 1)
    psd[1:-1] *= 2
    return np.fft.rfftfreq(seg, 1 / fs), psd


def band_rms(x: np.ndarray, fs: float) -> list[float]:
    """RMS [unit] of ``x`` in each of :data:`BANDS_HZ` (from its PSD)."""
    f, p = _welch(x, fs)
    df = f[1] - f[0]
    return [float(math.sqrt(p[(f >= lo) & (f < hi)].sum() * df)) for lo, hi in BANDS_HZ]


def analyse(est: np.ndarray, truth: np.ndarray, t0: float, t1: float, point: np.ndarray) -> dict[str, Any]:
    """The figures of one hold (rows of :func:`sim.sitl.ground_truth.series` between receive
    times ``t0`` and ``t1``)."""
    est, truth = np.delete(est, 1, axis=1), np.delete(truth, 1, axis=1)  # no boot times here
    e = est[(est[:, 0] >= t0) & (est[:, 0] < t1)]
    out: dict[str, Any] = {"samples": len(e), "span_s": round(t1 - t0, 1)}
    if len(e) < 100:
        return out
    fs = (len(e) - 1) / (e[-1, 0] - e[0, 0])
    sp_e = np.hypot(e[:, 4], e[:, 5])
    off_e = np.hypot(e[:, 1] - point[0], e[:, 2] - point[1])
    out.update(est_speed_mean=float(sp_e.mean()), est_speed_max=float(sp_e.max()), est_offset_rms=float(np.sqrt((off_e ** 2).mean())),
               est_offset_max=float(off_e.max()), fs_hz=float(fs))
    out["est_pos_bands"] = [math.hypot(a, b) for a, b in zip(band_rms(e[:, 1], fs), band_rms(e[:, 2], fs))]
    out["est_vel_bands"] = [math.hypot(a, b) for a, b in zip(band_rms(e[:, 4], fs), band_rms(e[:, 5], fs))]
    # the speed the mission sees with its velocity made consistent with the position (tau 1 s)
    fix = PositionConsistentVelocity(1.0)
    fixed = np.array([fix.update(row[0], row[1:4], row[4:7]) for row in e])
    out["est_consistent_speed_mean"] = float(np.hypot(fixed[:, 0], fixed[:, 1]).mean())
    # the estimate's position rate (its jumps) against its own velocity
    dt = np.diff(e[:, 0])
    ok = dt > 1e-3
    rate = np.hypot(np.diff(e[:, 1])[ok] / dt[ok], np.diff(e[:, 2])[ok] / dt[ok])
    out["est_position_rate_mean"] = float(rate.mean())
    if truth.size:
        tr = truth[(truth[:, 0] >= t0 - 1) & (truth[:, 0] < t1 + 1)]
        if len(tr) > 100:
            ti = np.column_stack([np.interp(e[:, 0], tr[:, 0], tr[:, k]) for k in range(1, 7)])
            sp_t = np.hypot(ti[:, 3], ti[:, 4])
            err = e[:, 1:7] - ti
            bias = err.mean(axis=0)
            off_t = np.hypot(ti[:, 0] - point[0] + bias[0], ti[:, 1] - point[1] + bias[1])  # about the point as PX4 places it
            out.update(true_speed_mean=float(sp_t.mean()), true_speed_max=float(sp_t.max()),
                       true_offset_rms=float(np.sqrt((off_t ** 2).mean())), true_offset_max=float(off_t.max()),
                       err_bias_ne=[float(bias[0]), float(bias[1])],
                       err_pos_rms=float(np.sqrt(((err[:, 0] - bias[0]) ** 2 + (err[:, 1] - bias[1]) ** 2).mean())),
                       err_vel_rms=float(np.sqrt(((err[:, 3] - bias[3]) ** 2 + (err[:, 4] - bias[4]) ** 2).mean())))
            out["true_pos_bands"] = [math.hypot(a, b) for a, b in zip(band_rms(ti[:, 0], fs), band_rms(ti[:, 1], fs))]
            out["true_vel_bands"] = [math.hypot(a, b) for a, b in zip(band_rms(ti[:, 3], fs), band_rms(ti[:, 4], fs))]
            out["err_pos_bands"] = [math.hypot(a, b) for a, b in zip(band_rms(err[:, 0], fs), band_rms(err[:, 1], fs))]
            out["err_vel_bands"] = [math.hypot(a, b) for a, b in zip(band_rms(err[:, 3], fs), band_rms(err[:, 4], fs))]
    return out


def fly(laws: list[Law], hold_s: float, out: Path, speed_factor: float) -> dict[str, Any]:
    """One PX4 flight holding the point under each law in turn; the figures per law."""
    from sim.testing.probe import Probe

    out.mkdir(parents=True, exist_ok=True)
    build = build_dir()
    assert build is not None
    result: dict[str, Any] = {"laws": {}}
    with NetNamespace() as ns:
        rootfs = Path(f"/var/tmp/{ns.name}")
        sitl = Px4Sitl(build, rootfs / "rootfs", ns, speed_factor=speed_factor, out_dir=out)
        probe = None
        flyer = None
        try:
            sitl.start()
            probe = ns.inside(lambda: Probe(bind="127.0.0.1:14540", vehicle=("127.0.0.1", 14580), history_len=200_000))
            from sim.sitl.px4 import wait_armable
            from sim.testing.probe import connect

            connect(probe, timeout_s=30.0, heartbeat_period_s=0.5)
            wait_armable(probe, 60.0)
            result["asked"] = ground_truth.ask(probe, RATE_HZ)
            lp = probe.wait_for("LOCAL_POSITION_NED", timeout_s=5.0)
            if lp is None:
                raise RuntimeError("no LOCAL_POSITION_NED")
            flyer = Flyer(probe)
            flyer.point = np.array([lp.x, lp.y, HOVER_D_M])
            flyer.start()
            time.sleep(1.0)
            for _ in range(20):
                ack = probe.set_mode("OFFBOARD", timeout_s=0.5)
                if ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED:
                    break
            ack = probe.arm()
            if ack is None or ack.result != px4.MAV_RESULT_ACCEPTED:
                raise RuntimeError(f"arming refused: {ack}")
            time.sleep(15.0)  # climb and settle on PX4 alone
            spans = []
            for law in laws:
                flyer.begin(law.name, law)
                t0 = time.monotonic()
                time.sleep(hold_s)
                spans.append((law, t0, time.monotonic()))
            flyer.begin("end", None)
            time.sleep(0.5)
            est, truth = ground_truth.series(probe)
            result["truth_samples"] = int(len(truth))
            result["clock_ratio"] = clock_ratio_of(est[:, 0], est[:, 1])
            for i, (law, t0, t1) in enumerate(spans):
                result["laws"][f"{i}:{law.name}"] = analyse(est, truth, t0 + 5.0, t1, flyer.point)
            ground_truth.write_csv(out / "hold.csv", est, truth)
            (out / "segments.json").write_text(json.dumps(flyer.marks))
        finally:
            if flyer is not None:
                flyer.stop()
            if probe is not None:
                probe.close()
            sitl.stop()
            import shutil
            shutil.rmtree(rootfs, ignore_errors=True)
    return result


def _fmt_bands(values: list[float] | None) -> str:
    return "/".join(f"{v:.3f}" for v in values) if values else "-"


@click.command()
@click.option("--laws", default="px4;lead=2.6;lead=2.6,int=1", show_default=True,
              help="laws to hold under, separated by ';' (see the module docstring)")
@click.option("--hold-s", type=float, default=30.0, show_default=True)
@click.option("--out", type=click.Path(file_okay=False), default=None)
@click.option("--speed-factor", type=float, default=1.03, show_default=True, help="PX4_SIM_SPEED_FACTOR")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None)
def main(laws: str, hold_s: float, out: str | None, speed_factor: float, json_path: str | None) -> None:
    why = unavailable_reason()
    if why:
        raise click.ClickException(why)
    chosen = [parse_law(x.strip()) for x in laws.split(";") if x.strip()]
    base = Path(out or f"/tmp/px4-hold-{os.getpid()}")
    click.echo(f"PX4 build {build_dir()}, laws {[x.name for x in chosen]}, hold {hold_s:g} s each, load {os.getloadavg()[0]:.1f}")
    res = fly(chosen, hold_s, base, speed_factor)
    click.echo(f"PX4 clock / wall {res['clock_ratio']:.3f}; ground truth samples {res['truth_samples']}; "
               f"bands [Hz] {'/'.join(f'{lo:g}-{hi:g}' for lo, hi in BANDS_HZ)}")
    cols = ("est_speed_mean", "est_consistent_speed_mean", "est_speed_max", "true_speed_mean", "true_speed_max", "est_offset_rms", "true_offset_rms",
            "err_pos_rms", "err_vel_rms", "est_position_rate_mean")
    click.echo(f"{'law':>22} " + " ".join(f"{c:>22}" for c in cols))
    for name, r in res["laws"].items():
        click.echo(f"{name:>22} " + " ".join(f"{r.get(c, float('nan')):>22.3f}" for c in cols))
    for key in ("est_pos_bands", "true_pos_bands", "err_pos_bands", "est_vel_bands", "true_vel_bands", "err_vel_bands"):
        click.echo(f"{key:>16}: " + "  ".join(f"{name} {_fmt_bands(r.get(key))}" for name, r in res["laws"].items()))
    if json_path:
        Path(json_path).write_text(json.dumps(res, indent=2))
    click.echo(f"logs in {base}")


if __name__ == "__main__":
    main()
