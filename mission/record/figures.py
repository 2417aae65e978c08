"""The figures of a flight record: what ``summary.json`` (and ``marsupial simulate --json``) says
about a flight, computed from its :class:`~mission.record.table.FlightRecord` alone.

:func:`figures` of one record against one target: the separation, the ride's offsets, the arrival,
the phase switches and stalls, the take-off from a deck, the recovery, and P1-P3 of the paper's
Definition 1; :func:`summary_of` adds, with several targets, each leg's figures and the whole
flight's (:data:`WHOLE_FLIGHT_NOTE`); :func:`summarise` reads a log directory's record first.
Times [s] from the first RIDING tick (t = 0 as in the paper; ``riding_start_s`` on the mission
clock); distances [m] and speeds [m/s] in local NED.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from mission.core.law import norm
from mission.phases.phase import AFTER_SEPARATION, FLYING, OUTBOUND, Phase
from mission.phases.stall import SETTLE_S, STALL_S
from mission.phases.types import TELEMETRY_SILENT_S
from mission.record.table import FlightRecord, read_record


def _num(x: float | None) -> float | None:
    return None if x is None or not np.isfinite(x) else round(float(x), 6)


def _nanmax(values: np.ndarray) -> float | None:
    """Largest finite value, or None when there is none (a flight that never saw the vehicle)."""
    finite = values[np.isfinite(values)]
    return _num(finite.max()) if finite.size else None


LAST_METRE_M = 1.0  # the last metre starts when the vehicle first comes this close to the target [m]
ON_TARGET_M = 0.05  # the reference "sits on the target" within this [m]


def _arrival_figures(r: FlightRecord, dist_t: np.ndarray, target: np.ndarray) -> dict[str, Any]:
    """How the vehicle finished: ``last_metre_s`` [s], from its first tick within
    :data:`LAST_METRE_M` of the target to the first ARRIVED tick; ``hover_speed_m_s`` [m/s], its
    mean horizontal speed (as the vehicle reports it) over the ticks we still fly it (up to the
    handover to Hold or Land) with the reference within :data:`ON_TARGET_M` of the target (None
    without such ticks); ``max_target_distance_at_target_m`` [m], its farthest from the target
    over those ticks."""
    out: dict[str, Any] = {"last_metre_s": None, "hover_speed_m_s": None, "max_target_distance_at_target_m": None}
    arrived = np.flatnonzero(r.phase == Phase.ARRIVED)
    close = np.flatnonzero(np.isfinite(dist_t) & (dist_t <= LAST_METRE_M))
    if len(arrived) and len(close) and close[0] <= arrived[0]:
        out["last_metre_s"] = _num(r.t[arrived[0]] - r.t[close[0]])
    ref_on = norm(r.vec("x_ref") - target) <= ON_TARGET_M
    ticks = np.flatnonzero(ref_on & np.isin(r.phase, sorted(OUTBOUND)))
    if len(ticks):
        v = r.vec("v_p")[ticks]
        out["hover_speed_m_s"] = _num(np.hypot(v[:, 0], v[:, 1]).mean())
        out["max_target_distance_at_target_m"] = _nanmax(dist_t[ticks])
    return out


def summarise(directory: str | Path) -> dict[str, Any]:
    """The summary of the flight logged in ``directory`` (:func:`summary_of` its record)."""
    return summary_of(read_record(directory))


def summary_of(r: FlightRecord) -> dict[str, Any]:
    """The summary of a flight record (:func:`figures` of the whole record), and with several
    targets ``legs``: the figures of each leg (its slice of the record, judged against its own
    target) with its outcome; the flight's P1-P3 then hold only if every leg flown holds them."""
    out = figures(r)
    if len(r.info.get("targets") or []) > 1:
        legs = []
        for leg in r.legs():
            fig = {"leg": leg.k, "target_ned_m": leg.target_ned_m}
            if leg.record is not None:
                fig.update(figures(leg.record))
            fig["outcome"] = leg.outcome
            legs.append(fig)
        out["legs"] = legs
        flown = [leg for leg in legs if "p1" in leg]
        for p in ("p1", "p2", "p3"):
            out[p] = bool(flown) and all(leg[p] for leg in flown)
        out.update(_whole_flight(r, flown))
    return out


