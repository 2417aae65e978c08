"""Where the riding passenger truly left the deck in relnav flights on real PX4 SITL
(:mod:`bench.px4_relnav`'s logs; docs/relnav.md, "Where the PX4 ride lost 0.3 m").

For every RIDING tick of each leg: the true horizontal offset of the passenger from the rover's true
dock point (SIH's truth as the camera node received it, the mission's record put on that clock as
:mod:`bench.px4_relnav` does). Each tick over ``--over`` (0.3 m) is put to the first cause that holds,
in this order, from the rover's true motion then and the estimate:

- ``standing``: the rover truly slower than 0.3 m/s before it first moved in this ride (the ride's
  first seconds), ``stopped``: the same after it had moved (braking to a stop under the ride);
- ``speed change``: slower than 0.8 m/s, or its true acceleration along its path over 0.5 m/s^2
  (pulling away, braking), then or within the second before (the passenger still catching up);
- ``turning``: its course turning faster than 10 deg/s then (its heading wobbles +-10 deg on a
  straight course, so only the instant counts);
- ``marker lost``: the newest marker fused older than 0.25 s (``/pair0/relnav``'s ``since_marker_s``);
- ``estimate off``: the estimate's offset more than 0.15 m off the true one;
- ``cruise``: none of these (a straight, steady rover).

Per leg it prints the ticks over and their causes, the median offset along the rover's path while
it cruises (positive: the passenger ahead), and the estimate's error (median, and over the ticks
over). ``PYTHONPATH=. python -m bench.px4_relnav_ride DIR...``; ``--trace N [--span A B]`` prints leg N's
ride every 0.1 s instead (:func:`trace`).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click
import numpy as np

from bench.px4_relnav import PAIR_DIR, _rover_velocity
from bench.px4_team import _at, _on_monotonic, _read_truth
from mission.config.schema import load_config
from mission.flightdata.read import read_messages

STANDING_M_S = 0.3  # [m/s] the rover counts as standing below this true speed
CRUISE_M_S = 0.8  # [m/s] ... as cruising above this, with its acceleration along its path within
ACCEL_M_S2 = 0.5  # [m/s^2]
TURN_DEG_S = 10.0  # [deg/s] its course turning faster than this: a turn
BLIND_S = 0.25  # [s] the newest marker fused older than this: lost
ESTIMATE_OFF_M = 0.15  # [m] the estimate's offset this far off the truth: the estimate's fault
AFTER_S = 1.0  # [s] a speed change still counts this long after it


def _within(flag: np.ndarray, t: np.ndarray, span_s: float) -> np.ndarray:
    """Whether ``flag`` held at any time in ``[t - span_s, t]``, for each time ``t`` [s] (sorted)."""
    held = np.flatnonzero(flag)
    if not len(held):
        return np.zeros(len(t), dtype=bool)
    last = np.searchsorted(t[held], t, side="right") - 1
    return (last >= 0) & (t - t[held[np.clip(last, 0, None)]] <= span_s)


def _since_marker(directory: Path, offset_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The relative estimate's ``since_marker_s`` [s] against the bench's monotonic time [s]."""
    t, since = [], []
    for _, _, log_ns, data in read_messages(directory / PAIR_DIR / "flight.mcap", topics={f"/{PAIR_DIR}/relnav"}).messages:
        value = json.loads(data).get("since_marker_s")
        t.append(log_ns * 1e-9 - offset_s)
        since.append(np.inf if value is None else float(value))
    return np.asarray(t), np.asarray(since)


@dataclass(frozen=True)
class _Flight:
    """One flight's record on the bench's monotonic clock (``rec``: the record and its shift [s]),
    the clocks' offset [s], both truths (rows t, _, x, y, z, ...), the rover's true velocity
    (rows t, north, east) and the dock offset [m] NED."""

    rec: tuple[Any, float]
    offset_s: float
    passenger: np.ndarray
    rover: np.ndarray
    rover_v: np.ndarray
    slot: np.ndarray

    @classmethod
    def read(cls, directory: Path) -> _Flight | None:
        """The flight in ``directory`` (None: no record)."""
        cfg = load_config(directory / "config.toml")
        offset_s = json.loads((directory / "clock_offset.json").read_text())["unix_minus_monotonic_s"]
        rec = _on_monotonic(directory / PAIR_DIR, offset_s)
        if rec is None:
            return None
        _, passenger = _read_truth(directory / "truth-passenger.csv")
        _, rover = _read_truth(directory / "truth-rover.csv")
        return cls(rec, offset_s, passenger, rover, _rover_velocity(directory / "truth-rover.csv"),
                   np.asarray(cfg.mission.dock_offset_ned_m, dtype=float))


