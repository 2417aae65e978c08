"""Replay a recorded PX4 SITL response sequence into the mock vehicle's dynamics, and compare.

The recording (``record_responses.py`` of ../shared/px4_sitl, one CSV row per LOCAL_POSITION_NED
received from a real PX4) holds the setpoint in force at each row and PX4's own clock
(``px4_time_boot_ms``). Everything here runs on PX4's clock, never on the recorder's wall clock.

Replay: the setpoint of row ``i`` took effect halfway between rows ``i-1`` and ``i`` (the
recorder sent at 50 Hz, the rows come at 30 Hz). The dynamics (:func:`sim.vehicle.physics.multicopter.step`,
fixed steps of ``dt_s``) start hovering at PX4's position and velocity at the first replayed
row, and run continuously through every segment. At the start of each segment the simulated
position is moved to PX4's (a translation: it changes nothing for velocity setpoints, and it
gives a position setpoint the same starting error as on PX4, whose estimate drifts by metres).

Metrics per segment: RMS over the rows of the 3-D velocity difference [m/s], and for the ramps the
lag: the largest along-track distance [m] behind the commanded path (the position setpoint, or
for velocity-only setpoints the integral of the commanded velocity from the segment start).
"""
from __future__ import annotations

import csv
import gzip
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.vehicle.estimator import EstimateError
from sim.vehicle.physics.multicopter import Command, KinState, Limits, step

SCORED_PREFIXES = ("step_", "ramp_", "sine_")  # the segments the fit and the targets use
RAMP_SEGMENTS = ("ramp_velocity_only", "ramp_pos_vel_acc")
FIRST_REPLAYED_SEGMENT = "settle"  # hovering at 5 m after the climb


@dataclass(frozen=True)
class Recording:
    """Columns of a response recording (numpy arrays, one entry per row)."""

    t_s: np.ndarray  # PX4's clock [s]
    segment: np.ndarray  # segment name (str)
    kind: np.ndarray  # "velocity" | "pos_vel_acc"
    sp_pos: np.ndarray  # (N, 3) [m] NED, NaN when unused
    sp_vel: np.ndarray  # (N, 3) [m/s]
    sp_acc: np.ndarray  # (N, 3) [m/s^2], NaN when unused
    pos: np.ndarray  # (N, 3) [m] measured by PX4
    vel: np.ndarray  # (N, 3) [m/s] measured by PX4
    true_vel: np.ndarray | None = None  # (N, 3) [m/s] SIH's true velocity at each row, if recorded (NaN before the first)

    def segments(self) -> list[str]:
        """Segment names in flight order."""
        return list(dict.fromkeys(self.segment.tolist()))

    def scored_segments(self) -> list[str]:
        """The step, ramp and sine segments (not their ``_stop`` tails)."""
        return [s for s in self.segments() if s.startswith(SCORED_PREFIXES) and not s.endswith("_stop")]

    def rows(self, segment: str) -> np.ndarray:
        return np.flatnonzero(self.segment == segment)


def load_recording(path: str | Path) -> Recording:
    """Read a ``px4_offboard_responses.csv`` (optionally gzipped)."""
    path = Path(path)
    opener = gzip.open if path.suffix == ".gz" else open
    with opener(path, "rt", newline="") as handle:  # type: ignore[operator]
        rows = list(csv.DictReader(handle))
    if not rows:
        raise ValueError(f"{path}: no rows")

    def col(name: str) -> np.ndarray:
        try:
            return np.array([float(r[name]) for r in rows])
        except KeyError as exc:
            raise ValueError(f"{path}: missing column {name!r}") from exc

    def cols(*names: str) -> np.ndarray:
        return np.column_stack([col(n) for n in names])

    return Recording(
        t_s=col("px4_time_boot_ms") / 1000.0, segment=np.array([r["segment"] for r in rows]),
        kind=np.array([r["setpoint_kind"] for r in rows]),
        sp_pos=cols("sp_x_m", "sp_y_m", "sp_z_m"), sp_vel=cols("sp_vx_m_s", "sp_vy_m_s", "sp_vz_m_s"),
        sp_acc=cols("sp_ax_m_s2", "sp_ay_m_s2", "sp_az_m_s2"), pos=cols("x_m", "y_m", "z_m"),
        vel=cols("vx_m_s", "vy_m_s", "vz_m_s"),
        true_vel=cols("true_vx_m_s", "true_vy_m_s", "true_vz_m_s") if "true_vx_m_s" in rows[0] else None)


