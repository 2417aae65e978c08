"""The descent's relative-navigation gate ([relnav] enabled): a marker lost on the descent holds
the height above the deck, never on it; a vehicle already meeting the contact conditions docks;
a go-around forgets when the marker was lost."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from mission.config.schema import load_config
from mission.core.docking import gate_point
from mission.model import mission_model
from mission.phases import Phase
from mission.phases.recovery import approach, go_around
from mission.phases.types import CarrierObs, MissionState, Observation, RecoveryState, RelativeView, VehicleObs
from tests.conftest import CONFIGS

T = 100.0  # [s] the tick's time
LOST = RelativeView(position_ned_m=np.zeros(3), bias_ned_m=np.zeros(3), pending_ned_m=np.zeros(3),
                    position_sigma_m=0.02, converged=True, since_marker_s=2.0)  # marker not seen for 2 s


@pytest.fixture(scope="module")
def model():
    return mission_model(load_config(CONFIGS / "relnav.toml"))


def _at(model, height_m: float, descent: float, lost_s: float | None = None, east_m: float = 0.0):
    """The vehicle on the descent, ``height_m`` [m] over the dock point, exactly over it (or
    ``east_m`` [m] east of it), with the carrier's velocity; the carrier at the origin moving
    north at 1.5 m/s."""
    v_c = np.array([1.5, 0.0, 0.0])
    dock = np.zeros(3) + model.dock_offset_ned_m
    here = dock + np.array([0.0, east_m, -height_m])
    carrier = CarrierObs(position_ned_m=np.zeros(3), velocity_ned_m_s=v_c, age_s=0.0, alive=True, yaw_rad=0.0)
    vehicle = VehicleObs(position_ned_m=here, velocity_ned_m_s=v_c.copy(), armed=True, mode="OFFBOARD",
                         heartbeat_age_s=0.0)
    rec = RecoveryState(started_s=0.0, why="task done", attempts=1, s=1.0, descent=descent, marker_lost_s=lost_s,
                        carrier_samples=((T - 0.1, float(v_c[0]), float(v_c[1]), math.nan),), carrier_seen_s=T)
    state = MissionState(phase=Phase.APPROACH, since_s=T - 5.0, start_s=0.0, x_ref=here.copy(), u_ref=v_c.copy(),
                         recovery=rec, separation_time_s=10.0)
    return state, Observation(t_s=T, vehicle=vehicle, carrier=carrier, relative=LOST), dock


def test_a_marker_lost_in_the_last_centimetres_holds_above_the_deck_not_on_it(model):
    """Lost with the vehicle 0.2 m over the dock point (out of the contact band, descent nearly
    done): the reference is held at least three contact heights over the deck, not at deck
    height (on the old code it was held where the descent had got to: on the deck)."""
    g = model.recovery.geometry
    state, obs, dock = _at(model, 0.2, descent=0.98)
    new, dec = approach(state, obs, model)
    assert new.phase is Phase.APPROACH and new.recovery.marker_lost_s == T
    held = gate_point(dock, g) + new.recovery.descent * (dock - gate_point(dock, g))
    assert dock[2] - held[2] >= 3 * g.contact_height_m - 1e-9, held - dock  # over the deck by >= 3 contact heights
    assert new.recovery.contact is None


def test_a_vehicle_meeting_the_contact_conditions_docks_even_with_the_marker_just_lost(model):
    """Lost with the vehicle already within the contact band over the dock point: it docks (the
    old code held it there, on the deck, and never checked the contact)."""
    state, obs, _ = _at(model, 0.05, descent=1.0)
    new, dec = approach(state, obs, model)
    assert new.phase is Phase.DOCKED and new.recovery.contact is not None, dec.events


def test_a_go_around_forgets_when_the_marker_was_lost(model):
    """The marker lost on one descent: the go-around resets it, so the next descent's search
    for the marker starts afresh (on the old code it went around at once on the next loss)."""
    state, obs, _ = _at(model, 0.4, descent=0.3, lost_s=T - 1.0)
    new, _ = go_around(state, obs, model, "test")
    assert new.phase is Phase.GO_AROUND and new.recovery.marker_lost_s is None
    # the next approach's descent loses the marker again: it holds (a search), no go-around at once
    later, obs2, _ = _at(model, 0.4, descent=0.3)
    again, dec = approach(replace(later, recovery=replace(new.recovery, s=1.0, descent=0.3)), obs2, model)
    assert again.phase is Phase.APPROACH and again.recovery.marker_lost_s == T, dec.events


def test_a_descent_that_never_reaches_the_deck_goes_around_after_its_budget(model):
    """Every pause of the descent has its own timer (out of line: gate_timeout_s; the marker
    lost: search_s), and a vehicle that keeps coming back in line for a moment restarts them:
    in the relnav Monte-Carlo one descent hovered 0.3-0.45 m over the deck for 120 s. The whole
    descent has a budget (descent_budget_s: 24 s here): in line, 0.4 m over the dock point, not
    blocked, it still descends within it and goes around once past it, the go-around forgetting
    when the descent began."""
    from mission.phases.recovery import descent_budget_s

    budget = descent_budget_s(model)
    r = model.recovery
    assert budget == pytest.approx(2 * r.geometry.decision_height_m / r.descent_speed_m_s + 2 * r.gate_timeout_s
                                   + model.relnav.search_s)
    seen = replace(LOST, since_marker_s=0.0)
    state, obs, _ = _at(model, 0.4, descent=1.0)
    obs = replace(obs, relative=seen)
    within = replace(state, recovery=replace(state.recovery, descent_since_s=T - budget + 0.1))
    new, dec = approach(within, obs, model)
    assert new.phase is Phase.APPROACH, dec.events
    past = replace(state, recovery=replace(state.recovery, descent_since_s=T - budget - 0.1))
    new, dec = approach(past, obs, model)
    assert new.phase is Phase.GO_AROUND and new.recovery.descent_since_s is None
    assert any("the descent did not reach the deck within" in e for e in dec.events), dec.events


SEEN = replace(LOST, since_marker_s=0.0)


def _descent_after_one_tick(model, height_m: float, east_m: float = 0.0, relative=SEEN):
    g = model.recovery.geometry
    state, obs, _ = _at(model, height_m, descent=1.0 - height_m / g.decision_height_m, east_m=east_m)
    new, dec = approach(state, replace(obs, relative=relative), model)
    assert new.phase is Phase.APPROACH, dec.events
    return state.recovery.descent, new.recovery.descent


def test_the_last_contact_heights_are_descended_slower(model):
    """From three contact heights over the dock point the reference descends at
    recovery.final_descent_speed_m_s (0.15 m/s), above them at descent_speed_m_s (0.3 m/s). At
    0.3 m/s all the way the vehicle crossed the contact band at a true 0.53-0.58 m/s, over the
    contact conditions' 0.5 (relnav Monte-Carlo: its vertical speed swings +-0.25 m/s round the
    asked one)."""
    r, g = model.recovery, model.recovery.geometry
    assert r.final_descent_speed_m_s == pytest.approx(0.15)
    high = _descent_after_one_tick(model, 0.45)
    low = _descent_after_one_tick(model, 0.25)
    assert (high[1] - high[0]) * g.decision_height_m / model.dt_s == pytest.approx(r.descent_speed_m_s)
    assert (low[1] - low[0]) * g.decision_height_m / model.dt_s == pytest.approx(r.final_descent_speed_m_s)


def test_below_three_contact_heights_only_lined_up_with_a_margin(model):
    """0.08 m off the dock point (inside the 0.10 m contact radius, outside its 0.07 m with the
    0.3 margin): at 0.301 m and at 0.25 m over it the reference pauses where it is, at 0.15 m it
    goes back up to two contact heights, no go-around; 0.05 m off, it goes on down. Without the
    margin the vehicle entered the contact band 0.099-0.106 m off by the truth and sat in it, out
    of the contact conditions."""
    g = model.recovery.geometry
    pause = 1.0 - 2.0 * g.contact_height_m / g.decision_height_m
    for height in (0.301, 0.25):
        before, after = _descent_after_one_tick(model, height, east_m=0.08)
        assert after == pytest.approx(before), height
    before, after = _descent_after_one_tick(model, 0.15, east_m=0.08)
    assert after == pytest.approx(pause)
    before, after = _descent_after_one_tick(model, 0.15, east_m=0.05)
    assert after > before


def test_a_marker_lost_on_the_descent_climbs_back_to_the_gate(model):
    """Blind, the relative height drifts with the vehicle's own height estimate (0.65 m in 1.5 s
    in the Monte-Carlo, the vehicle then 0.3 m under the dock point while it read 0.3 m over):
    the reference's goal goes back to the gate instead of holding the height."""
    g = model.recovery.geometry
    state, obs, dock = _at(model, 0.4, descent=1.0 - 0.4 / g.decision_height_m)
    new, dec = approach(state, obs, model)
    assert new.phase is Phase.APPROACH and new.recovery.descent == 0.0, dec.events
    assert new.x_ref[2] < state.x_ref[2]  # the reference already climbs


