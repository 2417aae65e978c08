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
from mission.phases.types import CarrierSamples, Observation, RecoveryModel, RecoveryState, describe_age

TURN_MIN_SPEED_M_S = 0.3  # [m/s] a carrier slower than this has no heading to measure a turn by
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
    """The recovery's view of the carrier updated: course, last fresh time, and its velocity
    samples over the last ``recovery.carrier_rate_window_s`` (:func:`kept_samples`)."""
    c = obs.carrier
    if c is None:
        return rec
    rec = replace(rec, course=course(c.velocity_ned_m_s, rec.course))
    if carrier_fresh(obs, r.carrier_return_max_age_s):
        rec = replace(rec, carrier_seen_s=t)
    samples = kept_samples(rec.carrier_samples, t - c.age_s, c.velocity_ned_m_s, r.carrier_rate_window_s, c.yaw_rad)
    return rec if samples is rec.carrier_samples else replace(rec, carrier_samples=samples)


def mean_speed_m_s(samples: CarrierSamples, velocity_ned_m_s: np.ndarray) -> float:
    """[m/s] the carrier's horizontal speed as the mean of its velocity ``samples`` (the window
    :func:`observe_carrier` keeps): a GNSS velocity's noise (0.1-0.3 m/s on a parked carrier)
    averages out of the mean vector, where it adds to each sample's length. No samples: the
    length of ``velocity_ned_m_s``'s horizontal part."""
    if not samples:
        return float(norm(velocity_ned_m_s[:2]))
    return math.hypot(sum(s[1] for s in samples) / len(samples), sum(s[2] for s in samples) / len(samples))


def kept_samples(samples: CarrierSamples, sampled_s: float, velocity_ned_m_s: np.ndarray,
                 window_s: float, yaw_rad: float | None = None) -> CarrierSamples:
    """``samples`` ((t [s] the sample's own time, v_n, v_e [m/s], its heading [rad] or NaN when
    it sent none), oldest first) with the carrier's velocity and heading ``yaw_rad`` sampled at
    ``sampled_s`` (``t - age``) added when it is newer than the last,
    and those more than ``window_s`` [s] older than it dropped. A sample read again (or its time
    moved back by less than the window, as a clock offset's estimate moves) changes nothing; one
    older than that (the carrier's clock went back) starts the samples anew."""
    if samples:
        last = samples[-1][0]
        if last - window_s <= sampled_s <= last:
            return samples
        if sampled_s < last:
            samples = ()
    kept = tuple(s for s in samples if s[0] >= sampled_s - window_s)
    yaw = math.nan if yaw_rad is None or not math.isfinite(yaw_rad) else float(yaw_rad)
    return (*kept, (float(sampled_s), float(velocity_ned_m_s[0]), float(velocity_ned_m_s[1]), yaw))


def carrier_rates(samples: CarrierSamples, window_s: float) -> tuple[float | None, float | None]:
    """The carrier's horizontal acceleration [m/s^2] and turn rate [rad/s] (unsigned) over its
    ``samples`` (:func:`kept_samples`): the least-squares slopes, over the samples' own times, of
    its velocity and of its unwrapped heading (of the samples at least :data:`TURN_MIN_SPEED_M_S`
    fast). The heading is the one the carrier sent when every such sample has one (its own
    attitude estimate: the body the deck turns with), else the direction of its velocity. The
    velocity the passenger sees may be an estimate in its own frame (the relative estimator's,
    carrying the passenger's own velocity error: 0.1 m/s across a carrier at 0.45 m/s is 13 deg of
    heading), the carrier's heading is not. A steady turn or acceleration reads exactly; a wobble
    of the heading (a fused velocity's noise) is averaged over the window instead of differenced
    between two samples. Each is None while its samples span less than half ``window_s`` [s]."""
    if len(samples) < 2:
        return None, None
    a = np.asarray(samples, dtype=float)
    ts, v = a[:, 0], a[:, 1:3]
    accel = None
    if ts[-1] - ts[0] >= window_s / 2:
        tc = ts - ts.mean()
        accel = float(norm(tc @ (v - v.mean(axis=0)) / float(tc @ tc)))
    moving = np.hypot(v[:, 0], v[:, 1]) >= TURN_MIN_SPEED_M_S
    tm = ts[moving]
    if len(tm) < 2 or tm[-1] - tm[0] < window_s / 2:
        return accel, None
    sent = a[moving, 3]
    heading = np.unwrap(sent if np.isfinite(sent).all() else np.arctan2(v[moving, 1], v[moving, 0]))
    tc = tm - tm.mean()
    return accel, abs(float(tc @ (heading - heading.mean()) / float(tc @ tc)))


def carrier_unsteady(rec: RecoveryState, obs: Observation, r: RecoveryModel) -> str | None:
    """Why the carrier is not steady enough to land on (None: it is): accelerating (its reported
    acceleration, else :func:`carrier_rates`' from its velocity) or turning (:func:`carrier_rates`)
    beyond the recovery's limits, measured over its samples of the last
    ``recovery.carrier_rate_window_s`` by their own times (``t - age``: a 30 Hz carrier read by
    a 50 Hz tick would otherwise seem to turn up to a fifth faster than it does)."""
    c = obs.carrier
    if c is None:
        return None
    accel, turn = carrier_rates(rec.carrier_samples, r.carrier_rate_window_s)
    if c.acceleration_ned_m_s2 is not None:
        accel = float(norm(np.asarray(c.acceleration_ned_m_s2)[:2]))
    if accel is not None and accel > r.carrier_max_accel_m_s2:
        return f"the carrier accelerates at {accel:.2f} m/s^2 (limit {r.carrier_max_accel_m_s2:g})"
    if turn is not None and turn > r.carrier_max_turn_rate_rad_s:
        return f"the carrier turns at {math.degrees(turn):.1f} deg/s (limit {math.degrees(r.carrier_max_turn_rate_rad_s):g})"
    return None
