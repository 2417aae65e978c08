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
from mission.phases.types import CarrierObs, Observation, my_turn
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


def test_carried_within_b_c_not_its_turn_it_rides_the_dock_velocity(model):  # noqa: F811
    """Carried within b c of its own target while the carrier announces another's, the riding
    law stays on its docked branch (P >= 0): the reference's velocity is the dock's, not the
    separating branch's P e_pt towards its target (which had a rider in the team's Monte-Carlo
    lag its dock point by more than the dock tolerance: P1 failed)."""
    seen = {}

    def elsewhere(k, obs):
        seen[k] = obs
        return replace(obs, carrier_target_ned_m=ELSEWHERE)

    _, log, _, _ = fly(model, ticks=1500, on_tick=elsewhere)
    inside = [k for k, (_, phase, dec) in enumerate(log) if phase is Phase.RIDING and dec.dock is not None
              and norm(model.tick.target - dec.dock) < model.tick.event_distance_m - 0.5]
    assert len(inside) > 50  # the carrier drove on well within b c of its target, the passenger riding
    for k in inside:
        dec = log[k][2]
        assert dec.P >= 0.0
        assert norm(dec.relative) == 0.0
        assert norm(dec.desired - seen[k].carrier.velocity_ned_m_s) < 1e-9  # u_p = u_c
    assert all(p is Phase.RIDING for _, p, _ in log[inside[0]:inside[-1] + 1])


def test_the_carrier_s_acceleration_is_predicted_towards_the_announced_target(model):  # noqa: F811
    """A rider carried for another's target feeds forward the acceleration of the carrier's law
    towards the target the carrier announces, not towards its own: at full speed straight at the
    announced target the carrier does not accelerate (towards its own, off to the side, the
    prediction turned it at the acceleration limit)."""
    from mission.phases.flying import _carrier_acceleration

    x_c = np.array([40.0, 30.0, 0.0])  # its own target lies 53 m west-south-west, the announced one 26 m south
    towards = ELSEWHERE - x_c
    towards[2] = 0.0
    v_c = towards / norm(towards) * model.tick.carrier_safety.max_speed_m_s
    obs = Observation(t_s=0.0, vehicle=None, carrier=CarrierObs(x_c, v_c, age_s=0.0))
    own = _carrier_acceleration(obs, model)
    assert norm(own) > 0.5  # its own target lies elsewhere: the law would turn the carrier there
    served = _carrier_acceleration(replace(obs, carrier_target_ned_m=ELSEWHERE), model)
    assert norm(served) < 1e-6
    assert norm(_carrier_acceleration(replace(obs, carrier_target_ned_m=model.tick.target.copy()), model) - own) == 0.0