def test_the_reference_floor_is_over_the_ground_the_passenger_sees(model):
    """The passenger's own height estimate 1.8 m off (the relnav Monte-Carlo: its GNSS bias and
    PX4's error, 1.7-2.3 m in scenario 63): the carrier, on the ground, reads 1.8 m down in its
    frame, the dock point under the altitude floor fixed in it (safety.z_max_m = -0.5). The
    reference's floor moves over that ground, as the command's does: the descent goes on down
    (on the old code the reference sat on the floor at -0.500 m for 24 s and the approach went
    around on the descent's budget, three times in scenarios 98 and 129, which never docked)."""
    g = model.recovery.geometry
    state, obs, dock = _at(model, 0.4, descent=1.0 - 0.4 / g.decision_height_m)
    low = np.array([0.0, 0.0, 1.8])  # the ground 1.8 m down in the passenger's frame
    carrier = replace(obs.carrier, position_ned_m=obs.carrier.position_ned_m + low)
    vehicle = replace(obs.vehicle, position_ned_m=obs.vehicle.position_ned_m + low)
    state = replace(state, x_ref=state.x_ref + low)
    assert state.x_ref[2] > model.command_safety.z_max_m  # under the floor fixed in its frame
    new, dec = approach(state, replace(obs, carrier=carrier, vehicle=vehicle, relative=SEEN), model)
    assert new.phase is Phase.APPROACH, dec.events
    assert new.u_ref[2] > 0.0, new.u_ref  # going down, not pushed up to the floor


