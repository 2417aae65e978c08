"""The deck watched while seated (mission.phases.deck.watch): a rogue that arms the carried
passenger, switches its mode or lifts it off the deck, without the mission asking, is a fault
(deck_disturbed): nothing more is sent, the carrier is told, and that flight is never taken for a
take-off. The kinematic deck world of test_deck_ride.py."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mission.phases import AbortReason, Phase
from tests.unit.phases.test_deck_ride import fly, model  # noqa: F401  (model: the module's fixture)

ROGUE_AT = 100  # [ticks]: 2 s into the ride, long before the mission streams to arm


def _rogue(change):
    def on_tick(k, obs, state, armed):
        if state.phase == Phase.RIDING and state.streaming_since_s is None and k >= ROGUE_AT:
            return change(obs), armed
        return obs, armed
    return on_tick


@pytest.mark.parametrize("change, detail", [
    (lambda obs: replace(obs, vehicle=replace(obs.vehicle, armed=True)), "armed on the deck"),
    (lambda obs: replace(obs, vehicle=replace(obs.vehicle, mode="AUTO.TAKEOFF")), "switched from AUTO.LOITER to AUTO.TAKEOFF"),
    (lambda obs: replace(obs, vehicle=replace(obs.vehicle, position_ned_m=obs.vehicle.position_ned_m + np.array([0, 0, -2.0]))),
     "above the deck"),
], ids=["armed", "mode", "lifted"])
def test_a_seated_passenger_disturbed_without_the_mission_asking_is_a_fault(model, change, detail):  # noqa: F811
    state, log = fly(model, on_tick=_rogue(change))
    assert state.phase == Phase.ABORT and state.reason == AbortReason.DECK_DISTURBED, (state.phase, state.reason)
    assert detail in state.detail
    abort = next(i for i, (_, s, *_) in enumerate(log) if s.phase == Phase.ABORT)
    assert all(dec.setpoint is None and dec.request is None for _, _, dec, *_ in log[abort:])  # hands off
    assert not any(s.phase in (Phase.SEPARATED, Phase.NAVIGATING) for _, s, *_ in log)  # never a take-off
    assert all(dec.setpoint is None for _, s, dec, *_ in log[:abort] if s.phase == Phase.RIDING)  # nothing streamed to it


def test_while_the_mission_arms_it_another_mode_or_a_lift_is_still_a_fault(model):  # noqa: F811
    def rogue(k, obs, state, armed):
        if state.phase == Phase.RIDING and state.streaming_since_s is not None and obs.t_s - state.streaming_since_s > 0.5:
            return replace(obs, vehicle=replace(obs.vehicle, mode="AUTO.TAKEOFF")), armed
        return obs, armed

    state, log = fly(model, on_tick=rogue)
    assert state.phase == Phase.ABORT and state.reason == AbortReason.DECK_DISTURBED
    assert "to AUTO.TAKEOFF" in state.detail
    assert not any(s.phase in (Phase.SEPARATED, Phase.NAVIGATING) for _, s, *_ in log)


def test_the_mission_s_own_arming_and_take_off_are_no_fault(model):  # noqa: F811
    state, log = fly(model)
    assert any(s.phase == Phase.ARRIVED for _, s, *_ in log) and state.reason is None
