"""The relative estimator with a downward rangefinder (:meth:`RelativeEstimator.range`): over the
deck the range plus the vehicle's own height is the deck's height in the passenger's frame, so a
marker loss while the passenger's own height estimate drifts (0.3 m/s, as PX4 SITL's does near the
deck: tests/unit/relnav/test_own_drift.py) leaves the relative height right; off the deck (by the
estimate) a range is not fused; an outlier is gated; late ranges replay to the in-order result."""
from __future__ import annotations

import numpy as np

from mission.config.schema import load_config
from mission.relnav.estimator import RelativeEstimator
from mission.relnav.inputs import CarrierFix, MarkerFix, OwnSample, RangeFix
from tests.conftest import CONFIGS

DT = 0.02  # [s] the passenger's tick
DRIFT_FROM = 3.0  # [s] the own height estimate starts drifting
DRIFT = -0.3  # [m/s] NED down: the estimate rising over the truth (the vehicle, flying it, sinks)
LOSS = (6.0, 6.8)  # [s] no marker captured in this spell
RANGE_SIGMA = 0.03  # [m]
SEAT = np.zeros(3)  # [m] the deck's top and centre from the carrier's reference point (configs/relnav.toml's hover ride)
RADIUS = 0.5  # [m] recovery.deck_radius_m
ABOVE = np.array([0.0, 0.0, -0.4])  # [m] the vehicle over the deck
PARAMS = load_config(CONFIGS / "relnav.toml").relnav.params()


def _arrivals(seed: int, ranges: bool, above: np.ndarray = ABOVE) -> list[tuple[float, object]]:
    """What the estimator is handed, (arrival [s], measurement), in arrival order: the carrier's
    GNSS at 10 Hz 0.2 s late, the marker at ~17 Hz 0.1 s late but for ``LOSS``, the ranges (with
    ``ranges``) at 25 Hz 0.04 s late; the carrier drives north at 1.5 m/s, the vehicle rides
    ``above`` it, the GNSS frames ``(2, -1, 0.3)`` m apart."""
    rng, ranged = np.random.default_rng(seed), np.random.default_rng(seed + 100)  # the ranges' own noise stream
    bias, v = np.array([2.0, -1.0, 0.3]), np.array([1.5, 0.0, 0.0])
    out: list[tuple[float, object]] = []
    for k in range(int(LOSS[1] / DT) + 1):
        t = k * DT
        x = v * t
        if k % 5 == 0:
            out.append((t + 0.2, CarrierFix(t, x + bias + rng.normal(0, 0.3, 3), v + rng.normal(0, 0.2, 3))))
        if k % 3 == 0 and not LOSS[0] <= t <= LOSS[1]:
            out.append((t + 0.1, MarkerFix.isotropic(t, -above + rng.normal(0, 0.03, 3), 0.03)))
        if ranges and k % 2 == 0:  # the true height over the deck, measured
            out.append((t + 0.04, RangeFix(t, -above[2] + ranged.normal(0, RANGE_SIGMA), RANGE_SIGMA, SEAT, RADIUS)))
    return sorted(out, key=lambda a: a[0])


def _fly(arrivals: list[tuple[float, object]], above: np.ndarray = ABOVE, params=PARAMS):
    """The estimator handed ``arrivals`` as they arrive, ticked by the vehicle's own estimate (its
    height drifting from ``DRIFT_FROM``); the last estimate."""
    est = RelativeEstimator(params)
    v = np.array([1.5, 0.0, 0.0])
    i, e = 0, None
    for k in range(int(LOSS[1] / DT) + 1):
        t = k * DT
        while i < len(arrivals) and arrivals[i][0] <= t + 1e-9:
            m = arrivals[i][1]
            if isinstance(m, CarrierFix):
                est.carrier(m)
            elif isinstance(m, RangeFix):
                est.range(m)
            else:
                est.marker(m)  # type: ignore[arg-type]
            i += 1
        own_error = np.array([0.0, 0.0, DRIFT * max(0.0, t - DRIFT_FROM)])
        own_v = v + np.array([0.0, 0.0, DRIFT if t >= DRIFT_FROM else 0.0])
        e = est.tick(OwnSample(t, v * t + above + own_error, own_v))
    assert e is not None
    return e