#: With several targets, the top level's figures of one leg's separation: only in ``legs``.
PER_LEG_ONLY = ("separation_time_s", "carrier_target_distance_at_separation_m")
#: With several targets, the top level's figures that are the worst (largest) of the legs flown.
WORST_OF_LEGS = ("relative_speed_at_separation_m_s", "relative_input_jump_m_s", "input_jump_m_s",
                 "carrier_velocity_step_at_separation_m_s", "departure_delay_s",
                 "final_passenger_target_distance_m", "max_offset_before_separation_m", "riding_offset_held_m",
                 "max_relative_command_step_m_s", "max_target_distance_after_arrival_m", "last_metre_s",
                 "hover_speed_m_s", "max_target_distance_at_target_m", "takeoff_command_jump_m_s",
                 "takeoff_max_command_step_m_s", "takeoff_clear_s")
WHOLE_FLIGHT_NOTE = ("several targets: each leg's figures, against its own target, are in legs; at the top level "
                     f"{', '.join(PER_LEG_ONLY)} are per leg only (None), {', '.join(WORST_OF_LEGS)} are the largest of "
                     "the legs flown, min_carrier_target_distance_m is the carrier's closest approach to any target over "
                     "the whole flight, the rest (speed, obstacle clearance, phase switches, deck, contact of the last "
                     "recovery, P1-P3 of every leg) are of the whole flight")


def _whole_flight(r: FlightRecord, flown: list[dict[str, Any]]) -> dict[str, Any]:
    """The top level's target figures of a flight of several targets (:data:`WHOLE_FLIGHT_NOTE`),
    none of them measured against target 1 alone."""
    out: dict[str, Any] = {k: None for k in PER_LEG_ONLY}
    for k in WORST_OF_LEGS:
        if any(k in leg for leg in flown):  # the take-off's only riding on a deck
            values = [leg[k] for leg in flown if leg.get(k) is not None]
            out[k] = max(values) if values else None
    x_c = r.vec("x_c")
    have_c = np.isfinite(x_c).all(axis=1)
    targets = np.asarray(r.info["targets"], dtype=float)
    if have_c.any():
        out["min_carrier_target_distance_m"] = _num(min(norm(t - x_c[have_c]).min() for t in targets))
    out["top_level_figures"] = WHOLE_FLIGHT_NOTE
    return out


