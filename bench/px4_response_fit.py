"""The mock vehicle against real PX4's recorded offboard responses. Prints a table.

Replays the setpoint sequence of each recording (``tests/data/px4_responses/``, copied from
../shared/px4_sitl/responses/: ``original`` and the held-out ``repeat``) into the mock's dynamics
(:mod:`sim.sitl.replay`) and prints, per step / ramp / sine segment, the RMS velocity difference
from PX4, the mean over the segments, the ramp lags, and PX4 against itself (the two
recordings). PX4's ramp lag is given from its positions and from the integral of its velocities:
its position estimate drifts by 1-2 m from that integral over a ramp (EKF, SIH's GPS noise),
which no deterministic mock reproduces.

``--fit`` refits the free airframe constants (:class:`sim.vehicle.physics.multicopter.Airframe`: drag, tilt
lag, thrust lag, vertical drag) to the ``original`` recording only by Nelder-Mead on the mean RMS, and prints them
beside :data:`sim.vehicle.physics.multicopter.FITTED_AIRFRAME`; ``repeat`` stays a held-out check.

``--seeds N`` also replays with PX4 SITL's estimate errors (the mock as shipped:
:mod:`sim.vehicle.estimator`, seeds 1..N) and prints, per recording, each draw's mean RMS and that of the
draws' mean velocity (the mock's prediction, as the closed-loop figures are the mean of seeds). A
single draw errs on its own, and PX4's recording on its own, so its RMS is above the exact
estimate's (docs/mock-vehicle.md, "How close to PX4").

``unseen`` (``tests/data/px4_responses/unseen.csv.gz``, :mod:`bench.px4_response_record`: another
sequence, neither fit saw it, with SIH's true velocity beside PX4's) is scored on its own: the
exact mock per segment and, with ``--seeds``, the draws. ``--px4-error N`` replays ``original`` and
``repeat`` with PX4's own velocity error as the ``unseen`` flight measured it (estimate - truth,
:class:`sim.sitl.replay.RecordedEstimateError`) from N starting points: a draw of PX4's own
errors, the floor of what a draw of a faithful model can score.

Usage: ``python -m bench.px4_response_fit [--fit] [--seeds N] [--px4-error N] [--json out.json]``.
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

import click
import numpy as np

from sim.sitl.replay import (Comparison, RecordedEstimateError, Recording, compare, load_recording, px4_vs_px4_rms, ramp_lag_m,
                             rms_by_segment, simulate)
from sim.vehicle.estimator import PX4_SITL_SCALE, EstimateError
from sim.vehicle.physics.multicopter import FITTED_AIRFRAME, Airframe, Limits

DATA = Path(__file__).resolve().parents[1] / "tests" / "data" / "px4_responses"
RECORDINGS = ("original", "repeat")
UNSEEN = "unseen"  # a sequence neither fit saw, with SIH's true velocity (bench/px4_response_record.py)


def load_all() -> dict[str, Recording]:
    return {name: load_recording(DATA / f"{name}.csv.gz") for name in RECORDINGS}


def load_unseen() -> Recording | None:
    path = DATA / f"{UNSEEN}.csv.gz"
    return load_recording(path) if path.exists() else None


def with_px4_error(recs: dict[str, Recording], source: Recording, draws: int) -> dict[str, list[float]]:
    """Per recording: the mean RMS [m/s] of its replay with PX4's own measured velocity error
    (``source``'s), started at ``draws`` points evenly spread over it."""
    out: dict[str, list[float]] = {}
    for name, rec in recs.items():
        span = RecordedEstimateError(source).span_s
        out[name] = []
        for i in range(draws):
            v = simulate(rec, Limits(), estimate=RecordedEstimateError(source, offset_s=i * span / draws))
            out[name].append(float(np.mean(list(rms_by_segment(rec, v, rec.scored_segments()).values()))))
    return out


def nelder_mead(f, x0: np.ndarray, step: np.ndarray, iterations: int = 60) -> tuple[np.ndarray, float]:
    """Minimise ``f`` from ``x0`` (a small Nelder-Mead; no SciPy in the project)."""
    simplex = [x0] + [x0 + np.eye(len(x0))[i] * step[i] for i in range(len(x0))]
    values = [f(x) for x in simplex]
    for it in range(iterations):
        order = np.argsort(values)
        simplex, values = [simplex[i] for i in order], [values[i] for i in order]
        click.echo(f"  fit {it:3d}: {values[0]:.4f} at {np.round(simplex[0], 4).tolist()}", err=True)
        centroid = np.mean(simplex[:-1], axis=0)
        reflected = centroid + (centroid - simplex[-1])
        fr = f(reflected)
        if fr < values[0]:
            expanded = centroid + 2.0 * (centroid - simplex[-1])
            fe = f(expanded)
            simplex[-1], values[-1] = (expanded, fe) if fe < fr else (reflected, fr)
        elif fr < values[-2]:
            simplex[-1], values[-1] = reflected, fr
        else:
            contracted = centroid + 0.5 * (simplex[-1] - centroid)
            fc = f(contracted)
            if fc < values[-1]:
                simplex[-1], values[-1] = contracted, fc
            else:
                simplex = [simplex[0]] + [simplex[0] + 0.5 * (x - simplex[0]) for x in simplex[1:]]
                values = [values[0]] + [f(x) for x in simplex[1:]]
    best = int(np.argmin(values))
    return simplex[best], values[best]


def fit(rec: Recording, start: Airframe) -> tuple[Airframe, float]:
    """Airframe constants minimising the mean RMS against ``rec`` (all must stay positive)."""
    names = [f.name for f in fields(Airframe)]

    def cost(x: np.ndarray) -> float:
        if np.any(x <= 0):
            return 10.0
        return compare(rec, Limits(airframe=Airframe(*x))).mean_rms_m_s

    x0 = np.array([getattr(start, n) for n in names])
    best, value = nelder_mead(cost, x0, 0.2 * x0)
    return Airframe(**dict(zip(names, (float(round(v, 4)) for v in best)))), value


def table(recs: dict[str, Recording], results: dict[str, dict[str, Comparison]], self_rms: dict[str, float]) -> str:
    models = list(results)
    segments = list(self_rms)
    header = f"{'segment':28s}" + "".join(f"{m + '/' + r:>22s}" for m in models for r in RECORDINGS) + f"{'PX4 vs PX4':>12s}"
    lines = [header, "-" * len(header)]
    for seg in segments:
        cells = "".join(f"{results[m][r].rms_m_s[seg]:22.3f}" for m in models for r in RECORDINGS)
        lines.append(f"{seg:28s}{cells}{self_rms[seg]:12.3f}")
    cells = "".join(f"{results[m][r].mean_rms_m_s:22.3f}" for m in models for r in RECORDINGS)
    lines.append(f"{'mean RMS [m/s] (target 0.15)':28s}{cells}{float(np.mean(list(self_rms.values()))):12.3f}")
    for ramp in ("ramp_velocity_only", "ramp_pos_vel_acc"):
        cells = "".join(f"{results[m][r].lag_mock_m[ramp]:10.2f} m ({results[m][r].lag_ratio(ramp):4.2f}x) " for m in models
                        for r in RECORDINGS)
        lines.append(f"{'lag ' + ramp:28s}{cells}")
        px4 = "  ".join(f"{r}: {results[models[0]][r].lag_px4_m[ramp]:.2f} m" for r in RECORDINGS)
        lines.append(f"{'  PX4 lag (its positions)':28s}  {px4}")
        px4 = "  ".join(f"{r}: {ramp_lag_m(recs[r], ramp, recs[r].vel):.2f} m" for r in RECORDINGS)
        lines.append(f"{'  PX4 lag (its velocities)':28s}  {px4}")
    return "\n".join(lines)


def with_estimate_errors(recs: dict[str, Recording], seeds: int) -> dict[str, dict[str, Any]]:
    """Per recording: the mean RMS [m/s] of each seed's replay with PX4 SITL's estimate errors, and
    of the seeds' mean velocity."""
    out: dict[str, dict[str, Any]] = {}
    for name, rec in recs.items():
        draws = [simulate(rec, Limits(), estimate=EstimateError(PX4_SITL_SCALE, seed=seed)) for seed in range(1, seeds + 1)]
        each = [float(np.mean(list(rms_by_segment(rec, v, rec.scored_segments()).values()))) for v in draws]
        mean_v = np.mean(draws, axis=0)
        out[name] = {"per_seed_m_s": each, "of_the_mean_m_s": float(np.mean(list(rms_by_segment(rec, mean_v, rec.scored_segments()).values())))}
    return out


@click.command()
@click.option("--fit", "do_fit", is_flag=True, help="Refit the airframe constants to the original recording.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write the figures as JSON.")
@click.option("--seeds", type=click.IntRange(min=0), default=0, show_default=True,
              help="Also replay with PX4 SITL's estimate errors (the mock as shipped), seeds 1..N.")
@click.option("--px4-error", "px4_error", type=click.IntRange(min=0), default=0, show_default=True,
              help="Also replay original and repeat with the unseen flight's measured velocity error, from N starts.")
def main(do_fit: bool, json_path: Path | None, seeds: int, px4_error: int) -> None:
    """Print the mock-vs-PX4 table (and optionally refit)."""
    recs = load_all()
    airframes = {"mock": FITTED_AIRFRAME}
    if do_fit:
        t0 = time.monotonic()
        fitted, value = fit(recs["original"], FITTED_AIRFRAME)
        click.echo(f"fitted on original in {time.monotonic() - t0:.0f} s: {fitted} (mean RMS {value:.4f}); "
                   f"module constants: {FITTED_AIRFRAME}")
        airframes["refit"] = fitted
    results = {name: {r: compare(recs[r], Limits(airframe=af)) for r in RECORDINGS} for name, af in airframes.items()}
    self_rms = px4_vs_px4_rms(recs["original"], recs["repeat"])
    click.echo(table(recs, results, self_rms))
    unseen = load_unseen()
    payload_unseen: dict[str, Any] = {}
    if unseen is not None:
        exact = compare(unseen, Limits())
        payload_unseen["exact_rms_m_s"] = exact.rms_m_s
        click.echo(f"{UNSEEN} (no fit saw it), exact mock per segment: "
                   + ", ".join(f"{k} {v:.3f}" for k, v in exact.rms_m_s.items()) + f"; mean {exact.mean_rms_m_s:.3f}")
        again = DATA / f"{UNSEEN}_repeat.csv.gz"
        if again.exists():  # the same sequence on another fresh PX4
            rep = load_recording(again)
            self_unseen = float(np.mean(list(px4_vs_px4_rms(unseen, rep).values())))
            payload_unseen["px4_vs_px4_m_s"] = self_unseen
            click.echo(f"{UNSEEN}_repeat: exact mock {compare(rep, Limits()).mean_rms_m_s:.3f}; PX4 against itself "
                       f"{self_unseen:.3f}")
    errs = with_estimate_errors({**recs, **({UNSEEN: unseen} if unseen is not None else {})}, seeds) if seeds else {}
    if px4_error and unseen is not None and unseen.true_vel is not None:
        own = with_px4_error(recs, unseen, px4_error)
        payload_unseen["px4_own_error_m_s"] = own
        for name, each in own.items():
            click.echo(f"{name}: with PX4's own velocity error (the {UNSEEN} flight's, {px4_error} starts), mean RMS "
                       f"{np.mean(each):.3f} ({min(each):.3f}-{max(each):.3f})")
    for name, e in errs.items():
        each = e["per_seed_m_s"]
        click.echo(f"{name}: with PX4 SITL's estimate errors, mean RMS per draw {np.mean(each):.3f} "
                   f"({min(each):.3f}-{max(each):.3f}, {seeds} seeds); of the draws' mean velocity {e['of_the_mean_m_s']:.3f}")
    if json_path is not None:
        payload: dict[str, Any] = {name: {"airframe": asdict(airframes[name]),
                          **{r: {"rms_m_s": c.rms_m_s, "mean_rms_m_s": c.mean_rms_m_s, "lag_mock_m": c.lag_mock_m,
                                 "lag_px4_m": c.lag_px4_m} for r, c in res.items()}} for name, res in results.items()}
        payload["px4_vs_px4_rms_m_s"] = self_rms
        payload["with_estimate_errors"] = errs
        payload[UNSEEN] = payload_unseen
        json_path.write_text(json.dumps(payload, indent=1))


if __name__ == "__main__":
    main()