class RecordedEstimateError:
    """PX4's own velocity estimate error as one flight measured it (estimate - SIH's truth, from a
    recording with ``true_vel``, from its ``settle`` segment to its landing), replayed in place of
    :class:`sim.vehicle.estimator.EstimateError`'s draw: :meth:`advance` moves along it, starting
    ``offset_s`` [s] into it and wrapping round; :attr:`velocity` [m/s] NED is the error there,
    :attr:`position` zero. Another flight's error is a draw of PX4's own errors."""

    enabled = True

    def __init__(self, source: Recording, offset_s: float = 0.0) -> None:
        if source.true_vel is None:
            raise ValueError("the recording has no true velocity")
        first, last = int(source.rows(FIRST_REPLAYED_SEGMENT)[0]), int(source.rows("land")[0])
        self._t = source.t_s[first:last] - source.t_s[first]
        self._error = np.nan_to_num(source.vel[first:last] - source.true_vel[first:last])
        self.span_s = float(self._t[-1])
        self._u = offset_s % self.span_s
        self.position: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.velocity: tuple[float, float, float] = self._at(self._u)

    def _at(self, u: float) -> tuple[float, float, float]:
        e = [float(np.interp(u, self._t, self._error[:, k])) for k in range(3)]
        return (e[0], e[1], e[2])

    def advance(self, dt_s: float, flown: bool = True) -> None:
        self._u = (self._u + dt_s) % self.span_s
        self.velocity = self._at(self._u)


def command_of_row(rec: Recording, i: int) -> Command:
    """The setpoint of row ``i`` as the vehicle's command (PX4 semantics of the recorder's masks)."""
    v = rec.sp_vel[i]
    if rec.kind[i] == "velocity":
        return Command(float(v[0]), float(v[1]), float(v[2]))
    p, a = rec.sp_pos[i], rec.sp_acc[i]
    return Command(float(v[0]), float(v[1]), float(v[2]), position_ned_m=(float(p[0]), float(p[1]), float(p[2])),
                   acceleration_ned_m_s2=(float(a[0]), float(a[1]), float(a[2])))


def simulate(rec: Recording, limits: Limits, dt_s: float = 0.005, first_segment: str = FIRST_REPLAYED_SEGMENT,
             estimate: EstimateError | RecordedEstimateError | None = None) -> np.ndarray:
    """Replay ``rec`` into the dynamics from ``first_segment`` on; the velocity (N, 3) [m/s] the
    vehicle reports at every row (NaN before the first replayed row). With ``estimate`` PX4's
    controller flies the estimate, which errs so (:mod:`sim.vehicle.estimator`), and the
    velocity reported is the estimate's; without, the estimate is exact."""
    start = int(rec.rows(first_segment)[0])
    n = len(rec.t_s)
    out = np.full((n, 3), np.nan)
    p0, v0 = rec.pos[start], rec.vel[start]
    kin = KinState(float(p0[0]), float(p0[1]), float(p0[2]), float(v0[0]), float(v0[1]), float(v0[2]),
                   ground_d_m=0.0, on_ground=False)
    wind = (0.0, 0.0, 0.0)
    t = float(rec.t_s[start])
    out[start] = v0
    command = command_of_row(rec, start)
    est = estimate if estimate is not None and estimate.enabled else None

    def advance(kin: KinState) -> KinState:
        if est is None:
            return step(kin, command, limits, wind, dt_s)
        est.advance(dt_s)
        return step(kin, command, limits, wind, dt_s, (est.position, est.velocity))

    for i in range(start + 1, n):
        t_switch = 0.5 * (rec.t_s[i - 1] + rec.t_s[i])
        while t + dt_s <= t_switch + 1e-9:
            kin = advance(kin)
            t += dt_s
        if rec.segment[i] != rec.segment[i - 1]:  # align the position with PX4's (see the module docstring)
            shift = rec.pos[i] - np.array((kin.n_m, kin.e_m, kin.d_m)) - np.array((kin.vn_m_s, kin.ve_m_s, kin.vd_m_s)) * (rec.t_s[i] - t)
            if est is not None:
                shift -= np.array(est.position)  # PX4's is its estimate's position
            kin = _translated(kin, shift)
        command = command_of_row(rec, i)
        while t + dt_s <= rec.t_s[i] + 1e-9:
            kin = advance(kin)
            t += dt_s
        out[i] = (kin.vn_m_s, kin.ve_m_s, kin.vd_m_s)
        if est is not None:
            out[i] += est.velocity
        if kin.on_ground:
            break
    return out