def figures(r: FlightRecord) -> dict[str, Any]:
    """The figures of a flight record, with the keys of ``marsupial simulate --json``.

    Times are counted from the first RIDING tick (the carrier starts its approach), as t = 0 in
    the paper. P1: during RIDING the vehicle stayed within the dock tolerance of the dock point,
    the latch fired and the vehicle left; P2: the vehicle ended within the arrival radius; P3:
    the carrier was never at the target (and its closest approach is reported).
    """
    info = r.info
    target = np.asarray(info["target_ned_m"])
    x_p, x_c, v_p, v_c = r.vec("x_p"), r.vec("x_c"), r.vec("v_p"), r.vec("v_c")
    u_cmd, dock = r.vec("u_cmd"), r.vec("dock")
    riding = r.phase == Phase.RIDING
    sep_phases = np.isin(r.phase, sorted(AFTER_SEPARATION))
    t0 = r.t[riding][0] if riding.any() else (r.t[0] if len(r.t) else 0.0)
    out: dict[str, Any] = {k: None for k in (
        "separation_time_s", "carrier_target_distance_at_separation_m", "relative_speed_at_separation_m_s",
        "relative_input_jump_m_s", "input_jump_m_s", "carrier_velocity_step_at_separation_m_s", "departure_delay_s",
        "final_passenger_target_distance_m", "min_carrier_target_distance_m", "min_obstacle_clearance_m",
        "max_passenger_speed_m_s")}
    out["riding_start_s"] = _num(t0) if riding.any() else None  # on the mission clock (record.csv t_s)
    have_c = np.isfinite(x_c).all(axis=1)
    if have_c.any():
        out["min_carrier_target_distance_m"] = _num(norm(target - x_c[have_c]).min())
    if len(r.t):
        # at the end of the flight, or, for a passenger that came home, at the end of its stay at the target
        arrived = np.flatnonzero(r.phase == Phase.ARRIVED)
        final = arrived[-1] if info.get("final_action") == "return" and len(arrived) else -1
        out["final_passenger_target_distance_m"] = _num(norm(x_p[final] - target))
        out["max_passenger_speed_m_s"] = _nanmax(norm(v_p))
    obstacles = info.get("obstacles", [])
    if obstacles and len(r.t):
        clear = min(float((norm(x_p - np.asarray(o["center"])) - o["radius"]).min()) for o in obstacles)
        out["min_obstacle_clearance_m"] = _num(clear)
    rel_cmd = u_cmd - np.nan_to_num(v_c)
    first_sep = int(np.argmax(sep_phases)) if sep_phases.any() else None
    if "separation_time_s" in info and info["separation_time_s"] is None:
        first_sep = None  # the mission says this leg never separated (e.g. it aborted, then fell back)
    if first_sep is not None and first_sep > 0:
        sep_t = info.get("separation_time_s")
        out["separation_time_s"] = _num((r.t[first_sep] if sep_t is None else sep_t) - t0)
        anchor = info.get("anchor_ned_m")
        if anchor is not None:
            out["carrier_target_distance_at_separation_m"] = _num(norm(target - np.asarray(anchor)))
        out["relative_speed_at_separation_m_s"] = _num(norm(rel_cmd[first_sep]))
        out["relative_input_jump_m_s"] = _num(norm(rel_cmd[first_sep] - rel_cmd[first_sep - 1]))
        # The paper's P1 is about the passenger's own input: the command's step at the separation
        # tick. The relative figure above also holds the carrier's measured velocity changing on that
        # tick (a new sample of an accelerating rover: up to ~0.03 m/s at 30 Hz), reported beside.
        out["input_jump_m_s"] = _num(norm(u_cmd[first_sep] - u_cmd[first_sep - 1]))
        out["carrier_velocity_step_at_separation_m_s"] = _num(norm(np.nan_to_num(v_c[first_sep] - v_c[first_sep - 1])))
        left = np.isin(r.phase, sorted(AFTER_SEPARATION - {Phase.SEPARATED}))  # the passenger has left the dock
        if left.any():
            out["departure_delay_s"] = _num(r.t[int(np.argmax(left))] - r.t[first_sep])
    tol = float(info.get("dock_tolerance_m", 0.5))
    # A riding tick without a dock (the vehicle's own telemetry went silent: it hovered on a zero
    # setpoint) measures no offset: left out, so the maximum stays finite and P1 decidable.
    offsets = norm(x_p[riding] - dock[riding]) if riding.any() else np.array([])
    offsets = offsets[np.isfinite(offsets)]
    offset_riding = float(offsets.max()) if offsets.size else np.inf
    out["max_offset_before_separation_m"] = _num(offset_riding)
    # held for two ticks running: a one-tick spike is a sample taken late (a stalled process), not
    # the vehicle's motion (docs/px4-hold.md)
    out["riding_offset_held_m"] = _num(float(np.minimum(offsets[:-1], offsets[1:]).max())) if offsets.size > 1 else None
    out["max_relative_command_step_m_s"] = _nanmax(norm(np.diff(rel_cmd[riding | sep_phases], axis=0))) if (riding | sep_phases).sum() > 1 else None
    # Arrival without a swing: once the vehicle has come within the arrival radius of the target,
    # the farthest it got from it again (None if it never came that close).
    dist_t = norm(x_p - target)
    near = np.flatnonzero(np.isfinite(dist_t) & (dist_t <= float(info.get("arrival_radius_m", 0.5))))
    out["max_target_distance_after_arrival_m"] = _nanmax(dist_t[near[0]:]) if len(near) else None
    out.update(_arrival_figures(r, dist_t, target))
    out["p1"] = bool(riding.any() and offset_riding <= tol and out["departure_delay_s"] is not None)
    out["p2"] = bool((r.phase == Phase.ARRIVED).any() and out["final_passenger_target_distance_m"] is not None
                     and out["final_passenger_target_distance_m"] <= float(info.get("arrival_radius_m", 0.5)))
    out["p3"] = bool(out["min_carrier_target_distance_m"] is not None and out["min_carrier_target_distance_m"] > 0.0)
    out["max_phase_switch_jump_m_s"] = _switch_jump(r.t, r.phase, u_cmd)
    out["max_phase_switch_excess_m_s"] = _switch_excess(r.t, r.phase, u_cmd)
    out["max_stall_command_offset_m_s"] = _stall_offset(r.t, r.phase, u_cmd, v_p, r.cols.get("vehicle_age_s"))
    if info.get("ride") == "deck":
        out.update(_takeoff_figures(r, x_p, rel_cmd, riding, info))
    out.update(_recovery_summary(r, x_p, v_p, v_c, dock))
    return out


