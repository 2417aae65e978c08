"""One marker off its neighbours while riding, with the PX4 relnav tuning (configs/px4_sitl_relnav.toml):
the detector's covariance holds only the corners' noise (a centimetre), so without
``relnav.marker_model_sigma_m`` the filter takes a 9 cm outlier for the deck, swings the deck's
velocity by half a metre a second, and then rejects the good markers after it, as it did on a PX4
flight (docs/relnav.md, "What a marker's covariance leaves out")."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mission.config.schema import load_config
from mission.relnav.estimator import RelativeEstimator
from mission.relnav.inputs import CarrierFix, MarkerFix, OwnSample
from tests.conftest import CONFIGS

DT = 0.02  # [s] the passenger's tick
SPEED = np.array([0.8, 0.0, 0.0])  # [m/s] NED the carrier cruising north
ABOVE = np.array([0.0, 0.0, -1.5])  # [m] the vehicle rides 1.5 m over the carrier's reference point
OUTLIER_S = 10.0  # [s] the odd marker's capture, after a 0.17 s gap
OUTLIER_M = np.array([0.09, 0.0, 0.0])  # [m] how far off its neighbours it is


def _ride(model_sigma_m: float, seed: int) -> tuple[float, int]:
    """The largest deck-velocity error [m/s] in the 1.5 s from the odd marker, and the markers
    rejected over the ride. Markers at ~13 Hz, 3 mm of noise and a stated 8 mm, 100 ms late;
    GNSS fixes at 10 Hz with 0.35 m/s of velocity noise and 2 m of bias, 200 ms late."""
    params = dataclasses.replace(load_config(CONFIGS / "px4_sitl_relnav.toml").relnav.params(),
                                 marker_model_sigma_m=model_sigma_m)
    est = RelativeEstimator(params)
    rng = np.random.default_rng(seed)
    bias = np.array([2.0, -1.0, 0.3])
    waiting: list[tuple[float, object]] = []
    worst = 0.0
    for k in range(int(12.0 / DT)):
        t = k * DT
        c = SPEED * t
        if k % 5 == 0:
            fix = CarrierFix(t, c + bias + rng.normal(0, 0.3, 3), SPEED + rng.normal(0, 0.35, 3), np.zeros(3))
            waiting.append((t + 0.2, fix))
        gap = OUTLIER_S - 0.17 < t < OUTLIER_S
        if k % 4 == 0 and not gap or abs(t - OUTLIER_S) < DT / 2:
            off = OUTLIER_M if abs(t - OUTLIER_S) < DT / 2 else rng.normal(0, 0.003, 3)
            waiting.append((t + 0.1, MarkerFix.isotropic(t, -ABOVE + off, 0.008)))
        for _, m in [w for w in waiting if w[0] <= t]:
            est.carrier(m) if isinstance(m, CarrierFix) else est.marker(m)
        waiting = [w for w in waiting if w[0] > t]
        e = est.tick(OwnSample(t, c + ABOVE, SPEED))
        if OUTLIER_S <= t <= OUTLIER_S + 1.5:
            worst = max(worst, float(np.linalg.norm((e.carrier_velocity_ned_m_s - SPEED)[:2])))
    return worst, est.counts().rejected["marker"]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_one_marker_off_its_neighbours_moves_the_deck_velocity_little(seed: int):
    """With the 3 cm the PX4 configuration adds, the deck's velocity stays within 0.3 m/s of the
    truth (0.27-0.28 on seeds 0-4, the GNSS velocity's noise included) and no marker is rejected;
    with the detector's covariance alone it swings 0.43-0.49 m/s off and two good markers after
    the odd one are rejected (the control: the test can fail)."""
    worst, rejected = _ride(load_config(CONFIGS / "px4_sitl_relnav.toml").relnav.marker_model_sigma_m, seed)
    assert worst < 0.3 and rejected == 0, (worst, rejected)
    bare_worst, bare_rejected = _ride(0.0, seed)
    assert bare_worst > 0.4 and bare_rejected >= 2, (bare_worst, bare_rejected)
