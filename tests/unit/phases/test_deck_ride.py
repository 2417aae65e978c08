"""Riding on the deck (mission.ride = "deck"), driven by synthetic observations (pure, no sockets):
seated and disarmed while carried, armed within mission.arm_lead_s of the separation, the take-off
with the deck's keep-out, and the forced-disarm failsafe that waits until the deck is cleared."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mission.config.schema import load_config
from mission.controller import mission_model
from mission.core.law import norm
from mission.phases import AbortReason, CarrierObs, MissionState, Observation, Phase, VehicleObs, finished, step
from tests.conftest import CONFIGS

DECK = np.array([0.0, 0.0, -0.5])  # the deck (the dock point) above the carrier's position [m] NED


@pytest.fixture(scope="module")
def model():
    """demo.toml's mission riding a deck 0.5 m up, flown by velocity setpoints (the world below
    integrates the setpoint as a velocity)."""
    cfg = load_config(CONFIGS / "demo.toml")
    mission = cfg.mission.model_copy(update={"setpoint": "velocity", "track_gain": 1.5, "position_lead": 0.0,
                                             "drag_ff_per_s": 0.0, "integral_gain": 0.0, "ride": "deck",
                                             "dock_offset_ned_m": list(DECK)})
    safety = cfg.safety.model_copy(update={"z_max_m": -0.3})
    return mission_model(cfg.model_copy(update={"mission": mission, "safety": safety}))


def fly(model, *, ticks=3000, on_tick=None):
    """A kinematic world with a deck: the vehicle sits on the deck (moving with it) until it is
    armed in OFFBOARD and its setpoint climbs; the carrier drives at 2 m/s towards the target while
    the machine's phase carries (RIDING), and stops otherwise (at most 1 m/s^2 either way)."""
    dt = model.dt_s
    x_c, v_c = np.zeros(3), np.zeros(3)
    x_p, v_p = x_c + DECK, np.zeros(3)
    mode, armed, on_deck = "AUTO.LOITER", False, True
    state = MissionState()
    log = []
    for k in range(ticks):
        t = k * dt
        vehicle = VehicleObs(x_p.copy(), v_p.copy(), armed, mode, heartbeat_age_s=0.1, on_ground=on_deck)
        obs = Observation(t_s=t, vehicle=vehicle, carrier=CarrierObs(x_c.copy(), v_c.copy(), age_s=0.0))
        if on_tick:
            obs, armed = on_tick(k, obs, state, armed)
        state, dec = step(state, obs, model)
        log.append((t, state, dec, x_p.copy(), x_c.copy(), v_c.copy()))
        if dec.request == "arm":
            armed = True
        elif dec.request == "offboard" and armed:
            mode = "OFFBOARD"
        elif dec.request == "disarm" and on_deck:
            armed = False
        want = np.zeros(3)
        if state.phase == Phase.RIDING:
            e = model.tick.target - x_c
            e[2] = 0.0
            want = e / norm(e) * 2.0
        dv = want - v_c  # the carrier's acceleration limit, 1 m/s^2
        v_c = v_c + dv * min(1.0, 1.0 * dt / max(float(norm(dv)), 1e-12))
        x_c = x_c + v_c * dt
        sp = dec.setpoint
        flying = armed and mode == "OFFBOARD" and sp is not None
        if on_deck and flying and sp.velocity_ned_m_s[2] < 0:
            on_deck = False
        if on_deck:
            x_p, v_p = x_c + DECK, v_c.copy()
        else:
            v_p = sp.velocity_ned_m_s if flying else np.zeros(3)
            x_p = x_p + v_p * dt
        if finished(state, dec):
            break
    return state, log


def test_carried_disarmed_then_armed_within_the_lead_and_latched_at_bc(model):
    state, log = fly(model)
    phases = list(dict.fromkeys(s.phase for _, s, _, _, _, _ in log))
    assert phases[:5] == [Phase.STREAMING, Phase.RIDING, Phase.SEPARATED, Phase.NAVIGATING, Phase.ARRIVED]
    assert norm(model.tick.target - state.anchor) == pytest.approx(model.tick.event_distance_m, abs=1e-9)
    sep = next(i for i, (_, s, *_) in enumerate(log) if s.phase == Phase.SEPARATED)
    riding = [i for i, (_, s, *_) in enumerate(log) if s.phase == Phase.RIDING]
    first_sp = next(i for i in riding if log[i][2].setpoint is not None)
    first_arm = next(i for i in riding if log[i][2].request == "arm")
    dt = model.dt_s
    # nothing is sent while carried, until arm_lead_s before the separation; arming waits prestream_s
    assert all(log[i][2].setpoint is None for i in riding if i < first_sp)
    # (predicted at the present closing speed: with the target above the carrier's plane |e_tc|
    # closes ever slower, so the stream starts a little earlier than the lead)
    assert model.deck.arm_lead_s <= (sep - first_sp) * dt <= model.deck.arm_lead_s + 0.5
    assert (first_arm - first_sp) * dt == pytest.approx(model.prestream_s, abs=dt)
    assert (sep - first_arm) * dt < 10.0  # inside PX4's COM_DISARM_PRFLT
    # the relative command: no jump from the first setpoint streamed on the deck through the take-off
    rel = np.array([log[i][2].setpoint.velocity_ned_m_s - log[i][5] for i in range(first_sp, sep + 150)])
    assert np.abs(np.diff(rel, axis=0)).max() <= 0.05