def _takeoff_figures(r: FlightRecord, x_p: np.ndarray, rel_cmd: np.ndarray, riding: np.ndarray,
                     info: dict[str, Any]) -> dict[str, Any]:
    """The take-off from the deck (mission.ride = "deck"), from the first setpoint streamed on the
    deck until the vehicle is ``deck_clear_height_m`` above the deck's height at the separation (the
    latched anchor), on the command relative to the carrier (``u_cmd - v_c``) [m/s]:

    - ``takeoff_command_jump_m_s``: its largest change at a switch of the take-off: the first
      setpoint streamed (against zero, the seated vehicle's velocity relative to the deck: it sits
      on it, disarmed, with nothing sent before; what it *reports* is the deck's velocity plus its
      estimate's error, 0.2 m/s sigma, which is no change of a command: that is
      ``takeoff_stream_start_offset_m_s``), arming or a disarm, and the separation (the latch:
      RIDING -> SEPARATED; SEPARATED -> NAVIGATING only names the same law's progress);
    - ``takeoff_stream_start_offset_m_s``: the first setpoint streamed against the velocity the
      vehicle reported relative to the deck then (its estimate's error, for a seated vehicle);
    - ``takeoff_max_command_step_m_s``: its largest tick-to-tick change anywhere in that window
      (the ramp at the acceleration limits: at most their sum times the tick);
    - ``takeoff_clear_s`` [s]: from the separation until the vehicle is clear (None: never)."""
    out: dict[str, Any] = {"takeoff_command_jump_m_s": None, "takeoff_max_command_step_m_s": None,
                           "takeoff_clear_s": None, "takeoff_stream_start_offset_m_s": None}
    streamed = np.flatnonzero(riding & np.isfinite(rel_cmd).all(axis=1))
    anchor = info.get("anchor_ned_m")
    if not len(streamed) or anchor is None:
        return out
    start = int(streamed[0])
    after = np.arange(len(r.t)) > start
    above = after & (float(anchor[2]) - x_p[:, 2] > float(info.get("deck_clear_height_m", 1.0)))
    end = int(np.argmax(above)) if above.any() else len(r.t) - 1
    steps = norm(np.diff(rel_cmd[start:end + 1], axis=0))  # steps[j]: from tick start + j to start + j + 1
    own = r.vec("v_p")[start] - r.vec("v_c")[start]
    out["takeoff_stream_start_offset_m_s"] = _num(norm(rel_cmd[start] - own))
    jumps = [float(norm(rel_cmd[start]))]
    armed = r.cols.get("armed")
    switch = (r.phase[start + 1:end + 1] == Phase.SEPARATED) & (r.phase[start:end] != Phase.SEPARATED)
    if armed is not None:
        switch |= armed[start + 1:end + 1] != armed[start:end]
    jumps += [float(x) for x in steps[switch]]
    out["takeoff_command_jump_m_s"] = _nanmax(np.array(jumps))
    out["takeoff_max_command_step_m_s"] = _nanmax(steps) if len(steps) else None
    sep = np.flatnonzero(np.isin(r.phase, sorted(AFTER_SEPARATION)))
    if above.any() and len(sep):
        out["takeoff_clear_s"] = _num(r.t[end] - r.t[sep[0]])
    return out


def _switch_jump(t: np.ndarray, phase: np.ndarray, u_cmd: np.ndarray) -> float | None:
    """The largest change [m/s] of the commanded velocity from one tick to the next where the
    phase changed between two flying phases (None: no such switch). Not across a stall (ticks
    more than ``STALL_S`` apart): the vehicle flew on for the gap, and the command after it goes
    on from the vehicle, not from the command before it (:func:`_stall_offset` measures that)."""
    flying = np.isin(phase, sorted(FLYING))
    switch = np.flatnonzero((phase[1:] != phase[:-1]) & flying[1:] & flying[:-1] & (np.diff(t) <= STALL_S)) + 1
    jumps = norm(u_cmd[switch] - u_cmd[switch - 1]) if len(switch) else np.array([])
    return _nanmax(jumps) if len(jumps) else None


def _switch_excess(t: np.ndarray, phase: np.ndarray, u_cmd: np.ndarray) -> float | None:
    """What a switch adds to the command's step [m/s]: at each switch :func:`_switch_jump` counts,
    its step less the larger of the steps of the tick before it and the tick after it, the largest
    of these (None: no such switch, or none with a tick on each side). A command turning at the
    command filter's acceleration limit steps by that limit times dt on every tick (0.06 m/s at
    3 m/s^2 and 50 Hz), switch or not: its excess is about 0, where a switch that jumps stands out
    by its jump."""
    flying = np.isin(phase, sorted(FLYING))
    ok = (phase[1:] != phase[:-1]) & flying[1:] & flying[:-1] & (np.diff(t) <= STALL_S)
    switch = np.flatnonzero(ok) + 1
    switch = switch[(switch >= 2) & (switch + 1 < len(t))]
    if not len(switch):
        return None
    steps = norm(np.diff(u_cmd, axis=0))  # steps[k - 1]: from tick k - 1 to tick k
    excess = steps[switch - 1] - np.fmax(steps[switch - 2], steps[switch])
    return _nanmax(excess)