def test_a_marker_lost_below_the_decision_height_climbs_at_the_descent_timeout(model):
    """Below the decision height the marker counts as lost after relnav.descent_marker_timeout_s
    (0.25 s), not the gate's marker_timeout_s (0.5 s): 0.3 s after its last capture the vehicle
    0.2 m over the deck climbs back to the gate. In the Monte-Carlo the relative height had
    drifted 0.15-0.28 m by 0.5 s (PX4's vertical velocity error, 0.3 m/s), and the vehicle met
    the contact band out of the contact conditions before the climb began (scenarios 24, 35, 99,
    118, 192: 45-51 ticks each; 0-8 with the shorter timeout)."""
    relnav = model.relnav
    assert relnav.descent_marker_timeout_s < 0.3 < relnav.marker_timeout_s
    g = model.recovery.geometry
    state, obs, dock = _at(model, 0.2, descent=1.0 - 0.2 / g.decision_height_m)
    new, dec = approach(state, replace(obs, relative=replace(LOST, since_marker_s=0.3)), model)
    assert new.phase is Phase.APPROACH and new.recovery.descent == 0.0 and new.recovery.marker_lost_s == T, dec.events
    assert new.u_ref[2] < state.u_ref[2]  # the reference turns upwards at once
    # the gate itself still waits for marker_timeout_s: 0.3 s is in sight there
    assert relnav.descent_blocked(replace(LOST, since_marker_s=0.3)) is None


