"""The battery's say in a mission that comes home: whether it calls the passenger home now, and
whether the next leg can still be flown and recovered with the reserve. Pure: from the vehicle's
battery readings [%] and the mission clock [s]."""

from __future__ import annotations

import numpy as np

from mission.core.law import norm
from mission.phases.types import MissionModel, MissionState, Observation, RecoveryModel, dock_point


DRAIN_AFTER_S = 10.0  # [s] the drain rate is measured once the first reading is this old


def _drain_rate(state: MissionState, obs: Observation) -> float | None:
    """The battery's drain rate [%/s]: the average since the first reading (``state.battery_start``),
    once that is at least :data:`DRAIN_AFTER_S` old (None before, or with no reading)."""
    v = obs.vehicle
    if v is None or v.battery_pct is None or state.battery_start is None:
        return None
    t0, pct0 = state.battery_start
    if obs.t_s - t0 < DRAIN_AFTER_S:
        return None
    return max((pct0 - v.battery_pct) / (obs.t_s - t0), 0.0)


def _model(m: MissionModel) -> RecoveryModel:
    assert m.recovery is not None  # the battery recalls only with final_action "return"
    return m.recovery


def battery_recall(state: MissionState, obs: Observation, m: MissionModel) -> str | None:
    """Why the battery calls the passenger home now (None: it does not, or nothing is known).

    The drain rate [%/s] is the average since the first reading (``state.battery_start``, after
    at least 10 s); coming home takes the distance to the holdoff point at the return speed less the
    carrier's speed away, plus ``recovery.docking_budget_s``. The passenger is recalled when what is
    left, less what that would use, falls to ``recovery.battery_reserve_pct``."""
    r, v, c = _model(m), obs.vehicle, obs.carrier
    rate = _drain_rate(state, obs)
    if rate is None or v is None or v.battery_pct is None or c is None:
        return None
    dock = dock_point(obs, m)
    to_carrier = dock - v.position_ned_m
    dist = float(norm(to_carrier))
    away = float(np.dot(c.velocity_ned_m_s, to_carrier)) / dist if dist > 1e-6 else 0.0
    closing = max(r.returning.speed_m_s - max(away, 0.0), 0.3)
    needed = rate * (dist / closing + r.docking_budget_s)
    if v.battery_pct - needed <= r.battery_reserve_pct:
        return (f"battery: {v.battery_pct:.0f} % left, coming home uses about {needed:.0f} % "
                f"(reserve {r.battery_reserve_pct:g} %)")
    return None


def next_leg_problem(state: MissionState, obs: Observation, m: MissionModel) -> str | None:
    """Why the next leg cannot be flown and recovered with the battery's reserve (None: it can).

    The next leg costs, at the drain rate so far (as :func:`battery_recall` measures it): the ride
    until the carrier is b c from its target (at the carrier's top speed), the flight out and back
    (2 b c at the return speed), the task, and the docking budget."""
    r, v, c = _model(m), obs.vehicle, obs.carrier
    rate = _drain_rate(state, obs)
    if m.next_target is None or rate is None or v is None or v.battery_pct is None or c is None:
        return None
    bc = m.tick.law.separation_distance_m
    carrier_speed = m.tick.carrier_safety.max_speed_m_s or 1.0
    ride = max(float(norm(m.next_target - dock_point(obs, m))) - bc, 0.0) / carrier_speed
    needed = rate * (ride + 2 * bc / r.returning.speed_m_s + r.at_target_s + r.docking_budget_s)
    if v.battery_pct - needed <= r.battery_reserve_pct:
        return (f"battery: {v.battery_pct:.0f} % left, the next leg uses about {needed:.0f} % "
                f"(reserve {r.battery_reserve_pct:g} %)")
    return None