def _stall_offset(t: np.ndarray, phase: np.ndarray, u_cmd: np.ndarray, v_p: np.ndarray,
                  vehicle_age_s: np.ndarray | None = None) -> float | None:
    """After each stall (a gap between ticks longer than ``STALL_S``, flying on both sides): the
    largest distance [m/s] between the command and the vehicle's velocity over the ``SETTLE_S``
    from the first tick after it, where the command restarts on the vehicle
    (:mod:`mission.phases.stall`); the jump a stall can make (None: no stall). A tick whose
    vehicle sample is older than ``TELEMETRY_SILENT_S`` (``vehicle_age_s`` [s]; the link's thread
    stalled with the loop and has not read the vehicle again) is left out: its velocity is the
    one from before the gap, and the command then repeats the last one by design
    (:func:`mission.phases.stall.unread`), so the two say nothing of the restart."""
    flying = np.isin(phase, sorted(FLYING))
    after = np.flatnonzero((np.diff(t) > STALL_S) & flying[1:] & flying[:-1]) + 1
    read = np.ones(t.shape, dtype=bool) if vehicle_age_s is None else ~(vehicle_age_s > TELEMETRY_SILENT_S)
    offsets = [norm(u_cmd[k] - v_p[k]) for i in after
               for k in [np.flatnonzero((t >= t[i]) & (t < t[i] + SETTLE_S) & read)]]
    values = np.concatenate(offsets) if offsets else np.array([])
    return _nanmax(values) if len(values) else None


def _recovery_summary(r: FlightRecord, x_p: np.ndarray, v_p: np.ndarray, v_c: np.ndarray,
                      dock: np.ndarray) -> dict[str, Any]:
    """The recovery's figures (mission.final_action = "return"): docked_again, recovery_outcome,
    contact (from mission.json's ``recovered``; riding on a deck, a contact counts only once the
    passenger reported itself landed on it: ``confirmed_s``), carrier_speed_on_approach_m_s ([min, max] [m/s] of
    the carrier's horizontal speed during APPROACH) and deck_violations: ticks of the recovery's
    flying phases before contact where the vehicle was at or below the dock point's height within
    the deck (recovery.deck_radius_m) without meeting the contact conditions."""
    rec, params = r.info.get("recovered"), r.info.get("recovery")
    if r.info.get("final_action") != "return" or params is None:
        return {}
    contact = None if rec is None else rec.get("contact")
    if contact is not None and len(r.t) and contact.get("time_s") is not None and contact["time_s"] < r.t[0]:
        contact = None  # the last leg's, carried on into this one (riding on to its target): this leg has not docked
    # on a deck a dock is confirmed by the passenger's own landed state, never by the carrier's word
    unconfirmed = contact is not None and r.info.get("ride") == "deck" and "confirmed_s" not in contact
    out: dict[str, Any] = {"docked_again": contact is not None and not unconfirmed}
    if unconfirmed:
        out["recovery_outcome"] = "contact not confirmed: the passenger never reported itself landed on the deck"
    elif contact is not None:
        out["recovery_outcome"] = "docked"
    elif rec is not None and rec.get("fallback"):
        out["recovery_outcome"] = f"fallback: {rec['fallback']}"
    else:
        out["recovery_outcome"] = "not begun" if rec is None else "unfinished"
    out["contact"] = contact
    approach = (r.phase == Phase.APPROACH) & np.isfinite(v_c).all(axis=1)
    carrier_speed = np.hypot(v_c[approach, 0], v_c[approach, 1])  # [min, max] of the carrier's, on the approach
    out["carrier_speed_on_approach_m_s"] = ([_num(carrier_speed.min()), _num(carrier_speed.max())]
                                            if carrier_speed.size else None)
    before = np.isin(r.phase, [Phase.RETURNING, Phase.HOLDOFF, Phase.APPROACH, Phase.GO_AROUND])
    e, dv = x_p - dock, v_p - v_c
    horizontal, below = np.hypot(e[:, 0], e[:, 1]), e[:, 2] >= -params["contact_height_m"]
    out_of_contact = ((horizontal > params["contact_radius_m"])
                      | (np.hypot(dv[:, 0], dv[:, 1]) > params["contact_max_horizontal_speed_m_s"])
                      | (np.abs(dv[:, 2]) > params["contact_max_vertical_speed_m_s"]))
    on_deck = before & below & (horizontal <= params["deck_radius_m"]) & out_of_contact
    out["deck_violations"] = int(np.count_nonzero(on_deck & np.isfinite(e).all(axis=1)))
    return out
