"""The recovery queue in the team flown in-process (`marsupial simulate configs/team.toml`,
sim/batch/team_mission.py; docs/team.md "The recovery queue"): one passenger on the deck's
approach at a time, in the order asked (or the battery's), each docked at its first approach on
a carrier that keeps one recovery course, the waiting one clear of the approaching one, and no
step of the command over 0.05 m/s at a phase switch or a switch of the queue."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from mission.config.schema import load_config
from mission.phases import Phase
from sim.batch.team_mission import TeamWorld
from sim.vehicle.estimator import PX4_SITL_SCALE
from tests.conftest import CONFIGS
from tests.unit.batch.test_team_mission import assert_no_phase_switch_jump

pytestmark = pytest.mark.timeout(600)  # two team missions in-process, about 10 s of CPU each

STEP_MAX_M_S = 0.05  # [m/s] the most the command may step at a switch (docs/team.md)
ON_APPROACH = {Phase.APPROACH, Phase.DOCKED}


@dataclass
class Flight:
    world: TeamWorld
    docked: list[str]  # who entered DOCKED, in order
    both_on_approach: int  # ticks with two passengers on the deck's approach
    queue_step_m_s: float  # the largest reference step at a switch of the queue [m/s]
    phase_step_m_s: float  # the largest command step at a phase switch [m/s]
    waiting_gap_m: float  # the least true distance of a waiting passenger from one on the deck's approach [m]
    events: dict[str, list[str]]


def fly(batteries=None) -> Flight:
    w = TeamWorld(load_config(CONFIGS / "team.toml"), estimate_error=PX4_SITL_SCALE, seed=0, batteries=batteries)
    n = len(w.members)
    docked: list[str] = []
    both, q_step, p_step, gap = 0, 0.0, 0.0, np.inf
    prev = [(m.state.phase, None, False, None) for m in w.members]
    while not w.done:
        w.tick()
        x = [m.vehicle.true_position for m in w.members]
        on = [m.state.phase in ON_APPROACH for m in w.members]
        both += sum(on) > 1
        for i, m in enumerate(w.members):
            rec = m.state.recovery
            queued = rec is not None and rec.queued_since_s is not None
            u_ref = None if m.state.u_ref is None else np.array(m.state.u_ref)
            u_cmd = None if m.state.u_cmd is None else np.array(m.state.u_cmd)
            phase0, u_ref0, queued0, u_cmd0 = prev[i]
            if queued != queued0 and u_ref is not None and u_ref0 is not None:
                q_step = max(q_step, float(np.linalg.norm(u_ref - u_ref0)))
            if m.state.phase != phase0 and m.state.phase.flying and phase0.flying and u_cmd is not None \
                    and u_cmd0 is not None:
                p_step = max(p_step, float(np.linalg.norm(u_cmd - u_cmd0)))
            if m.state.phase is Phase.DOCKED and phase0 is not Phase.DOCKED:
                docked.append(m.name)
            if queued:
                for j in range(n):
                    if on[j]:
                        gap = min(gap, float(np.linalg.norm(x[i] - x[j])))
            prev[i] = (m.state.phase, u_ref, queued, u_cmd)
    return Flight(w, docked, both, q_step, p_step, gap, {m.name: [e for _, e in m.events] for m in w.members})


@pytest.fixture(scope="module")
def flight() -> Flight:
    return fly()


@pytest.fixture(scope="module")
def low_bravo() -> Flight:
    """bravo reports 30 % (under recovery.battery_reserve_pct 25 + team.queue_battery_pct 10): it must land."""
    return fly(batteries=[90.0, 30.0])


def test_one_on_the_decks_approach_at_a_time_in_the_order_asked(flight):
    assert flight.both_on_approach == 0
    assert flight.docked == ["alpha", "bravo", "alpha"]  # alpha asked first (27.0 s, bravo 37.8 s)
    assert any("asked first" in e for e in flight.events["bravo"])


def test_every_leg_docks_at_the_first_approach_on_the_recovery_course(flight):
    for m in flight.world.members:
        assert not any("go-around" in e for e in flight.events[m.name])
        legs = m.state.legs_done
        assert [leg["contact"]["attempts"] for leg in legs] == [1] * len(m.cfg.scenario.legs())
        # on the contact conditions (recovery.contact_radius_m = 0.15 m); measured 0.033, 0.104, 0.055 m by the
        # estimates, PX4 SITL's errors (docs/team.md asks <= 0.10 m of the mock's lockstep demo: bravo's misses it here)
        assert all(leg["contact"]["horizontal_error_m"] <= m.cfg.recovery.contact_radius_m for leg in legs)
    report = flight.world.report()
    for s in report["passengers"].values():
        for leg in s.get("legs") or [s]:
            assert leg["p1"] and leg["p2"] and leg["p3"]
            assert leg["carrier_speed_on_approach_m_s"] == pytest.approx([1.5, 1.5], abs=0.01)  # never stopped under it
    assert not any(report["carrier"]["inside_keep_out"])


def test_no_step_at_the_queues_switches_and_the_waiting_one_keeps_clear(flight):
    assert 0.0 < flight.queue_step_m_s <= STEP_MAX_M_S
    assert flight.phase_step_m_s <= STEP_MAX_M_S
    assert flight.waiting_gap_m >= load_config(CONFIGS / "team.toml").safety.passenger_separation_m - 0.01


def test_no_phase_switch_jumps_the_command_beside_a_neighbour_on_px4s_estimate_errors(flight):
    """test_team_mission.py's check on this module's flight: ``marsupial simulate configs/team.toml``'s
    (PX4 SITL's estimate errors, seed 0), flown here once for the tests of both modules."""
    assert_no_phase_switch_jump(flight.world)


def test_the_battery_decides_when_it_must(low_bravo):
    assert low_bravo.docked[0] == "bravo"  # it asked after alpha, but must land
    assert any("must land first" in e for e in low_bravo.events["alpha"])
    assert low_bravo.both_on_approach == 0
    assert low_bravo.queue_step_m_s <= STEP_MAX_M_S and low_bravo.phase_step_m_s <= STEP_MAX_M_S
    assert all(m.state.phase is Phase.DONE for m in low_bravo.world.members)
