"""HOLDOFF's settle rule (mission/phases/recovery.py): how far the vehicle's offset from the
holdoff point moves over the dwell comes from its positions, not from its velocity estimate, whose
PX4 error PX4 holds as a steady offset while reporting it whole (docs/px4-hold.md)."""
from __future__ import annotations

import numpy as np

from mission.config.schema import load_config
from mission.model import mission_model
from mission.phases.recovery import _settled
from mission.phases.types import RecoveryState
from tests.conftest import CONFIGS

MODEL = mission_model(load_config(CONFIGS / "recovery.toml")).recovery
assert MODEL is not None
DT = 0.02  # [s] one tick at 50 Hz


def settled_at(offsets: list[np.ndarray | None]) -> float | None:
    """The first tick time [s] at which a vehicle with these offsets (one a tick; None: not
    near) counts as settled."""
    rec = RecoveryState(started_s=0.0, why="task done")
    for k, offset in enumerate(offsets):
        rec, settled = _settled(rec, k * DT, offset, MODEL)
        if settled:
            return k * DT
    return None


def test_a_steady_offset_settles_after_the_dwell_whatever_the_velocity_estimate_says():
    # (the rule reads no velocity: PX4 holding a 0.25 m/s velocity error stands 0.26 m off, steady)
    steady = [np.array([0.2, -0.1, 0.05])] * 200
    assert settled_at(steady) == np.float64(round(MODEL.settle_dwell_s / DT) * DT)


def test_a_vehicle_drifting_across_the_point_does_not_settle():
    speed = MODEL.settle_speed_m_s * 1.5  # [m/s] relative to the point, within the radius all along
    r = MODEL.settle_radius_m
    drift = [np.array([-r + (speed * k * DT) % (2 * r), 0.0, 0.0]) for k in range(400)]
    assert settled_at(drift) is None
    swing = [np.array([r * np.sin(2 * np.pi * k * DT / MODEL.settle_dwell_s), 0.0, 0.0]) for k in range(400)]
    assert settled_at(swing) is None  # back where it was after each dwell, but never still
    slow = MODEL.settle_speed_m_s * 0.5
    creeping = [np.array([-r + slow * k * DT, 0.0, 0.0]) for k in range(200)]
    assert settled_at(creeping) is not None


def test_leaving_the_radius_starts_the_dwell_again():
    near, away = np.array([0.1, 0.0, 0.0]), None
    offsets = [near] * 40 + [away] + [near] * 100  # 0.8 s near, one tick out, then near
    t = settled_at(offsets)
    assert t is not None and t >= 41 * DT + MODEL.settle_dwell_s - 1e-9
