"""A flown mission (:class:`sim.batch.recovery.Flight`) held against the world's truth: the true
contact error and riding offset (the vehicle's true position against the carrier's true dock
point), the estimate's error at contact, deck touches outside the contact conditions counted on
the truth, the time the marker was in view. With ``[relnav]`` and ``[world]`` errors the flight's
own summary measures the vehicle's estimate against the phases' dock point, both in the
passenger's frame; these are the world's. Frames: local NED [m], [m/s]."""
from __future__ import annotations

from typing import Any

import numpy as np

from mission.config.schema import Config
from mission.phases import Phase
from mission.record.table import VEC
from sim.batch.recovery import Flight

BEFORE_CONTACT = (Phase.RETURNING, Phase.HOLDOFF, Phase.APPROACH, Phase.GO_AROUND)


def _vec(f: Flight, name: str) -> np.ndarray:
    return np.stack([f.record.cols[f"{name}_{a}"] for a in VEC], axis=1)


def relnav_truth(cfg: Config, f: Flight) -> dict[str, Any]:
    """The flight's figures against the truth: per leg its outcome and true contact error
    (horizontal, vertical: the vehicle above the dock point negative) [m], the estimate's error
    then [m] and the attempts; the true riding offset (3D, horizontal) max and median [m];
    ``true_deck_touches``: ticks before contact with the vehicle truly within the deck's radius
    and at or below the contact height over it while out of the contact conditions (its true
    velocity against the carrier's); ``low_horizontal_speed_m_s``: its true horizontal speed
    against the deck [m/s] over the approach's ticks within three contact heights over the dock
    point and the deck's radius (p50, p95, max, and how many ticks); P1-P3 and the largest command jump at a phase switch
    [m/s] from the summary; the go-arounds, the fallback's reason, the marker's time in view [s]."""
    t, phase, r = f.record.t, f.record.phase, cfg.recovery
    dock = _vec(f, "x_c_true") + np.asarray(cfg.mission.dock_offset_ned_m, float)
    x = _vec(f, "x_true")
    off = x - dock
    dv = np.gradient(x, t, axis=0) - np.gradient(dock, t, axis=0)
    est_err = np.linalg.norm(_vec(f, "rel_est") - _vec(f, "rel_true"), axis=1)
    legs = []
    for leg in f.state.legs_done:
        c = leg.get("contact")
        row: dict[str, Any] = {"leg": leg["leg"], "outcome": leg["outcome"]}
        if c:
            k = int(np.argmin(abs(t - c["time_s"])))
            row.update(contact_horizontal_m=round(float(np.hypot(*off[k, :2])), 4),
                       contact_vertical_m=round(float(off[k, 2]), 4), estimate_error_m=round(float(est_err[k]), 4),
                       attempts=c["attempts"])
        legs.append(row)
    riding = phase == Phase.RIDING.value
    ride, ride_h = np.linalg.norm(off[riding], axis=1), np.hypot(off[riding, 0], off[riding, 1])
    horizontal = np.hypot(off[:, 0], off[:, 1])
    out_of_contact = ((horizontal > r.contact_radius_m) | (np.hypot(dv[:, 0], dv[:, 1]) > r.contact_max_horizontal_speed_m_s)
                      | (np.abs(dv[:, 2]) > r.contact_max_vertical_speed_m_s))
    touches = (np.isin(phase, [p.value for p in BEFORE_CONTACT]) & (off[:, 2] >= -r.contact_height_m)
               & (horizontal <= r.deck_radius_m) & out_of_contact)
    # the last decimetres: the approach within three contact heights over the dock point and over the deck,
    # where the contact's speeds are decided (a figure of every descent, not of the rare touch alone)
    low = ((phase == Phase.APPROACH.value) & (off[:, 2] >= -3.0 * r.contact_height_m) & (horizontal <= r.deck_radius_m))
    low_speed = np.hypot(dv[low, 0], dv[low, 1])
    seen = _vec(f, "since_marker")[:, 0] <= cfg.relnav.marker_timeout_s
    s, rec = f.summary, f.state.recovery
    p1_legs = [{k: leg.get(k) for k in ("leg", "p1", "max_offset_before_separation_m", "departure_delay_s")}
               for leg in s.get("legs") or []]

    def stat(v: np.ndarray, how) -> float | None:
        return round(float(how(v)), 4) if v.size else None

    return {"docked": f.docked, "legs": legs, "phase": s.get("phase"), "reason": s.get("reason"),
            "riding_offset_max_m": stat(ride, np.max), "riding_offset_median_m": stat(ride, np.median),
            "riding_horizontal_max_m": stat(ride_h, np.max), "riding_horizontal_median_m": stat(ride_h, np.median),
            "p1": s.get("p1"), "p2": s.get("p2"), "p3": s.get("p3"),
            "max_phase_switch_jump_m_s": s.get("max_phase_switch_jump_m_s"),
            "relative_input_jump_m_s": s.get("relative_input_jump_m_s"),
            "true_deck_touches": int(np.count_nonzero(touches)), "go_arounds": f.go_arounds,
            "low_horizontal_speed_m_s": {"p50": stat(low_speed, np.median), "p95": stat(low_speed, lambda v: np.percentile(v, 95)),
                                         "max": stat(low_speed, np.max), "ticks": int(low_speed.size)},
            "p1_legs": p1_legs, "worst_ride": _worst_ride(f, riding),
            "fallback": (rec.fallback_why or None) if rec is not None else None,
            "marker_in_view_s": round(float(seen.sum() * (t[1] - t[0])), 1) if len(t) > 1 else 0.0,
            "duration_s": round(float(t[-1]), 1)}


def _worst_ride(f: Flight, riding: np.ndarray) -> dict[str, Any] | None:
    """Where the riding offset by the estimate (the vehicle's own position against the phases'
    dock point, P1's figure) was largest: its time [s], since the ride began [s], the offset
    [m] NED, the true carrier's speed [m/s] and acceleration [m/s^2], the phases' carrier
    velocity less the true one (horizontal) [m/s], the relative estimate's error [m], the
    marker's age [s]. None: no riding tick."""
    t = f.record.t
    if not riding.any():
        return None
    off = _vec(f, "x_p") - _vec(f, "dock")
    size = np.where(riding, np.linalg.norm(off, axis=1), -1.0)
    size = np.where(np.isfinite(size), size, -1.0)
    k = int(np.argmax(size))
    start = k
    while start > 0 and riding[start - 1]:
        start -= 1
    v_true = np.gradient(_vec(f, "x_c_true"), t, axis=0)
    a_true = np.gradient(v_true, t, axis=0)
    dv = _vec(f, "v_c")[k] - v_true[k]
    return {"t_s": round(float(t[k]), 2), "into_ride_s": round(float(t[k] - t[start]), 2),
            "offset_ned_m": [round(float(x), 3) for x in off[k]],
            "carrier_speed_m_s": round(float(np.hypot(*v_true[k, :2])), 3),
            "carrier_accel_m_s2": round(float(np.hypot(*a_true[k, :2])), 3),
            "deck_velocity_error_m_s": round(float(np.hypot(*dv[:2])), 3),
            "relative_error_m": round(float(np.linalg.norm(_vec(f, "rel_est")[k] - _vec(f, "rel_true")[k])), 3),
            "marker_age_s": round(float(_vec(f, "since_marker")[k, 0]), 2)}
