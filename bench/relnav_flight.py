"""One mission of a ``[relnav]`` configuration flown in-process (:class:`sim.batch.recovery.World`) and
held against the world's truth: what the phases did, the true contact error and riding offset, the
estimate's error at contact, the time with the marker in view.

    PYTHONPATH=. python -m bench.relnav_flight configs/relnav.toml [--no-marker]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from mission.config.schema import load_config
from mission.record import VEC
from sim.batch.recovery import World, configured

SHOWN = ("approach", "go-around", "contact", "fallback", "docked", "separat", "leg", "abort", "holdoff", "returning")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config")
    ap.add_argument("--no-marker", action="store_true", help="fly with no measurement feed (the camera off)")
    args = ap.parse_args()
    cfg = load_config(args.config)
    if args.no_marker:
        cfg = cfg.model_copy(update={"mission": cfg.mission.model_copy(update={"feeds": []})})
    t0 = time.process_time()
    w = World(cfg, configured()).run()
    f = w.flight()
    print(f"CPU {time.process_time() - t0:.1f} s; ended in {f.summary.get('phase')} {f.summary.get('reason')} "
          f"{f.summary.get('detail')}")
    for t, e in f.events:
        if any(k in e for k in SHOWN):
            print(f"{t:7.2f} {e}")
    cols, t_s, phase = f.record.cols, f.record.t, f.record.phase

    def vec(name: str) -> np.ndarray:
        return np.stack([cols[f"{name}_{a}"] for a in VEC], axis=1)

    off = vec("x_true") - (vec("x_c_true") + np.asarray(cfg.mission.dock_offset_ned_m))
    est_err = np.linalg.norm(vec("rel_est") - vec("rel_true"), axis=1)
    for leg in f.state.legs_done:
        c = leg.get("contact")
        print(f"leg {leg['leg']}: {leg['outcome']}")
        if c:
            k = int(np.argmin(abs(t_s - c["time_s"])))
            print(f"  true contact error: horizontal {np.linalg.norm(off[k, :2]):.3f} m, vertical {off[k, 2]:+.3f} m; "
                  f"estimate error {est_err[k]:.3f} m; attempts {c['attempts']}")
    riding = phase == "RIDING"
    if riding.any():
        print(f"true riding offset: max {np.max(np.linalg.norm(off[riding], axis=1)):.3f} m, "
              f"median {np.median(np.linalg.norm(off[riding], axis=1)):.3f} m")
    seen = vec("since_marker")[:, 0] <= cfg.relnav.marker_timeout_s
    print(f"marker in view {seen.sum() * w.dt_s:.1f} s of {t_s[-1]:.1f} s")


if __name__ == "__main__":
    main()
