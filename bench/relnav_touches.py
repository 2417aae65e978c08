"""The deck touches of ``bench.relnav_mc`` scenarios, each episode (a run of touch ticks) put to
a cause from the record against the world's truth (:func:`sim.batch.truth.relnav_truth` counts
the ticks):

- ``blind``: the marker's newest fused capture older than ``relnav.descent_marker_timeout_s`` at
  some tick of the episode or of the half second before it (the relative height drifting with
  the vehicle's own height estimate);
- with the marker in sight, which contact condition the truth broke: ``out_of_radius`` (any tick
  beyond ``recovery.contact_radius_m``), else ``vertical_speed`` (any tick over
  ``contact_max_vertical_speed_m_s``), else ``horizontal_speed``.

    PYTHONPATH=. python -m bench.relnav_touches configs/relnav.toml 24 35 99 [--jsonl out.jsonl]

Prints one JSON line a scenario (the figures of ``bench.relnav_mc`` and its ``touch_episodes``:
start [s], ticks, cause, the marker's largest age [s]), then the ticks and flights per cause.
"""
from __future__ import annotations

import argparse
import json
import time
from collections import Counter, defaultdict
from typing import Any

import numpy as np

from bench.relnav_mc import draw
from mission.config.schema import Config, load_config
from sim.batch.recovery import Flight, World, configured
from sim.batch.truth import BEFORE_CONTACT, _vec, relnav_truth
from sim.vehicle.options import VehicleOptions

BEFORE_S = 0.5  # [s] the marker's age is looked at this long before an episode too


def touch_episodes(cfg: Config, f: Flight) -> list[dict[str, Any]]:
    """The flight's touch episodes (the ticks ``relnav_truth`` counts, in runs), each with its
    cause (module docstring)."""
    t, phase, r = f.record.t, f.record.phase, cfg.recovery
    dock = _vec(f, "x_c_true") + np.asarray(cfg.mission.dock_offset_ned_m, float)
    x = _vec(f, "x_true")
    off = x - dock
    dv = np.gradient(x, t, axis=0) - np.gradient(dock, t, axis=0)
    h, hs = np.hypot(off[:, 0], off[:, 1]), np.hypot(dv[:, 0], dv[:, 1])
    far, fast_h = h > r.contact_radius_m, hs > r.contact_max_horizontal_speed_m_s
    fast_v = np.abs(dv[:, 2]) > r.contact_max_vertical_speed_m_s
    band = np.isin(phase, [p.value for p in BEFORE_CONTACT]) & (off[:, 2] >= -r.contact_height_m) & (h <= r.deck_radius_m)
    idx = np.flatnonzero(band & (far | fast_h | fast_v))
    age = _vec(f, "since_marker")[:, 0]
    before = int(round(BEFORE_S / (t[1] - t[0]))) if len(t) > 1 else 0
    out = []
    for run in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if idx.size else []:
        oldest = float(np.nanmax(age[max(0, run[0] - before):run[-1] + 1]))
        cause = ("blind" if oldest > cfg.relnav.descent_marker_timeout_s else "out_of_radius" if far[run].any()
                 else "vertical_speed" if fast_v[run].any() else "horizontal_speed")
        out.append({"t_s": round(float(t[run[0]]), 2), "ticks": int(run.size), "cause": cause,
                    "marker_age_max_s": round(oldest, 2)})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config")
    ap.add_argument("scenarios", type=int, nargs="+")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--estimate-error", type=float, default=VehicleOptions.estimate_error)
    ap.add_argument("--jsonl", help="also write each scenario's line here")
    args = ap.parse_args()
    cfg = load_config(args.config)
    rng = np.random.default_rng(args.seed)
    out = open(args.jsonl, "w") if args.jsonl else None
    ticks: Counter[str] = Counter()
    flights: defaultdict[str, set[int]] = defaultdict(set)
    for k in range(max(args.scenarios) + 1):
        drawn, flown = draw(cfg, rng, k)
        if k not in args.scenarios:
            continue
        t0 = time.process_time()
        f = World(flown, configured(estimate_error=args.estimate_error, seed=args.seed * 1000 + k)).run().flight()
        row = {"scenario": k, **drawn, "cpu_s": round(time.process_time() - t0, 1), **relnav_truth(flown, f),
               "touch_episodes": touch_episodes(flown, f)}
        for e in row["touch_episodes"]:
            ticks[e["cause"]] += e["ticks"]
            flights[e["cause"]].add(k)
        line = json.dumps(row)
        print(line, flush=True)
        if out is not None:
            out.write(line + "\n")
            out.flush()
    print(json.dumps({"scenarios": len(args.scenarios), "touch_ticks": dict(ticks),
                      "touch_flights": {c: len(s) for c, s in flights.items()}}))
    if out is not None:
        out.close()


if __name__ == "__main__":
    main()
