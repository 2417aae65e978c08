"""Replay a flight's relative estimator from its logged inputs, as flown or with other tuning, and
judge it against SIH's truth.

``python -m bench.relnav_replay DIR... [--set relnav.KEY=VALUE ...] [--plot FILE]``

DIR is a flight of ``bench.px4_relnav`` (its ``config.toml``, ``pair0/flight.mcap`` with the
``relnav/inputs`` channel, and SIH's ``truth-passenger.csv`` / ``truth-rover.csv``), or any log
directory with a ``flight.mcap`` and ``--config``. The inputs (every own sample, carrier fix,
marker, range and seat the flight's step handed the estimator: mission.flightdata.relnav_inputs)
are fed to a fresh :class:`mission.relnav.estimator.RelativeEstimator` built from the flight's
``[relnav]`` with the ``--set`` overrides. Without overrides the replay must give the flown
estimates to the bit (printed as ``replay check``: the largest difference of the deck's velocity).

Per flight and phase group (``riding``: RIDING; ``approach``: HOLDOFF and APPROACH), against the
truth (the rover's SIH position and velocity minus the quadrotor's, at each estimate's sample time
on the bench's monotonic clock): the relative position's horizontal error [m] (median, 95th
percentile, max), in all and in sight of the marker (the newest fused marker captured at most
``IN_SIGHT_S`` before), the share of estimates out of sight (``blind_share``), the error over the
standard deviation the estimate states (``error_over_sigma``: an honest filter keeps it under about
3 however long it is blind), each marker's horizontal error against the truth at its capture beside the
standard deviation it stated, the deck's velocity error [m/s] (the estimate's carrier velocity against the
rover's true velocity: a frame offset does not move, so they compare directly; and against what
riding must follow, the deck's motion in the passenger's GNSS frame: the rover's true motion plus
the rate of the passenger's own estimate's error, :func:`deck_motion`) and the largest
change of that estimated velocity from one estimate to the next [m/s] (its swing at a fusion);
markers fused and rejected, and resets. The figures are the filter's own; what the phases see
passes through the step's slew and correction limits after it (mission.passenger.relative).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click
import numpy as np

from mission.config.schema import load_config, with_overrides
from mission.flightdata.read import read_messages
from mission.flightdata.relnav_inputs import input_from_message
from mission.flightdata.topics import RELNAV_CHANNELS, topics
from mission.passenger.relative import hand
from mission.record.table import read_record
from mission.relnav.estimator import RelativeEstimator
from mission.relnav.inputs import RelativeEstimate
from sim.sitl import ground_truth

DERIVATIVE_S = 0.2  # [s] the window the deck's true motion is differentiated over
IN_SIGHT_S = 0.3  # [s] an estimate counts as in sight of the marker when its newest fused marker is this young
GROUPS = {"riding": ("RIDING",), "approach": ("HOLDOFF", "APPROACH")}
PAIR_DIR = "pair0"


def _log_dir(directory: Path) -> Path:
    return directory / PAIR_DIR if (directory / PAIR_DIR / "flight.mcap").exists() else directory


def _parse_sets(sets: tuple[str, ...]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for s in sets:
        key, sep, value = s.partition("=")
        if not sep:
            raise click.BadParameter(f"{s!r}: expected KEY=VALUE", param_hint="--set")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def _repeats(inputs: list[tuple[int, dict[str, Any]]]) -> set[int]:
    """The ``seq`` of every carrier fix that repeats the one before it (the same position: a GNSS
    fix sent again or aged again, its velocity perhaps corrected since), handed as new by a flight
    before the step told fixes apart by the carrier's own stamp
    (mission.passenger.relative.RelativeDeck._new_fix)."""
    out, last = set(), None
    for _, m in inputs:
        if m["kind"] == "carrier":
            values = m["position"]
            if values == last:
                out.add(m["seq"])
            last = values
    return out


def replay(directory: Path, config: Path | None, overrides: dict[str, Any], drop_repeats: bool = False) -> dict[str, Any]:
    """The flight in ``directory`` replayed (module docstring): its estimates, the flown ones and
    the mission-clock shift onto the bench's monotonic clock (None without ``clock_offset.json``).
    ``drop_repeats``: leave out the carrier fixes that repeat the one before (:func:`_repeats`)."""
    log_dir = _log_dir(directory)
    cfg_path = config or directory / "config.toml"
    cfg = with_overrides(load_config(cfg_path), overrides) if overrides else load_config(cfg_path)
    content = read_messages(log_dir / "flight.mcap")
    names = topics(cfg.zenoh.pair, RELNAV_CHANNELS)
    inputs = sorted(((t, json.loads(d)) for topic, _, t, d in content.messages if topic == names["relnav_inputs"]),
                    key=lambda x: x[1]["seq"])
    if not inputs:
        raise click.ClickException(f"{log_dir / 'flight.mcap'}: no {names['relnav_inputs']} channel (a flight "
                                   "before the estimator's inputs were logged, or without [relnav])")
    flown_at = [(t, json.loads(d)) for topic, _, t, d in content.messages if topic == names["relnav"]]
    flown = [m for _, m in flown_at]
    # row by row, as the step ran it: the row's inputs handed, then its estimate (a row with no new
    # own sample still catches up on what arrived: RelativeEstimator.estimate)
    est = RelativeEstimator(cfg.relnav.params())
    estimates: list[RelativeEstimate] = []
    skip = _repeats(inputs) if drop_repeats else set()
    k = 0
    for row_t, _ in flown_at:
        while k < len(inputs) and inputs[k][0] <= row_t:
            if inputs[k][1]["seq"] not in skip:
                hand(est, input_from_message(inputs[k][1]))
            k += 1
        estimates.append(est.estimate())
    shift = None
    offset_file = directory / "clock_offset.json"
    if offset_file.exists():
        shift = content.epoch_ns * 1e-9 - json.loads(offset_file.read_text())["unix_minus_monotonic_s"]
    markers = [m for _, m in inputs if m["kind"] == "marker"]
    fixes = [m for _, m in inputs if m["kind"] == "carrier"]
    return {"estimates": estimates, "flown": flown, "record": read_record(log_dir), "shift_s": shift, "cfg": cfg,
            "markers": markers, "fixes": fixes}


def _truth(path: Path) -> np.ndarray | None:
    """Rows t (monotonic: when the bench received it, as the camera node did), x, y, z, vx, vy, vz of
    SIH's truth in ``path``, then the error of the vehicle's own estimate (its PX4's position less
    the truth) x, y, z (None: no file). (A straight-line fit of PX4's own sample times onto the
    monotonic clock put the markers 0.014 m off the truth at the median, against 0.003 m on the
    receipt times: SITL's pace varies under load.)"""
    if not path.exists():
        return None
    c = ground_truth.read_csv(path)
    rows = np.column_stack([c[k] for k in ("t_rx_s", "true_x", "true_y", "true_z", "true_vx", "true_vy", "true_vz")]
                           + [c[k] - c[f"true_{k}"] for k in ("x", "y", "z")])
    return rows[np.isfinite(rows).all(axis=1)]


def deck_motion(rover: np.ndarray, passenger: np.ndarray, t: np.ndarray, window_s: float = DERIVATIVE_S) -> np.ndarray:
    """[m/s] NED at monotonic times ``t``: how the deck truly moves in the passenger's GNSS frame,
    the rate of the rover's true position plus the passenger's own estimate's error (what riding
    must follow: the vehicle flies on its own estimate), as a centred difference over ``window_s``."""
    def where(tt: np.ndarray) -> np.ndarray:
        return _at(rover, tt, range(1, 4)) + _at(passenger, tt, range(7, 10))
    return (where(t + window_s / 2) - where(t - window_s / 2)) / window_s


def _at(series: np.ndarray, t: np.ndarray, cols: range) -> np.ndarray:
    return np.column_stack([np.interp(t, series[:, 0], series[:, k]) for k in cols])


def _stats(v: np.ndarray) -> list[float | None]:
    if not len(v):
        return [None, None, None]
    return [round(float(np.median(v)), 3), round(float(np.percentile(v, 95)), 3), round(float(v.max()), 3)]


def figures(directory: Path, r: dict[str, Any]) -> dict[str, Any]:
    """The replay's figures by phase group (module docstring), and the replay check against the flown estimates."""
    est: list[RelativeEstimate] = r["estimates"]
    t = np.array([e.t_s for e in est])
    vel = np.array([e.carrier_velocity_ned_m_s for e in est])
    rel = np.array([e.position_ned_m for e in est])
    since = np.array([e.since_marker_s for e in est])
    sigma = np.array([e.position_sigma_m for e in est])
    flown = r["flown"]
    check = None
    if len(flown) == len(est):
        fv = np.array([[m["carrier_velocity"][a] for a in "ned"] for m in flown])
        check = float(np.abs(fv - vel).max())
    rec = r["record"]
    i = np.clip(np.searchsorted(rec.t, t, side="right") - 1, 0, len(rec.t) - 1)
    phase = rec.phase[i]
    swing = np.r_[0.0, np.hypot(*np.diff(vel[:, :2], axis=0).T)]
    out: dict[str, Any] = {"flight": directory.name, "estimates": len(est), "replay_check_m_s": check}
    passenger, rover = _truth(directory / "truth-passenger.csv"), _truth(directory / "truth-rover.csv")
    have_truth = passenger is not None and rover is not None and r["shift_s"] is not None and len(passenger) > 1
    passenger = np.zeros((0, 7)) if passenger is None else passenger
    rover = np.zeros((0, 7)) if rover is None else rover
    last = est[-1].counts if est else None
    for name, phases in GROUPS.items():
        sel = np.isin(phase, phases)
        g: dict[str, Any] = {"ticks": int(sel.sum()), "swing_max_m_s": round(float(swing[sel].max()), 3) if sel.any() else None}
        if have_truth and sel.any():
            tm = t[sel] + r["shift_s"]
            true_rel = _at(rover, tm, range(1, 4)) - _at(passenger, tm, range(1, 4))
            true_v = _at(rover, tm, range(4, 7))
            error = np.hypot(*(rel[sel] - true_rel)[:, :2].T)
            g["position_error_m"] = _stats(error)
            in_sight = since[sel] <= IN_SIGHT_S
            g["blind_share"] = round(float(1.0 - in_sight.mean()), 3)
            g["in_sight_position_error_m"] = _stats(error[in_sight])
            g["error_over_sigma"] = _stats(error / sigma[sel])
            g["velocity_error_m_s"] = _stats(np.hypot(*(vel[sel] - true_v)[:, :2].T))
            g["motion_error_m_s"] = _stats(np.hypot(*(vel[sel] - deck_motion(rover, passenger, tm))[:, :2].T))
        out[name] = g
    if have_truth and r["markers"]:
        # each marker against the truth at its capture: how far the measurement errs, and what it said of itself
        mt = np.array([m["t_s"] for m in r["markers"]])
        z = np.array([m["offset"] for m in r["markers"]])
        sigma = np.sqrt(np.array([max(np.linalg.eigvalsh(np.reshape(m["covariance"], (3, 3)))) for m in r["markers"]]))
        true_rel = _at(rover, mt + r["shift_s"], range(1, 4)) - _at(passenger, mt + r["shift_s"], range(1, 4))
        out["marker_error_m"] = _stats(np.hypot(*(z - true_rel)[:, :2].T))
        out["marker_sigma_m"] = _stats(sigma)
    if have_truth and r["fixes"]:
        # the carrier's published velocity against the rover's truth at the fix's time: the noise the
        # estimator's relnav.gnss_velocity_sigma_m_s stands for (per horizontal axis, RMS and 99th percentile)
        ft = np.array([m["t_s"] for m in r["fixes"]]) + r["shift_s"]
        inside = (ft > rover[0, 0]) & (ft < rover[-1, 0])
        dv = np.array([m["velocity"] for m in r["fixes"]])[inside] - _at(rover, ft[inside], range(4, 7))
        out["fix_velocity_error_m_s"] = [round(float(np.sqrt(np.mean(dv[:, :2] ** 2))), 3),
                                         round(float(np.percentile(np.abs(dv[:, :2]), 99)), 3)]
    if last is not None:
        out["counts"] = {"markers_fused": last.fused["marker"], "markers_rejected": last.rejected["marker"],
                         "resets": last.resets}
    out["_series"] = (t, vel, phase, swing)
    return out


def plot(path: Path, rows: list[tuple[Path, tuple[dict[str, Any], dict[str, Any]]]]) -> None:
    """The deck's estimated horizontal velocity (and SIH's truth) over each flight, one panel a flight."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(rows), 1, figsize=(11, 3.2 * len(rows)), squeeze=False)
    for ax, (directory, (r, f)) in zip(axes[:, 0], rows):
        t, vel, phase, _ = f["_series"]
        ax.plot(t, vel[:, 0], lw=0.8, label="estimate north")
        ax.plot(t, vel[:, 1], lw=0.8, label="estimate east")
        rover = _truth(directory / "truth-rover.csv")
        if rover is not None and r["shift_s"] is not None:
            tt = rover[:, 0] - r["shift_s"]
            ax.plot(tt, rover[:, 4], "k--", lw=0.6, label="SIH north")
            ax.plot(tt, rover[:, 5], "k:", lw=0.6, label="SIH east")
        riding = np.isin(phase, GROUPS["riding"])
        ax.fill_between(t, -3, 3, where=riding, color="tab:green", alpha=0.08, label="riding")
        ax.set_xlim(t[0], t[-1])
        ax.set_ylim(-2.5, 2.5)
        ax.set_ylabel("deck velocity [m/s]")
        ax.set_title(f"{directory.name}: the relative estimator's deck velocity, replayed")
        ax.legend(loc="upper right", fontsize=7, ncol=5)
    axes[-1, 0].set_xlabel("mission clock [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


@click.command(help=__doc__.split("\n\n")[0] + "\n\nDIR: a bench.px4_relnav flight directory (or a log "
               "directory with --config). See the module's docstring for the figures.")
@click.argument("dirs", nargs=-1, required=True, type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--config", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="The flight's configuration (default: DIR/config.toml).")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE",
              help="Override a setting for the replay (e.g. relnav.accel_noise_m_s2=0.5); repeatable.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Draw the deck's velocity, replayed and true, to this PNG.")
@click.option("--json", "as_json", is_flag=True, help="One JSON line a flight instead of the table.")
@click.option("--drop-repeats", is_flag=True,
              help="Leave out carrier fixes that repeat the one before (a GNSS fix sent or aged again; flights before the "
                   "step told fixes apart by the carrier's own stamp handed them as new).")
def main(dirs: tuple[Path, ...], config: Path | None, sets: tuple[str, ...], plot_path: Path | None, as_json: bool,
         drop_repeats: bool) -> None:
    overrides = _parse_sets(sets)
    rows = []
    header = ("flight | group | ticks | position error med/p95/max [m] | out of sight [share] | in sight: "
              "position error med/p95/max [m] | error over its stated sigma med/p95/max | deck velocity error med/p95/max [m/s] | "
              "against its motion in the passenger's frame [m/s] | "
              "largest swing [m/s] | markers fused/rejected, resets | replay check [m/s]")
    if not as_json:
        click.echo(f"replaying {len(dirs)} flight(s) with {overrides or 'the flown tuning'}")
        click.echo(header)
    for k, directory in enumerate(dirs, 1):
        r = replay(directory, config, overrides, drop_repeats)
        f = figures(directory, r)
        rows.append((directory, (r, f)))
        if as_json:
            click.echo(json.dumps({k: v for k, v in f.items() if not k.startswith("_")}))
            continue
        c = f.get("counts", {})
        for name in GROUPS:
            g = f[name]
            click.echo(f"{f['flight']} | {name} | {g['ticks']} | {g.get('position_error_m')} | {g.get('blind_share')} | "
                       f"{g.get('in_sight_position_error_m')} | {g.get('error_over_sigma')} | {g.get('velocity_error_m_s')} | "
                       f"{g.get('motion_error_m_s')} | "
                       f"{g['swing_max_m_s']} | {c.get('markers_fused')}/{c.get('markers_rejected')}, {c.get('resets')} | "
                       f"{f['replay_check_m_s'] if not (overrides or drop_repeats) else '-'}   [{k}/{len(dirs)}]")
        if "marker_error_m" in f:
            click.echo(f"{f['flight']} | markers against the truth: horizontal error med/p95/max {f['marker_error_m']} m, "
                       f"their stated sigma {f['marker_sigma_m']} m")
        if "fix_velocity_error_m_s" in f:
            click.echo(f"{f['flight']} | the carrier's published velocity against the truth, per horizontal axis: "
                       f"RMS / p99 {f['fix_velocity_error_m_s']} m/s (relnav.gnss_velocity_sigma_m_s "
                       f"{r['cfg'].relnav.gnss_velocity_sigma_m_s:g})")
    if plot_path is not None:
        plot(plot_path, rows)
        click.echo(f"plot: {plot_path}")


if __name__ == "__main__":
    main()