def causes(directory: Path, over_m: float = 0.3) -> list[dict[str, Any]]:
    """Per leg of the flight in ``directory``: its RIDING ticks over ``over_m`` [m] by cause (module docstring)."""
    flight = _Flight.read(directory)
    if flight is None:
        return []
    rec, passenger, rover, rover_v, slot = flight.rec, flight.passenger, flight.rover, flight.rover_v, flight.slot
    marker_t, since = _since_marker(directory, flight.offset_s)

    def vel(t: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(t, rover_v[:, 0], rover_v[:, j]) for j in (1, 2)])

    out = []
    for leg in rec[0].legs():
        lr = leg.record
        riding = lr.phase == "RIDING" if lr is not None else np.zeros(0, dtype=bool)
        if lr is None or not riding.any():
            continue
        t = lr.t[riding] + rec[1]
        true = (_at(passenger, t) - (_at(rover, t) + slot))[:, :2]
        size = np.hypot(true[:, 0], true[:, 1])
        v = vel(t)
        speed = np.hypot(v[:, 0], v[:, 1])
        along_u = v / np.maximum(speed, 1e-9)[:, None]
        accel = np.sum((vel(t + 0.1) - vel(t - 0.1)) / 0.2 * along_u, axis=1)
        course = np.unwrap(np.arctan2(v[:, 1], v[:, 0]))
        turn = np.where(speed > STANDING_M_S, np.abs(np.gradient(course, t)) * 180.0 / np.pi, 0.0)
        estimate = (lr.vec("x_p") - lr.vec("dock"))[riding][:, :2]
        est_err = np.hypot(*(estimate - true).T)
        blind = np.interp(t, marker_t, since) if len(marker_t) else np.full(len(t), np.inf)
        moved = np.flatnonzero(speed > STANDING_M_S)
        first_move = t[moved[0]] if len(moved) else np.inf
        changing = _within((speed >= STANDING_M_S) & ((speed < CRUISE_M_S) | (np.abs(accel) > ACCEL_M_S2)), t, AFTER_S)
        counts: dict[str, int] = {}
        for i in np.flatnonzero(size > over_m):
            if speed[i] < STANDING_M_S:
                cause = "standing" if t[i] < first_move else "stopped"
            elif changing[i]:
                cause = "speed change"
            elif turn[i] > TURN_DEG_S:
                cause = "turning"
            elif blind[i] > BLIND_S:
                cause = "marker lost"
            elif est_err[i] > ESTIMATE_OFF_M:
                cause = "estimate off"
            else:
                cause = "cruise"
            counts[cause] = counts.get(cause, 0) + 1
        cruise = speed > CRUISE_M_S
        over = size > over_m
        out.append({"leg": leg.k, "ticks": int(riding.sum()), "over": int(over.sum()), "causes": counts,
                    "median_m": round(float(np.median(size)), 3), "max_m": round(float(size.max()), 3),
                    "max_at_s": round(float(t[int(size.argmax())] - t[0]), 1),
                    "along_cruise_m": round(float(np.median(np.sum(true * along_u, axis=1)[cruise])), 3) if cruise.any() else None,
                    "estimate_error_m": round(float(np.median(est_err)), 3),
                    "estimate_error_over_m": round(float(np.median(est_err[over])), 3) if over.any() else None})
    return out


def trace(directory: Path, leg_k: int, span_s: tuple[float, float], step_s: float = 0.1) -> list[dict[str, float]]:
    """Leg ``leg_k``'s ride in ``directory`` every ``step_s`` [s] over ``span_s`` [s] into it: the
    true offset from the dock point [m] (north, east, size), and north/east velocities [m/s] of
    the rover (true), the passenger (true), the deck as the phases saw it (``v_c``) and the
    command (``u_cmd``)."""
    flight = _Flight.read(directory)
    if flight is None:
        return []
    rec, passenger, rover, rover_v, slot = flight.rec, flight.passenger, flight.rover, flight.rover_v, flight.slot
    passenger_v = _rover_velocity(directory / "truth-passenger.csv")  # the same columns
    out: list[dict[str, float]] = []
    for leg in rec[0].legs():
        lr = leg.record
        if leg.k != leg_k or lr is None or not (lr.phase == "RIDING").any():
            continue
        riding = lr.phase == "RIDING"
        t_all = lr.t[riding] + rec[1]
        deck, cmd = lr.vec("v_c")[riding], lr.vec("u_cmd")[riding]
        for t in np.arange(t_all[0] + span_s[0], min(t_all[0] + span_s[1], t_all[-1]) + 1e-9, step_s):
            i = int(np.searchsorted(t_all, t))
            i = min(i, len(t_all) - 1)
            off = (_at(passenger, np.array([t])) - (_at(rover, np.array([t])) + slot))[0, :2]
            row = {"s": round(float(t - t_all[0]), 2), "off_n": float(off[0]), "off_e": float(off[1]),
                   "off": float(np.hypot(*off))}
            for name, series in (("rover", rover_v), ("passenger", passenger_v)):
                for j, axis in ((1, "n"), (2, "e")):
                    row[f"{name}_v{axis}"] = float(np.interp(t, series[:, 0], series[:, j]))
            for name, vec in (("deck", deck), ("cmd", cmd)):
                row[f"{name}_vn"], row[f"{name}_ve"] = float(vec[i, 0]), float(vec[i, 1])
            out.append({k: round(v, 3) for k, v in row.items()})
    return out


@click.command()
@click.argument("flights", nargs=-1, type=click.Path(file_okay=False, exists=True))
@click.option("--over", "over_m", type=float, default=0.3, show_default=True, help="[m] the riding offset counted")
@click.option("--trace", "trace_leg", type=int, default=None,
              help="Instead: print leg N's ride every 0.1 s over --span (the offset, the rover's, the passenger's, "
                   "the deck's and the command's velocities) of each flight.")
@click.option("--span", type=(float, float), default=(0.0, 4.0), show_default=True, help="[s] into the ride, with --trace")
def main(flights: tuple[str, ...], over_m: float, trace_leg: int | None, span: tuple[float, float]) -> None:
    """Print, per leg of each flight, where its true riding offset went over --over."""
    if trace_leg is not None:
        for d in flights:
            for row in trace(Path(d), trace_leg, span):
                click.echo(f"{Path(d).name} {json.dumps(row)}")
        return
    total: dict[str, int] = {}
    for d in flights:
        for row in causes(Path(d), over_m):
            click.echo(f"{Path(d).name} {json.dumps(row)}")
            for k, n in row["causes"].items():
                total[k] = total.get(k, 0) + n
    click.echo(f"ticks over {over_m} m by cause: {json.dumps(total)}")


if __name__ == "__main__":
    main()
