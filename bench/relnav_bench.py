"""The relative estimator's numbers for docs/relnav.md: the bias carried and removed, replay
equality, the gate, NEES over a seeded Monte-Carlo, the world's GNSS statistics, and the CPU
cost per tick. Seeded: the same numbers every run (the CPU time excepted).

Usage: ``python -m bench.relnav_bench [--runs 50]``.
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

from mission.config.relnav import CarrierGnssSection, PassengerGnssSection, RelnavSection
from mission.relnav.estimator import RelativeEstimator
from mission.relnav.inputs import CarrierFix, MarkerFix, OwnSample
from sim.gnss import CarrierGnss
from sim.testing.relnav_world import NEES_CHECKPOINTS_S, average_nees, fly, make_world
from sim.vehicle.estimator import BiasedEstimateError

PARAMS = RelnavSection().params()
BIAS = (2.0, 0.0, 0.0)


def _err(est, world, since_s):  # type: ignore[no-untyped-def]
    return np.array([e.position_ned_m - x[:3] for e, x in zip(est, world.truth) if e.t_s >= since_s])


def bias_runs() -> None:
    w = make_world(PARAMS, seed=1, constant_bias_m=BIAS, truth_accel_m_s2=0.1)
    est = fly(RelativeEstimator(PARAMS), w)
    late = [e for e in est if e.t_s >= 20.0]
    print(f"GNSS alone (2 m north bias, t >= 20 s): mean error {_err(est, w, 20.0).mean(axis=0).round(3)} m, "
          f"bias guess {np.mean([e.bias_ned_m for e in late], axis=0).round(3)} m, sigma {est[-1].position_sigma_m:.2f} m")
    w = make_world(PARAMS, seed=2, constant_bias_m=BIAS, marker_from_s=10.0, truth_accel_m_s2=0.1)
    est = fly(RelativeEstimator(PARAMS), w)
    e = _err(est, w, 20.0)
    first = next(x.t_s for x in est if x.converged)
    print(f"with markers from 10 s (3 cm, 10 Hz, 50-150 ms late), t >= 20 s: mean error {e.mean(axis=0).round(3)} m, "
          f"RMS per axis {np.sqrt((e ** 2).mean(axis=0)).round(3)} m, bias {est[-1].bias_ned_m.round(3)} m "
          f"(sigma {np.sqrt(np.diag(est[-1].covariance)[6:]).round(3)}), converged from {first:.2f} s, "
          f"counts {est[-1].counts}")


def replay() -> None:
    kw = dict(seed=3, constant_bias_m=BIAS, marker_from_s=2.0, duration_s=10.0, measure_until_s=9.0)
    a = fly(RelativeEstimator(PARAMS), make_world(PARAMS, marker_delay_s=(0.0, 0.0), gnss_delay_s=(0.0, 0.0), **kw))[-1]
    b = fly(RelativeEstimator(PARAMS), make_world(PARAMS, **kw))[-1]
    print(f"replay: late and out-of-order vs on time: max |position difference| "
          f"{np.abs(a.position_ned_m - b.position_ned_m).max():.2e} m, covariance {np.abs(a.covariance - b.covariance).max():.2e}")


def nees(runs: int) -> None:
    n9, n3 = average_nees(PARAMS, runs)
    print(f"NEES over {runs} runs at t = {NEES_CHECKPOINTS_S} s: whole state (expect 9) {n9.round(2)}, "
          f"position (expect 3) {n3.round(2)}")


def cost() -> None:
    """CPU per tick at 50 Hz with GNSS at 10 Hz 200 ms late and markers at 30 Hz 100 ms late."""
    rng = np.random.default_rng(0)
    est = RelativeEstimator(PARAMS)
    pending: list[tuple[float, object]] = []
    n = 3000
    t0 = time.process_time()
    for k in range(1, n + 1):
        t = k * 0.02
        pc, pp = np.array([10.0 + t, 5.0, 0.0]), np.array([t, 0.0, 0.0])
        if k % 5 == 0:
            pending.append((t + 0.2, CarrierFix(t, pc + BIAS + rng.normal(0, 0.3, 3), np.array([1.0, 0, 0]))))
        if k % 2 == 0:
            pending.append((t + 0.1, MarkerFix.isotropic(t, pc - pp + rng.normal(0, 0.03, 3), 0.03)))
        for _, m in [p for p in pending if p[0] <= t]:
            est.carrier(m) if isinstance(m, CarrierFix) else est.marker(m)  # type: ignore[arg-type]
        pending = [p for p in pending if p[0] > t]
        est.tick(OwnSample(t, pp, np.array([1.0, 0, 0])))
    print(f"cost: {1e3 * (time.process_time() - t0) / n:.3f} ms CPU per 50 Hz tick (GNSS 10 Hz 200 ms late, "
          "markers 25 Hz 100 ms late, each replayed)")


def gnss_stats() -> None:
    cfg = CarrierGnssSection(enabled=True, bias_sigma_m=1.5, bias_tau_s=40.0, position_sigma_m=0.0, rate_hz=1.0,
                             latency_s=0.0, jitter_s=0.0, seed=7)
    g = CarrierGnss(cfg)
    err = np.array([f.error_ned_m for k in range(8000) for f in g.observe(float(k), np.zeros(3), np.zeros(3))])
    x = err[:, 0] - err[:, 0].mean()
    rho = float((x[:-40] * x[40:]).mean() / (x * x).mean())
    print(f"carrier GNSS bias (1.5 m, 40 s asked): sigma N/E/D {err.std(axis=0).round(3)} m, "
          f"autocorrelation at 40 s {rho:.3f} (1/e = {math.exp(-1):.3f})")


def sim_world(seed: int = 0) -> None:
    """Against the simulators' world rather than the filter's model: the carrier's standalone GNSS
    (defaults: 1.5 m / 300 s bias, 0.3 m, 10 Hz, 0.2 +- 0.05 s), the passenger's own estimate with
    PX4 SITL's errors and a 1.5 m / 300 s GNSS bias, markers of 3 cm at 15 Hz 50-150 ms late
    from 20 s; the carrier at 1 m/s north, the passenger 3 m above and 2 m behind it; 60 s at 50 Hz."""
    gnss = CarrierGnss(CarrierGnssSection(enabled=True, seed=seed))
    own_err = BiasedEstimateError(1.0, PassengerGnssSection(bias_sigma_m=1.5, seed=seed + 1), seed=seed)
    rng = np.random.default_rng(seed + 2)
    est = RelativeEstimator(PARAMS)
    pending: list[tuple[float, object]] = []
    errs = []
    dt = 0.02
    for k in range(1, 3001):
        t = k * dt
        v = np.array([1.0, 0.0, 0.0])
        carrier = np.array([t, 0.0, 0.0])
        vehicle = carrier + [-2.0, 0.0, -3.0]
        for f in gnss.observe(t, carrier, v):
            est.carrier(CarrierFix(f.t_s, f.position_ned_m, f.velocity_ned_m_s))
        for _ in range(5):
            own_err.advance(dt / 5)
        if t >= 20.0 and k % 3 == 0:
            pending.append((t + rng.uniform(0.05, 0.15),
                            MarkerFix.isotropic(t, carrier - vehicle + rng.normal(0, 0.03, 3), 0.03)))
        for _, m in [p for p in pending if p[0] <= t]:
            est.marker(m)  # type: ignore[arg-type]
        pending = [p for p in pending if p[0] > t]
        e = est.tick(OwnSample(t, vehicle + np.array(own_err.position), v + np.array(own_err.velocity)))
        errs.append(e.position_ned_m - (carrier - vehicle))
    err = np.array(errs)
    before, after = err[500:1000], err[2000:]
    print(f"simulators' world, seed {seed}: GNSS alone (10-20 s) mean error {before.mean(axis=0).round(2)} m; "
          f"with markers (40-60 s) mean {after.mean(axis=0).round(3)} m, RMS per axis "
          f"{np.sqrt((after ** 2).mean(axis=0)).round(3)} m, max {np.abs(after).max():.3f} m; counts {e.counts}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--runs", type=int, default=50)
    args = ap.parse_args()
    bias_runs()
    replay()
    nees(args.runs)
    gnss_stats()
    cost()
    for seed in range(3):
        sim_world(seed)


if __name__ == "__main__":
    main()