def test_a_marker_lost_out_of_line_climbs_rather_than_holds(model):
    """Blind and 0.12 m off the dock point by the estimate (out of the 0.10 m contact radius):
    the climb to the gate goes ahead of the out-of-line hold at three contact heights, whose
    horizontal error is the drifted estimate's (scenarios 35 and 118: held 0.3 m over the deck
    by the estimate, the truth 0.1 m over it and 0.15 m off)."""
    g = model.recovery.geometry
    state, obs, dock = _at(model, 0.25, descent=1.0 - 0.25 / g.decision_height_m, east_m=0.12)
    # out of line for 4 s already (gate_timeout_s 5): the climb restarts that pause's timer, else a
    # vehicle out of line for a moment once the marker is back went round at once (scenarios 40, 103)
    state = replace(state, recovery=replace(state.recovery, settled_since_s=T - 4.0))
    new, dec = approach(state, obs, model)
    assert new.phase is Phase.APPROACH, dec.events
    assert new.recovery.descent == 0.0 and new.recovery.marker_lost_s == T
    assert new.recovery.settled_since_s is None  # not the out-of-line pause


def test_the_marker_back_the_descent_goes_on_from_where_the_reference_climbed_to(model):
    """After a climb for a lost marker the descent resumes from the reference's height (0.4 m
    over the deck here), not from the gate: with 10 % of the time blind, a descent restarted
    from the gate at every loss would spend its budget."""
    g = model.recovery.geometry
    state, obs, dock = _at(model, 0.4, descent=0.0, lost_s=T - 0.5)
    new, dec = approach(state, replace(obs, relative=SEEN), model)
    assert new.phase is Phase.APPROACH and new.recovery.marker_lost_s is None, dec.events
    resumed = 1.0 - 0.4 / g.decision_height_m
    step = model.recovery.descent_speed_m_s * model.dt_s / g.decision_height_m
    assert new.recovery.descent == pytest.approx(resumed + step)
    # from under three contact heights it resumes from them: the marker's correction of the
    # drifted estimate is still being let through (scenarios 15, 16: resumed 0.2 m over the deck,
    # the vehicle crossed the contact band at 0.54-0.61 m/s)
    low, obs, dock = _at(model, 0.2, descent=0.0, lost_s=T - 0.5)
    new, dec = approach(low, replace(obs, relative=SEEN), model)
    slow_from = 1.0 - 3.0 * g.contact_height_m / g.decision_height_m
    final = model.recovery.final_descent_speed_m_s * model.dt_s / g.decision_height_m
    assert new.recovery.descent == pytest.approx(slow_from + final), dec.events


def test_the_riding_reference_floor_is_over_the_ground_the_passenger_sees(model):
    """Riding with the passenger's own height estimate 2.2 m off (the relnav Monte-Carlo's
    scenario 63: the ground 2.2 m down in its frame, the dock point 0.7 m under it, under the
    altitude floor safety.z_max_m = -0.5 fixed in its frame). The riding law's reference filter
    has its floor over that ground, as the command's: the reference rides the dock point's
    velocity (on the old code the barrier asked it 1.2 m/s up, the vehicle rose 0.6 m off the
    dock point and P1 failed)."""
    from mission.phases.flying import riding

    ground = np.array([0.0, 0.0, 2.2])
    v_c = np.array([1.0, 0.0, 0.0])
    carrier = CarrierObs(position_ned_m=ground.copy(), velocity_ned_m_s=v_c, age_s=0.0, alive=True, yaw_rad=0.0)
    dock = ground + model.dock_offset_ned_m
    assert dock[2] > model.tick.passenger_safety.z_max_m  # under the floor fixed in its frame
    vehicle = VehicleObs(position_ned_m=dock.copy(), velocity_ned_m_s=v_c.copy(), armed=True, mode="OFFBOARD",
                         heartbeat_age_s=0.0)
    state = MissionState(phase=Phase.RIDING, since_s=T - 5.0, start_s=0.0, x_ref=dock.copy(), u_ref=v_c.copy(),
                         prev_dock=dock - v_c * model.dt_s, separation_time_s=None)
    new, dec = riding(state, Observation(t_s=T, vehicle=vehicle, carrier=carrier, relative=SEEN), model)
    assert new.phase is Phase.RIDING, dec.events
    assert abs(new.u_ref[2]) < 0.05, new.u_ref  # the dock's velocity, no climb
    assert new.u_ref[0] == pytest.approx(v_c[0], abs=0.05)