def _translated(kin: KinState, shift: np.ndarray) -> KinState:
    return KinState(kin.n_m + float(shift[0]), kin.e_m + float(shift[1]), kin.d_m + float(shift[2]), kin.vn_m_s,
                    kin.ve_m_s, kin.vd_m_s, kin.yaw_rad, kin.yaw_rate_rad_s, kin.an_m_s2, kin.ae_m_s2,
                    kin.ground_d_m, kin.on_ground, kin.ad_m_s2, kin.dvn_m_s2,
                    kin.dve_m_s2, kin.dvd_m_s2, kin.ctrl)


def rms_by_segment(rec: Recording, velocity: np.ndarray, segments: Iterable[str]) -> dict[str, float]:
    """RMS [m/s] of the 3-D velocity difference ``velocity - rec.vel`` over each segment's rows."""
    out = {}
    for name in segments:
        rows = rec.rows(name)
        diff = np.linalg.norm(velocity[rows] - rec.vel[rows], axis=1)
        out[name] = float(np.sqrt(np.nanmean(diff ** 2)))
    return out


def ramp_lag_m(rec: Recording, segment: str, velocity: np.ndarray | None = None) -> float:
    """Largest along-track lag [m] behind the commanded path over ``segment`` (north ramps).

    With ``velocity`` (N, 3) the vehicle's path is its integral from the segment start (the
    mock); without, PX4's measured positions.
    """
    rows = rec.rows(segment)
    t = rec.t_s[rows]
    if velocity is None:
        along = rec.pos[rows, 0] - rec.pos[rows[0], 0]
    else:
        along = _integral(t, velocity[rows, 0])
    if rec.kind[rows[0]] == "velocity":
        commanded = _integral(t, rec.sp_vel[rows, 0])
    else:
        commanded = rec.sp_pos[rows, 0] - rec.pos[rows[0], 0]
    return float(np.max(commanded - along))


def _integral(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Trapezoidal running integral of ``v`` over ``t`` from 0."""
    return np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))))


@dataclass(frozen=True)
class Comparison:
    """The mock's replay against one recording."""

    rms_m_s: dict[str, float]  # per scored segment
    lag_mock_m: dict[str, float]  # per ramp
    lag_px4_m: dict[str, float]

    @property
    def mean_rms_m_s(self) -> float:
        return float(np.mean(list(self.rms_m_s.values())))

    def lag_ratio(self, segment: str) -> float:
        """Mock lag / PX4 lag (1 = equal)."""
        return self.lag_mock_m[segment] / self.lag_px4_m[segment]


def compare(rec: Recording, limits: Limits, dt_s: float = 0.005,
            estimate: EstimateError | RecordedEstimateError | None = None) -> Comparison:
    """Replay ``rec`` (``estimate``: as :func:`simulate`) and score the mock against it."""
    velocity = simulate(rec, limits, dt_s, estimate=estimate)
    rms = rms_by_segment(rec, velocity, rec.scored_segments())
    ramps = [s for s in RAMP_SEGMENTS if s in rec.segments()]
    return Comparison(rms, {s: ramp_lag_m(rec, s, velocity) for s in ramps}, {s: ramp_lag_m(rec, s) for s in ramps})


def px4_vs_px4_rms(a: Recording, b: Recording) -> dict[str, float]:
    """RMS [m/s] between two recordings of the same sequence, per scored segment, aligned on each
    segment's first row (how far PX4 is from itself)."""
    out = {}
    for name in a.scored_segments():
        ra, rb = a.rows(name), b.rows(name)
        ta, tb = a.t_s[ra] - a.t_s[ra[0]], b.t_s[rb] - b.t_s[rb[0]]
        keep = ta <= tb[-1]
        vb = np.column_stack([np.interp(ta[keep], tb, b.vel[rb, k]) for k in range(3)])
        out[name] = float(np.sqrt(np.mean(np.sum((a.vel[ra][keep] - vb) ** 2, axis=1))))
    return out
