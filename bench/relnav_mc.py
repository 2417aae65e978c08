"""A Monte-Carlo of a ``[relnav]`` configuration flown in-process, held against the world's truth
(:func:`sim.batch.truth.relnav_truth`). Each scenario draws, seeded:

- the carrier's and the passenger's GNSS biases: each one's mean horizontal size uniform in
  0-3 m (its Gauss-Markov sigma per axis that size / 1.2533), independent seeds;
- the carrier's speed on its recovery course, uniform in 0-2 m/s;
- marker outages 10 % of the time, in spells of 0.3-1 s (``world.marker_outages``);
- the camera's latency, uniform in 50-150 ms;

and the passenger's own estimate errs as PX4 SITL's does (``--estimate-error``, a multiple of
PX4 SITL's errors as the demo's mock vehicle flies them; 0: exact, an upper bound).

    PYTHONPATH=. python -m bench.relnav_mc configs/relnav.toml [--scenarios 20] [--seed 0] [--estimate-error 1]
        [--first 0] [--only 3 18 ...] [--jsonl out.jsonl]

``--first K`` flies scenarios K .. ``--scenarios``-1 and ``--only`` just the ones named: each
scenario draws the same as in the whole batch (the draws before it are made and thrown away), so
a batch split in ranges over several processes, or one scenario flown again, flies the same.

Prints one JSON line a scenario, then the batch against the targets: docked within two
approaches (every leg), the true contact error's median and 95th percentile, deck touches outside
the contact conditions, the median over the flights of the last 0.3 m's true sideways speed's p95, and how every flight that did not dock ended.
"""
from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np

from mission.config.schema import Config, load_config, with_overrides
from sim.batch.recovery import World, configured
from sim.batch.truth import relnav_truth
from sim.vehicle.options import VehicleOptions

RAYLEIGH_MEAN = 1.2533  # the mean size of a 2D Gaussian vector over its sigma per axis


def draw(cfg: Config, rng: np.random.Generator, k: int) -> tuple[dict[str, Any], Config]:
    """Scenario ``k``: what it drew and its configuration."""
    drawn = {"carrier_bias_m": float(rng.uniform(0, 3)), "passenger_bias_m": float(rng.uniform(0, 3)),
             "carrier_speed_m_s": float(rng.uniform(0, 2)), "latency_s": float(rng.uniform(0.05, 0.15))}
    flown = with_overrides(cfg, {
        "world.carrier_gnss.bias_sigma_m": drawn["carrier_bias_m"] / RAYLEIGH_MEAN,
        "world.carrier_gnss.seed": 10_000 + k, "world.passenger_gnss.seed": 20_000 + k,
        "world.passenger_gnss.bias_sigma_m": drawn["passenger_bias_m"] / RAYLEIGH_MEAN,
        "carrier.recovery_speed_m_s": drawn["carrier_speed_m_s"], "vision.latency_s": drawn["latency_s"],
        "world.marker_outages.fraction": 0.1, "world.marker_outages.min_s": 0.3, "world.marker_outages.max_s": 1.0})
    return {k2: round(v, 3) for k2, v in drawn.items()}, flown


def _median(values: list[float | None]) -> float | None:
    """The median of the values given (None: none given)."""
    given = [v for v in values if v is not None]
    return round(float(np.median(given)), 4) if given else None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config")
    ap.add_argument("--scenarios", type=int, default=20, help="scenarios drawn: 0 .. N-1 (the range's end with --first)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--estimate-error", type=float, default=VehicleOptions.estimate_error,
                    help="the vehicle's estimate errors, a multiple of PX4 SITL's (0: exact); default: the demo's")
    ap.add_argument("--first", type=int, default=0, help="the first scenario flown (a range: --first K --scenarios N)")
    ap.add_argument("--only", type=int, nargs="+", help="fly only these scenarios (their draws as in the batch)")
    ap.add_argument("--jsonl", help="also write each scenario's line here")
    args = ap.parse_args()
    if not args.only and args.first >= args.scenarios:
        ap.error(f"--first {args.first} flies nothing: scenarios {args.first} .. {args.scenarios - 1} "
                 "(--scenarios is the range's end, not its length)")
    cfg = load_config(args.config)
    rng = np.random.default_rng(args.seed)
    rows = []
    out = open(args.jsonl, "w") if args.jsonl else None
    last = max(args.only) + 1 if args.only else args.scenarios
    for k in range(last):
        drawn, flown = draw(cfg, rng, k)
        if k < args.first or (args.only and k not in args.only):
            continue
        t0 = time.process_time()
        f = World(flown, configured(estimate_error=args.estimate_error, seed=args.seed * 1000 + k)).run().flight()
        row = {"scenario": k, **drawn, "cpu_s": round(time.process_time() - t0, 1), **relnav_truth(flown, f)}
        rows.append(row)
        line = json.dumps(row)
        print(line, flush=True)
        if out is not None:
            out.write(line + "\n")
            out.flush()
    contacts = [leg["contact_horizontal_m"] for r in rows for leg in r["legs"] if "contact_horizontal_m" in leg]
    within2 = [r["docked"] and all(leg.get("attempts", 9) <= 2 for leg in r["legs"]) for r in rows]
    not_docked = [{"scenario": r["scenario"], "phase": r["phase"], "reason": r["reason"], "fallback": r["fallback"]}
                  for r in rows if not r["docked"]]
    print(json.dumps({
        "scenarios": len(rows), "docked_within_2_approaches_pct": round(100.0 * float(np.mean(within2)), 1),
        "docked_first_approach_pct": round(100.0 * float(np.mean(
            [r["docked"] and all(leg.get("attempts", 9) == 1 for leg in r["legs"]) for r in rows])), 1),
        "true_contact_median_m": round(float(np.median(contacts)), 4) if contacts else None,
        "true_contact_p95_m": round(float(np.percentile(contacts, 95)), 4) if contacts else None,
        "true_contact_max_m": round(float(np.max(contacts)), 4) if contacts else None,
        "true_deck_touches": sum(r["true_deck_touches"] for r in rows),
        # the last decimetres' true sideways speed against the deck: a figure of every descent (the touches are rare)
        "low_horizontal_speed_p95_median_m_s": _median([r["low_horizontal_speed_m_s"]["p95"] for r in rows]),
        "flights_with_deck_touches": sum(1 for r in rows if r["true_deck_touches"]),
        "p1_failed": [r["scenario"] for r in rows if not r["p1"]],
        "p1_p3_all": all(r["p1"] and r["p2"] and r["p3"] for r in rows),
        "max_phase_switch_jump_m_s": max((r["max_phase_switch_jump_m_s"] or 0.0) for r in rows),
        "riding_horizontal_median_m": round(float(np.median([r["riding_horizontal_median_m"] for r in rows
                                                             if r["riding_horizontal_median_m"] is not None])), 3),
        "estimate_error": args.estimate_error, "not_docked": not_docked, "cpu_s": round(sum(r["cpu_s"] for r in rows), 1)}))
    if out is not None:
        out.close()


if __name__ == "__main__":
    main()
