"""What a log directory's JSON says about the mission beside the record's figures: ``mission.json``'s
mission info from the configuration (:func:`mission_info`) and what the flown mission's last state
adds to it (:func:`flown_info`), and ``summary.json``'s outcome (:func:`outcome_summary`).
Frames: local NED [m]; times [s] on the mission clock.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from mission.config.schema import Config
from mission.phases.types import MissionState


def mission_info(cfg: Config) -> dict[str, Any]:
    """What ``mission.json`` records about the mission (for summaries and plots)."""
    return {
        "target_ned_m": list(cfg.scenario.target),
        "obstacles": [{"center": o.center, "radius": o.radius} for o in cfg.scenario.obstacles],
        "bc_m": cfg.law.params().separation_distance_m,
        "carrier_start_ned_m": list(cfg.scenario.carrier_start),
        "dock_offset_ned_m": list(cfg.mission.dock_offset_ned_m),
        "dock_tolerance_m": cfg.mission.dock_tolerance_m,
        "arrival_radius_m": cfg.mission.arrival_radius_m,
        "pair": cfg.zenoh.pair,
        "rate_hz": cfg.mission.rate_hz,
        "final_action": cfg.mission.final_action,
        "ride": cfg.mission.ride,
        "deck_clear_height_m": cfg.mission.deck_clear_height_m,
        "targets": cfg.scenario.legs(),
        "frame": cfg.scenario.frame,
        "recovery": cfg.recovery.model_dump(mode="json") if cfg.mission.final_action == "return" else None,
    }


def recovered_info(st: MissionState) -> dict[str, Any] | None:
    """How the recovery went, for mission.json (None: the mission did not try one)."""
    rec = st.recovery
    if rec is None:
        return None
    return {"why": rec.why, "attempts": rec.attempts, "contact": rec.contact, "fallback": rec.fallback_why or None,
            "started_s": rec.started_s}


def flown_info(st: MissionState) -> dict[str, Any]:
    """What the mission's last state adds to mission.json: the separation's instant [s] and
    anchor [m] NED, the recovery (:func:`recovered_info`), the legs done and skipped."""
    return {"separation_time_s": st.separation_time_s, "anchor_ned_m": None if st.anchor is None else st.anchor.tolist(),
            "recovered": recovered_info(st), "legs_done": list(st.legs_done), "legs_skipped": st.legs_skipped}


def outcome_summary(st: MissionState, ticks: int, overruns: int, counters: dict[str, Any], rates_hz: Sequence[float],
                    doubts_at_separation: int | None) -> dict[str, Any]:
    """How a flown mission ended, for summary.json: its phase, reason and detail, ``ticks`` and
    loop ``overruns``, the loop's ``counters`` (what was dropped and why), the median of the
    LOCAL_POSITION_NED rates seen while flying [Hz] (None: none measured), and whether the carrier
    feed had jumped onto a new track or had its source contested by the separation
    (``doubts_at_separation``: how often; None: no separation): then P1-P3 are not claimed."""
    outcome: dict[str, Any] = {
        "phase": st.phase, "reason": st.reason, "detail": st.detail, "ticks": ticks, "loop_overruns": overruns,
        **counters, "position_rate_hz": round(float(np.median(rates_hz)), 2) if len(rates_hz) else None,
        "carrier_resync_before_separation": None if doubts_at_separation is None else doubts_at_separation > 0}
    if doubts_at_separation:  # the latch may have fired on a relocalised (or spoofed) track
        outcome.update(p1=None, p2=None, p3=None, p1_p3_note=(
            "not claimed: the carrier feed jumped onto a new track or its source was contested before "
            "the separation (carrier_feed.jumps, carrier_feed.contests)"))
    return outcome