def test_it_clears_the_deck_before_it_moves_out_sideways(model):
    """Taking off: below deck_clear_height_m over the deck the vehicle stays within the funnel the
    keep-out stands on the dock point (radius + slope x height), whatever the law asks."""
    state, log = fly(model)
    sep = next(i for i, (_, s, *_) in enumerate(log) if s.phase == Phase.SEPARATED)
    d = model.deck
    checked = 0
    for _, s, _, x_p, x_c, _ in log[sep:]:
        deck = x_c + DECK
        height = deck[2] - x_p[2]
        if height >= d.clear_height_m:
            break
        r = float(np.hypot(*(x_p - deck)[:2]))
        assert r <= d.keep_out_radius_m + d.slope * max(height, 0.0) + 0.03, (height, r)
        checked += 1
    assert checked > 10
    cleared = next(s for _, s, *_ in log[sep:] if not s.seated)
    assert cleared.phase in (Phase.SEPARATED, Phase.NAVIGATING)


def test_a_disarm_on_the_deck_is_no_fault_but_in_the_take_off_it_is(model):
    """PX4 disarms a seated vehicle that waits for the separation (COM_DISARM_PRFLT): it is armed
    again. Disarmed while taking off (still seated, after the latch): vehicle_disarmed."""
    def preflight_disarm(k, obs, state, armed):
        if state.phase == Phase.RIDING and state.streaming_since_s is not None and armed \
                and obs.t_s - state.streaming_since_s > 2.0 and not getattr(preflight_disarm, "done", False):
            preflight_disarm.done = True  # type: ignore[attr-defined]
            return replace(obs, vehicle=replace(obs.vehicle, armed=False)), False
        return obs, armed

    state, log = fly(model, on_tick=preflight_disarm)
    assert getattr(preflight_disarm, "done", False)
    assert any(s.phase == Phase.ARRIVED for _, s, *_ in log) and state.phase != Phase.ABORT

    def disarm_in_take_off(k, obs, state, armed):
        if state.phase == Phase.SEPARATED:
            return replace(obs, vehicle=replace(obs.vehicle, armed=False)), False
        return obs, armed

    state, _ = fly(model, on_tick=disarm_in_take_off)
    assert state.phase == Phase.ABORT and state.reason == AbortReason.VEHICLE_DISARMED
    assert "taking off from the deck" in state.detail


def test_landed_on_the_deck_is_where_it_is_until_it_cleared_it(model):
    """ON_GROUND while seated (on the deck, taking off) aborts nothing; once the vehicle has
    cleared the deck, ON_GROUND is PX4's forced landing again: vehicle_disarmed."""
    def landed_after_clearing(k, obs, state, armed):
        if state.phase == Phase.NAVIGATING and not state.seated:
            return replace(obs, vehicle=replace(obs.vehicle, on_ground=True)), armed
        return obs, armed

    state, _ = fly(model, on_tick=landed_after_clearing)
    assert state.phase == Phase.ABORT and state.reason == AbortReason.VEHICLE_DISARMED
    assert "ON_GROUND" in state.detail


def test_not_armed_when_the_separation_comes_aborts_and_stops_the_carrier(model):
    def refuse(k, obs, state, armed):
        return obs, False  # the arm request never takes

    state, log = fly(model, on_tick=refuse)
    assert state.phase == Phase.ABORT and state.reason == AbortReason.ARMING_REFUSED
    assert "separation" in state.detail


def test_an_untrusted_carrier_feed_holds_on_the_deck_and_never_disarms_a_waiting_passenger(model):
    """While the feed does not trust the carrier (just bound, a resync): the passenger says it
    holds (the carrier pauses), the latch waits, and a passenger armed for its take-off is not
    asked to disarm (it follows the deck as it feels it)."""
    window: dict[str, float] = {}

    def distrust(k, obs, state, armed):
        if state.phase == Phase.RIDING and state.streaming_since_s is not None and armed and "t0" not in window:
            window["t0"] = obs.t_s
        if "t0" in window and obs.t_s - window["t0"] < 1.0:
            return replace(obs, carrier=replace(obs.carrier, untrusted="resync")), armed
        return obs, armed

    state, log = fly(model, on_tick=distrust)
    held = [(s, d) for t, s, d, *_ in log if "t0" in window and window["t0"] <= t < window["t0"] + 1.0]
    assert held and all(s.held_dock is not None for s, _ in held)
    assert all(d.request != "disarm" and s.phase == Phase.RIDING for s, d in held)
    assert any(s.phase == Phase.ARRIVED for _, s, *_ in log)  # trusted again: it separated and flew
