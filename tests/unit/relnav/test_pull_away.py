"""The relative estimator with configs/relnav.toml's tuning following a carrier that pulls away
from rest at its acceleration limit (1 m/s^2), as it does at the start of a ride: the markers
(3 cm, ~17 Hz, 100 ms late) and the GNSS fixes (10 Hz, 200 ms late, 2 m of bias) as the
simulation gives them. The riding vehicle flies the estimate's carrier velocity as its
feed-forward, so what it lags by is what the vehicle lags the dock point by (P1, docs/relnav.md)."""
from __future__ import annotations

import numpy as np

from mission.config.schema import load_config
from mission.relnav.estimator import RelativeEstimator
from mission.relnav.inputs import CarrierFix, MarkerFix, OwnSample
from tests.conftest import CONFIGS

DT = 0.02  # [s] the passenger's tick
START = 5.0  # [s] the carrier starts
ACCEL = 1.0  # [m/s^2] safety.carrier_max_accel_m_s2


def _carrier(t: float) -> tuple[np.ndarray, np.ndarray]:
    """At rest until START, then ACCEL north up to 2 m/s: position [m], velocity [m/s] NED."""
    s = max(0.0, t - START)
    a = min(s * ACCEL, 2.0)
    x = 0.5 * a * s if a < 2.0 else 2.0 + 2.0 * (s - 2.0)
    return np.array([x, 0.0, 0.0]), np.array([a, 0.0, 0.0])


def _velocity_lag(seed: int, sends_acceleration: bool = False) -> float:
    """The estimate's carrier velocity behind the truth [m/s], mean over 0.5-2 s of the pull;
    ``sends_acceleration``: each fix carries the acceleration the carrier measured when it
    published it (0.2 s after the fix), with 0.05 m/s^2 of noise."""
    params = load_config(CONFIGS / "relnav.toml").relnav.params()
    est = RelativeEstimator(params)
    rng = np.random.default_rng(seed)
    bias, above = np.array([2.0, -1.0, 0.3]), np.array([0.0, 0.0, -1.5])
    waiting: list[tuple[float, object]] = []
    lags = []
    for k in range(int(7.5 / DT)):
        t = k * DT
        x, v = _carrier(t)
        if k % 5 == 0:
            a = None
            if sends_acceleration:
                a = np.array([ACCEL if START <= t + 0.2 and _carrier(t + 0.2)[1][0] < 2.0 else 0.0, 0.0, 0.0])
                a = a + rng.normal(0, 0.05, 3)
            waiting.append((t + 0.2, CarrierFix(t, x + bias + rng.normal(0, 0.3, 3), v + rng.normal(0, 0.2, 3), a)))
        if k % 3 == 0:
            waiting.append((t + 0.1, MarkerFix.isotropic(t, -above + rng.normal(0, 0.03, 3), 0.03)))
        for _, m in [w for w in waiting if w[0] <= t]:
            est.carrier(m) if isinstance(m, CarrierFix) else est.marker(m)
        waiting = [w for w in waiting if w[0] > t]
        e = est.tick(OwnSample(t, x + above, v))  # the vehicle rides over it
        if START + 0.5 <= t <= START + 2.0:
            lags.append(v[0] - float(np.asarray(e.carrier_velocity_ned_m_s)[0]))
    return float(np.mean(lags))


def test_the_estimate_follows_a_carrier_pulling_away_from_rest():
    """Mean lag over six seeds at most 0.25 m/s: 0.20-0.22 with relnav.accel_noise_m_s2 = 1.0,
    0.30-0.33 with 0.3, where the vehicle riding it fell up to 0.72 m behind its dock point (P1
    failed in 24 of 200 Monte-Carlo flights, each at the start of a ride from rest)."""
    lags = [_velocity_lag(seed) for seed in range(6)]
    assert 0.0 < float(np.mean(lags)) <= 0.25, lags


def test_the_acceleration_the_carrier_sends_takes_the_lag_away():
    """With the acceleration the carrier measured sent beside each fix, the estimate's velocity
    moves on through the fixes' latency as the carrier's does: mean lag over six seeds within
    0.05 m/s either way (0.20-0.22 m/s behind without it, the test above)."""
    lags = [_velocity_lag(seed, sends_acceleration=True) for seed in range(6)]
    assert abs(float(np.mean(lags))) <= 0.05, lags
    assert max(abs(x) for x in lags) <= 0.1, lags
