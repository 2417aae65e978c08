"""Flight-record figures: a leg that never separated has no separation figures and no crash; a
separated leg's input jump is its own command's step, apart from the carrier's velocity step."""

import numpy as np

from mission.phases.phase import Phase
from mission.record.figures import figures
from mission.record.table import COLUMNS, FlightRecord


def _record(phases: list[Phase], info: dict) -> FlightRecord:
    n = len(phases)
    cols = {c: np.zeros(n) for c in COLUMNS if c not in ("t_s", "phase", "mode")}
    cols["x_p_d"] = np.full(n, -1.0)
    return FlightRecord(t=np.arange(n) * 0.02, phase=np.array(phases, dtype=object), cols=cols, info=info)


def test_a_leg_that_aborted_before_separating_has_no_separation_figures():
    """A leg that aborts while riding and falls back: the mission reports ``separation_time_s``
    as None. The record's fallback ticks are not a separation, and the figures do not raise."""
    info = {"target_ned_m": [30.0, 0.0, -5.0], "separation_time_s": None}
    out = figures(_record([Phase.RIDING] * 20 + [Phase.FALLBACK] * 10, info))
    assert out["separation_time_s"] is None
    assert out["relative_input_jump_m_s"] is None


def test_a_separated_leg_counts_from_the_missions_separation_time():
    info = {"target_ned_m": [30.0, 0.0, -5.0], "separation_time_s": 0.30}
    out = figures(_record([Phase.RIDING] * 20 + [Phase.SEPARATED] * 10, info))
    assert out["separation_time_s"] == 0.30
    info.pop("separation_time_s")
    assert abs(figures(_record([Phase.RIDING] * 20 + [Phase.SEPARATED] * 10, info))["separation_time_s"] - 0.40) < 1e-9


def test_the_input_jump_is_the_commands_own_step_and_the_carriers_step_is_reported_beside():
    """At the separation tick the passenger brakes by 0.04 m/s while a new sample of the carrier's
    velocity steps by 0.03 m/s: the paper's jump (the passenger's input) is 0.04, the command relative
    to the carrier steps by both."""
    info = {"target_ned_m": [30.0, 0.0, -5.0], "separation_time_s": 0.40}
    rec = _record([Phase.RIDING] * 20 + [Phase.SEPARATED] * 10, info)
    rec.cols["v_c_n"][:] = 2.0
    rec.cols["v_c_n"][20:] = 2.03
    rec.cols["u_cmd_n"][:20] = 2.0
    rec.cols["u_cmd_n"][20:] = 2.0 - 0.04 * np.arange(1, 11)
    out = figures(rec)
    assert abs(out["input_jump_m_s"] - 0.04) < 1e-9
    assert abs(out["carrier_velocity_step_at_separation_m_s"] - 0.03) < 1e-9
    assert abs(out["relative_input_jump_m_s"] - 0.07) < 1e-9


def test_a_switch_inside_a_steady_turn_adds_nothing_and_a_jump_stands_out():
    """A command turning at 3 m/s^2 steps by 0.06 m/s on every tick: the step at the
    SEPARATED -> NAVIGATING switch is 0.06, its excess over the ticks beside it 0. The same
    switch with a 0.05 m/s jump on it has an excess of 0.05."""
    info = {"target_ned_m": [30.0, 0.0, -5.0], "separation_time_s": 0.10}
    phases = [Phase.RIDING] * 5 + [Phase.SEPARATED] * 10 + [Phase.NAVIGATING] * 10
    angle = 0.06 * np.arange(25)  # 1 m/s turning so that each tick steps by 0.06 m/s
    rec = _record(phases, info)
    rec.cols["u_cmd_n"][:], rec.cols["u_cmd_e"][:] = np.cos(angle), np.sin(angle)
    out = figures(rec)
    assert abs(out["max_phase_switch_jump_m_s"] - 0.06) < 1e-3
    assert abs(out["max_phase_switch_excess_m_s"]) < 1e-6
    rec.cols["u_cmd_n"][15:] -= 0.05 * np.sin(angle[15])  # the switch to NAVIGATING jumps by 0.05 along the turn
    rec.cols["u_cmd_e"][15:] += 0.05 * np.cos(angle[15])
    out = figures(rec)
    assert abs(out["max_phase_switch_jump_m_s"] - 0.11) < 2e-3
    assert abs(out["max_phase_switch_excess_m_s"] - 0.05) < 2e-3


RECOVERY_PARAMS = {"contact_height_m": 0.1, "contact_radius_m": 0.1, "contact_max_horizontal_speed_m_s": 0.2,
                   "contact_max_vertical_speed_m_s": 0.5, "deck_radius_m": 0.5}


def test_a_leg_riding_on_to_its_target_has_not_docked_on_the_last_legs_contact():
    """A leg after a dock rides on (TRANSIT) and the mission ends before it separates: the
    recovery the state still holds is the last leg's, whose contact came before this leg began.
    The leg reports no contact and an unfinished recovery (it reported the last leg's contact,
    docked, when a carrier that stood short of the next leg's start kept it riding until the
    mission's timeout); a contact inside the leg's own ticks is its own."""
    contact = {"horizontal_error_m": 0.06, "attempts": 1, "time_s": 0.1}
    info = {"target_ned_m": [30.0, 0.0, -5.0], "separation_time_s": None, "final_action": "return",
            "recovery": RECOVERY_PARAMS, "recovered": {"contact": contact}}
    rec = _record([Phase.TRANSIT] * 20, info)
    rec = FlightRecord(t=rec.t + 1.0, phase=rec.phase, cols=rec.cols, info=info)  # the leg began at 1.0 s
    out = figures(rec)
    assert out["docked_again"] is False and out["contact"] is None and out["recovery_outcome"] == "unfinished", out
    own = figures(FlightRecord(t=rec.t - 1.0, phase=rec.phase, cols=rec.cols, info=info))  # the contact at 0.1 s: its own
    assert own["docked_again"] is True and own["contact"] == contact and own["recovery_outcome"] == "docked", own
