"""Is the carrier a carrier to land on (pure): its state fresh and trusted (:func:`carrier_unfit`),
and the carrier steady, not accelerating or turning beyond the recovery's limits
(:func:`carrier_unsteady`, on the samples :func:`observe_carrier` keeps in the recovery's state).

Frames: local NED [m], [m/s]; times [s] on the controller's clock, a carrier sample's own time
``t - age``.
"""
from __future__ import annotations

import math

import numpy as np

from mission.core.docking import course
from mission.core.law import norm
from mission.core.records import replace
from mission.phases.types import Observation, RecoveryModel, RecoveryState, describe_age

CARRIER_RATE_WINDOW_S = 0.25  # [s] the carrier's acceleration and turn rate are measured over this
FUTURE_SLACK_S = 0.05  # [s] a carrier state stamped further ahead of its clock than the bound and this: a fault


def carrier_unfit(obs: Observation, limit_s: float) -> str | None:
    """Why the carrier's state is no state to dock on, or None when it is one: present, its
    liveliness token not gone, measured (its age known: a round trip gave the carrier's clock)
    no longer than ``limit_s`` [s] ago (recovery.carrier_max_age_s) with the bound, not stamped
    ahead of the carrier's clock beyond the bound (:data:`FUTURE_SLACK_S`), and trusted by the
    feed (not just bound, resynced or contested: ``CarrierObs.untrusted``)."""
    c = obs.carrier
    if c is None:
        return "no carrier state"
    if c.alive is False:
        return f"carrier liveliness token gone (its last state {describe_age(c)})"
    if c.age_bound_s is None:
        return "the carrier's clock is not known (no round trip yet): its state's age is unknown"
    if c.worst_age_s > limit_s:
        return f"carrier state {describe_age(c)} (recovery.carrier_max_age_s = {limit_s:g})"
    if c.age_s < -(c.age_bound_s + FUTURE_SLACK_S):
        return (f"carrier state stamped {-c.age_s:.2f} s ahead of the carrier's clock (bound {c.age_bound_s:.3f} s): "
                "its stamps and its round trips disagree")
    if c.untrusted is not None:
        return f"carrier feed not trusted ({c.untrusted})"
    return None


def carrier_fresh(obs: Observation, limit_s: float) -> bool:
    """A carrier state to dock on (:func:`carrier_unfit` finds nothing wrong)."""
    return carrier_unfit(obs, limit_s) is None


def observe_carrier(rec: RecoveryState, obs: Observation, r: RecoveryModel, t: float) -> RecoveryState:
    """The recovery's view of the carrier updated: course, last fresh time, velocity history."""
    c = obs.carrier
    if c is None:
        return rec
    rec = replace(rec, course=course(c.velocity_ned_m_s, rec.course))
    if carrier_fresh(obs, r.carrier_return_max_age_s):
        rec = replace(rec, carrier_seen_s=t)
    sampled = t - c.age_s  # when the carrier took this sample (the rates are measured between samples)
    if rec.carrier_t_s is None or sampled - rec.carrier_t_s >= CARRIER_RATE_WINDOW_S:
        rec = replace(rec, carrier_v=np.array(c.velocity_ned_m_s, dtype=float), carrier_t_s=sampled)
    return rec


def carrier_unsteady(rec: RecoveryState, obs: Observation, r: RecoveryModel, t: float) -> str | None:
    """Why the carrier is not steady enough to land on (None: it is): accelerating or turning
    beyond the recovery's limits, measured between its samples over :data:`CARRIER_RATE_WINDOW_S`
    of their own time (the samples' times, ``t - age``: a 30 Hz carrier read by a 50 Hz tick
    would otherwise seem to turn up to a fifth faster than it does)."""
    c = obs.carrier
    if c is None or rec.carrier_v is None or rec.carrier_t_s is None:
        return None
    dt = t - c.age_s - rec.carrier_t_s
    if c.acceleration_ned_m_s2 is not None:
        accel = float(norm(np.asarray(c.acceleration_ned_m_s2)[:2]))
    else:
        accel = float(norm((c.velocity_ned_m_s - rec.carrier_v)[:2])) / dt if dt >= CARRIER_RATE_WINDOW_S / 2 else 0.0
    if accel > r.carrier_max_accel_m_s2:
        return f"the carrier accelerates at {accel:.2f} m/s^2 (limit {r.carrier_max_accel_m_s2:g})"
    v0, v1 = rec.carrier_v[:2], np.asarray(c.velocity_ned_m_s)[:2]
    if float(norm(v0)) >= 0.3 and float(norm(v1)) >= 0.3 and dt >= CARRIER_RATE_WINDOW_S / 2:
        turn = abs(math.remainder(math.atan2(v1[1], v1[0]) - math.atan2(v0[1], v0[0]), 2 * math.pi)) / dt
        if turn > r.carrier_max_turn_rate_rad_s:
            return f"the carrier turns at {math.degrees(turn):.1f} deg/s (limit {math.degrees(r.carrier_max_turn_rate_rad_s):g})"
    return None
