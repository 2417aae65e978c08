"""Missions of a ``[relnav]`` configuration flown in-process (:class:`sim.batch.recovery.World`) and
held against the world's truth: what the phases did, the true contact error and riding offset, the
estimate's error at contact, the time with the marker in view, P1-P3 and the largest command jump
at a phase switch.

    PYTHONPATH=. python -m bench.relnav_flight configs/relnav.toml [--no-marker] [--rendered]
        [--seeds 0 1 2] [--set recovery.holdoff_distance_m=2.0 ...] [--quiet]

A seed ``k`` draws the carrier's and the passenger's GNSS errors and the marker's stream anew
(``world.carrier_gnss.seed`` and ``world.passenger_gnss.seed`` moved on by ``k``, the scenario's
seed ``k``); seed 0 is the configuration as written.
"""
from __future__ import annotations

import argparse
import json
import time
from mission.config.schema import Config, load_config, with_overrides
from sim.batch.recovery import World, configured
from sim.batch.truth import relnav_truth

SHOWN = ("approach", "go-around", "contact", "fallback", "docked", "separat", "leg", "abort", "holdoff", "returning",
         "marker", "search")


def seeded(cfg: Config, seed: int) -> Config:
    """``cfg`` with its world's GNSS errors drawn from seed ``seed`` (0: as written)."""
    if seed == 0:
        return cfg
    w = cfg.world
    return with_overrides(cfg, {"world.carrier_gnss.seed": w.carrier_gnss.seed + 1000 * seed,
                                "world.passenger_gnss.seed": w.passenger_gnss.seed + 1000 * seed})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config")
    ap.add_argument("--no-marker", action="store_true", help="fly with no measurement feed (the camera off)")
    ap.add_argument("--rendered", action="store_true", help="the marker rendered and detected (marker_rendered)")
    ap.add_argument("--seeds", type=int, nargs="*", default=[0])
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=JSON", help="configuration overrides")
    ap.add_argument("--quiet", action="store_true", help="no event list, one JSON line a seed")
    args = ap.parse_args()
    cfg = load_config(args.config)
    overrides = {k: json.loads(v) for k, v in (item.split("=", 1) for item in args.set)}
    if args.no_marker:
        overrides["mission.feeds"] = []
    elif args.rendered:
        overrides["mission.feeds"] = ["marker_rendered"]
    cfg = with_overrides(cfg, overrides) if overrides else cfg
    for seed in args.seeds:
        flown = seeded(cfg, seed)
        t0 = time.process_time()
        w = World(flown, configured(seed=seed)).run()
        f = w.flight()
        out = {"seed": seed, "cpu_s": round(time.process_time() - t0, 1), **relnav_truth(flown, f)}
        if not args.quiet:
            for t, e in f.events:
                if any(k in e for k in SHOWN):
                    print(f"{t:7.2f} {e}")
        print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