def test_below_three_contact_heights_the_reference_waits_for_the_vehicle(model):
    """The vehicle 0.25 m over the dock point, its reference 0.16 m below it (its vertical swing
    left it behind): with recovery.final_descent_lag_m 0.1 the reference is held 0.1 m below the
    vehicle and the descent waits; unset, the reference stays 0.16 m below and the descent goes
    on (the lead then sent the position 0.58 m below the vehicle, and such vehicles crossed the
    contact band at 0.5-0.7 m/s in the relnav Monte-Carlo). A reference within the lag, or above
    three contact heights, is not held."""
    g = model.recovery.geometry
    held_model = replace(model, recovery=replace(model.recovery, final_descent_lag_m=0.1))
    free_model = replace(model, recovery=replace(model.recovery, final_descent_lag_m=None))
    for height, lag, held in ((0.25, 0.16, True), (0.25, 0.05, False), (0.6, 0.16, False)):
        state, obs, dock = _at(model, height, descent=1.0 - (height - lag) / g.decision_height_m)
        state = replace(state, x_ref=state.x_ref + np.array([0.0, 0.0, lag]))
        x_p = obs.vehicle.position_ned_m
        for m, bounded in ((held_model, held), (free_model, False)):
            new, dec = approach(state, replace(obs, relative=SEEN), m)
            assert new.phase is Phase.APPROACH, dec.events
            below = new.x_ref[2] - x_p[2]  # [m] the reference under the vehicle after the tick
            if bounded:
                assert below == pytest.approx(0.1, abs=abs(new.u_ref[2]) * m.dt_s + 1e-9), (height, lag)
                assert new.recovery.descent < state.recovery.descent
            else:
                assert below > lag - 0.01, (height, lag, m.recovery.final_descent_lag_m)
                assert new.recovery.descent > state.recovery.descent


def test_over_the_deck_the_acceleration_sent_damps_with_the_near_deck_damping(model):
    """configs/relnav.toml's mission.near_deck_damping_per_s (7.2 /s, the tracking's 1.8 elsewhere):
    on the approach the acceleration sent carries -7.2 (v_p - u_ref), against -1.8 with it unset.
    The loop closing on the marker rang +-0.2 m/s sideways against the deck at about 0.6 Hz under
    a steady command (docs/relnav.md, "Damping the last decimetre")."""
    from mission.phases.flying import NEAR_DECK_DAMPED

    assert NEAR_DECK_DAMPED == {Phase.HOLDOFF, Phase.APPROACH}
    near, damping = model.near_deck_damping_per_s, model.tracking.damping_per_s
    assert near is not None and near > damping > 0
    state, obs, _ = _at(model, 0.25, descent=1.0 - 0.25 / model.recovery.geometry.decision_height_m)
    state = replace(state, u_cmd=obs.vehicle.velocity_ned_m_s.copy())  # the last command: the carrier's velocity
    v_p = obs.vehicle.velocity_ned_m_s + np.array([0.0, 0.08, 0.0])  # 0.08 m/s east of the carrier's velocity
    obs = replace(obs, vehicle=replace(obs.vehicle, velocity_ned_m_s=v_p), relative=SEEN)
    damped, dec = approach(state, obs, model)
    plain, dec_plain = approach(state, obs, replace(model, near_deck_damping_per_s=None))
    assert damped.phase is plain.phase is Phase.APPROACH and dec.setpoint.full and dec_plain.setpoint.full
    np.testing.assert_allclose(damped.u_ref, plain.u_ref)  # the reference does not depend on it
    extra = dec.setpoint.acceleration_ned_m_s2 - dec_plain.setpoint.acceleration_ned_m_s2
    np.testing.assert_allclose(extra, -(near - damping) * (v_p - damped.u_ref), atol=1e-9)