def _height_error(seed: int, ranges: bool) -> float:
    """The relative height's error [m] at the end of the marker loss (the estimate less the truth)."""
    return float(np.asarray(_fly(_arrivals(seed, ranges)).position_ned_m)[2] - (-ABOVE[2]))


def test_the_range_keeps_the_relative_height_through_a_marker_loss():
    """0.8 s without the marker while the own height estimate drifts at 0.3 m/s (0.24 m): mean
    over six seeds of the relative height's error at its end, at most 0.03 m with the ranges
    (measured: 0.015 m), where configs/relnav.toml's filter without them is off by 0.2 m or more
    (measured: 0.23 m)."""
    seeds = range(6)
    kept = float(np.mean([abs(_height_error(s, ranges=True)) for s in seeds]))
    lost = float(np.mean([abs(_height_error(s, ranges=False)) for s in seeds]))
    assert kept <= 0.03, (kept, lost)
    assert lost >= 0.2, lost


def test_ranges_off_the_deck_are_not_fused():
    """The vehicle 2 m beside the deck (radius 0.5 m): its ranges measure the ground, none is
    fused, each is counted ``off_deck``, and the relative height drifts as without them."""
    beside = np.array([2.0, 0.0, -0.4])
    e = _fly(_arrivals(0, ranges=True, above=beside), above=beside)
    assert e.counts.fused["range"] == 0 and e.counts.rejected["range"] == 0
    sent = sum(1 for _, m in _arrivals(0, True, beside) if isinstance(m, RangeFix))
    assert sent - 3 <= e.counts.off_deck <= sent  # but those before the first tick or after the last
    without = _fly(_arrivals(0, ranges=False, above=beside), above=beside)
    np.testing.assert_allclose(e.position_ned_m, without.position_ned_m, rtol=0, atol=1e-12)


def test_an_outlier_range_is_gated():
    """A range 1 m short (a bird, the carrier's mast) among good ones is rejected and counted,
    the others fused."""
    arrivals = _arrivals(1, ranges=True)
    k = next(i for i, (_, m) in enumerate(arrivals) if isinstance(m, RangeFix) and m.t_s >= LOSS[0] + 0.2)
    t, m = arrivals[k]
    assert isinstance(m, RangeFix)
    arrivals[k] = (t, RangeFix(m.t_s, m.range_m - 1.0, m.sigma_m, m.deck_top_ned_m, m.deck_radius_m))
    e = _fly(arrivals)
    assert e.counts.rejected["range"] == 1 and e.counts.fused["range"] > 100
    assert abs(float(np.asarray(e.position_ned_m)[2] - (-ABOVE[2]))) <= 0.05


def test_late_ranges_give_the_in_order_result():
    """The same measurements handed in at their capture times or late and out of order (the
    ranges held 0.3 s, behind the markers and the GNSS) give the same estimate (all captured
    0.4 s before the end, so that all arrive)."""
    def captured(m: object) -> float:
        return m.capture_t_s if isinstance(m, MarkerFix) else m.t_s  # type: ignore[attr-defined]

    arrivals = [(a, m) for a, m in _arrivals(2, ranges=True) if captured(m) <= LOSS[1] - 0.4]
    on_time = sorted(((captured(m), m) for _, m in arrivals), key=lambda a: a[0])
    late = sorted(((a + 0.3 if isinstance(m, RangeFix) else a, m) for a, m in arrivals), key=lambda a: a[0])
    a, b = _fly(on_time), _fly(late)
    np.testing.assert_allclose(b.position_ned_m, a.position_ned_m, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.covariance, a.covariance, rtol=0, atol=1e-12)
    assert a.counts == b.counts and a.counts.fused["range"] > 100
