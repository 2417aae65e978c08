"""A passenger's turn (mission/phases/types.py: my_turn): the latch waits until the carrier
announces this passenger's target (a team's carrier serving another passenger may pass within
b c of it); no announcement, one passenger, is always its turn. Driven by the synthetic world of
test_phases (the carrier drives at 2 m/s towards the target while the machine says RIDING)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from mission.core.law import norm
from mission.passenger.inputs import PassengerInputs
from mission.passenger.step import PassengerStep
from mission.phases import Phase
from mission.phases.types import Observation, my_turn
from tests.unit.phases.test_phases import fly, model  # noqa: F401  (the module's fixture)

ELSEWHERE = np.array([44.0, 4.0, -4.0])  # another passenger's target


def _first(log, phase):
    return next((k for k, (_, p, _) in enumerate(log) if p is phase), None)


def test_no_announcement_is_always_its_turn(model):  # noqa: F811
    obs = Observation(t_s=0.0, vehicle=None, carrier=None)
    assert my_turn(obs, model)
    assert my_turn(replace(obs, carrier_target_ned_m=np.asarray(model.tick.target) + 5e-4), model)
    assert not my_turn(replace(obs, carrier_target_ned_m=ELSEWHERE), model)


def test_the_latch_waits_for_the_passenger_s_turn(model):  # noqa: F811
    _, alone, _, _ = fly(model, ticks=3000)
    k_alone = _first(alone, Phase.SEPARATED)
    assert k_alone is not None
    turn_at = k_alone + 100  # the carrier announces this passenger's target only 2 s later

    def announce(k, obs):
        return replace(obs, carrier_target_ned_m=model.tick.target.copy() if k >= turn_at else ELSEWHERE)

    state, log, _, _ = fly(model, ticks=3000, on_tick=announce)
    k = _first(log, Phase.SEPARATED)
    assert _first(log[:turn_at], Phase.SEPARATED) is None  # within b c of its target, not its turn: it rides on
    assert k == turn_at  # its turn: the latch fires on that tick
    assert norm(model.tick.target - state.anchor) < model.tick.event_distance_m  # the carrier had gone on past b c
    assert state.phase is Phase.DONE


def test_the_step_passes_the_announcement_to_the_phases(model):  # noqa: F811
    step = PassengerStep(model)
    obs = step.observe(PassengerInputs(1.0, None, None, carrier_target_ned_m=ELSEWHERE))
    assert obs.carrier_target_ned_m is ELSEWHERE
    assert step.observe(PassengerInputs(1.0, None, None)).carrier_target_ned_m is None
