"""The recovery queue (mission/phases/queue.py, docs/team.md "The recovery queue"): one passenger
on the deck's approach at a time; the one that asked first goes first, except that one whose
battery must land goes before, the lowest first; a waiting passenger holds off at its queue
point, clear of every other slot's approach; the switches of the queue do not jump the command."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from mission.config.passenger import passenger_config
from mission.config.schema import from_dict, load_config
from mission.core.docking import holdoff_point
from mission.core.safety import Neighbours
from mission.errors import ConfigError
from mission.model import mission_model
from mission.phases import Phase, recovery
from mission.phases.queue import (
    TIE_S,
    Claim,
    claim,
    goes_before,
    place,
    queue_point,
    wait_reason,
    yield_reason,
)
from mission.phases.types import CarrierObs, MissionState, Observation, RecoveryState, VehicleObs
from mission.config.team import queue_clearance_m
from tests.conftest import CONFIGS

MUST = 35.0  # [%] recovery.battery_reserve_pct 25 + team.queue_battery_pct 10 (the defaults)
TARGET = np.array([10.0, 0.0, -3.0])


def others(phase: str, recovery_s: float | None = None, battery: float | None = None, sysid: int = 1,
           target=TARGET, age_s: float = 0.0) -> Neighbours:
    """One neighbour in ``phase``, its recovery ``recovery_s`` [s] old at its sample ``age_s`` [s] ago."""
    return Neighbours(np.array([[0.0, 5.0, -3.0]]), np.zeros((1, 3)), np.array([age_s]), phases=(phase,),
                      recovery_s=(recovery_s,), battery_pct=(battery,), ids=(sysid,),
                      targets_ned_m=None if target is None else np.asarray(target, dtype=float)[None])


def me(asked_s: float, battery: float | None = None, rank: int = 2) -> Claim:
    return claim(asked_s, battery, MUST, rank)


def test_the_one_that_asked_first_goes_first():
    assert "asked first" in wait_reason(me(5.0), others("HOLDOFF", 8.0), MUST)
    assert wait_reason(me(5.0), others("HOLDOFF", 2.0), MUST) is None
    # its sample's age counts: 4.5 s old then, 0.6 s ago -> 5.1 s now, before 5.0
    assert wait_reason(me(5.0), others("RETURNING", 4.5, age_s=0.6), MUST) is not None
    assert wait_reason(me(5.0), others("NAVIGATING", None), MUST) is None  # not coming home: not in the queue


def test_two_that_asked_at_once_go_in_the_order_of_their_system_ids():
    assert wait_reason(me(5.0, rank=2), others("HOLDOFF", 5.0 + TIE_S / 2, sysid=1), MUST) is not None
    assert wait_reason(me(5.0, rank=1), others("HOLDOFF", 5.0 + TIE_S / 2, sysid=2), MUST) is None
    assert wait_reason(me(5.0 + TIE_S / 2, rank=1), others("HOLDOFF", 5.0, sysid=2), MUST) is None


def test_the_battery_decides_when_it_must_the_lowest_first():
    # asked later, but must land: it goes first
    assert "must land first" in wait_reason(me(20.0, battery=80.0), others("HOLDOFF", 1.0, battery=30.0), MUST)
    assert wait_reason(me(1.0, battery=30.0), others("HOLDOFF", 20.0, battery=80.0), MUST) is None
    # both must: the lower battery first, whoever asked first
    assert "less battery" in wait_reason(me(20.0, battery=34.0), others("HOLDOFF", 1.0, battery=28.0), MUST)
    assert wait_reason(me(1.0, battery=28.0), others("HOLDOFF", 20.0, battery=34.0), MUST) is None
    # above the threshold the battery says nothing: the order of asking
    assert "asked first" in wait_reason(me(1.0, battery=40.0), others("HOLDOFF", 20.0, battery=90.0), MUST)
    # a battery not known is not a must
    assert wait_reason(me(20.0, battery=None), others("HOLDOFF", 1.0, battery=None), MUST) is None


def test_the_order_is_never_both_ways():
    rng = np.random.default_rng(3)
    claims = [Claim(float(rng.choice([0.0, 0.05, 3.0, 7.0])), float(rng.choice([20.0, 30.0, 60.0])),
                    bool(rng.integers(0, 2)), int(rng.integers(1, 4))) for _ in range(40)]
    for a, b in itertools.combinations(claims, 2):
        assert not (goes_before(a, b) and goes_before(b, a))
        if a != b and (a.rank != b.rank or abs(a.asked_s - b.asked_s) > TIE_S or a.must != b.must):
            assert goes_before(a, b) or goes_before(b, a) or (a.must and b.must and a.battery_pct == b.battery_pct
                                                             and a.rank == b.rank)


@pytest.mark.parametrize("phase", ["APPROACH", "DOCKED"])
def test_nobody_overtakes_one_on_the_decks_approach(phase):
    # even one that must land and asked first waits: the one on the approach is never interrupted
    assert "deck's approach" in wait_reason(me(50.0, battery=26.0), others(phase, 1.0, battery=90.0), MUST)


def test_a_riding_neighbour_holds_the_queue_only_when_the_carrier_serves_it():
    announced = TARGET
    for phase in ("RIDING", "TRANSIT", "SEPARATED"):
        assert "serves" in wait_reason(me(5.0), others(phase), MUST, announced)
        assert wait_reason(me(5.0), others(phase, target=TARGET + 20.0), MUST, announced) is None  # rides along
        assert wait_reason(me(5.0), others(phase, target=None), MUST, announced) is not None  # not known: waits
    assert wait_reason(me(5.0), others("HOME"), MUST, announced) is None


def test_each_one_ahead_is_one_more_level_of_queue_point():
    two = Neighbours(np.zeros((2, 3)), np.zeros((2, 3)), np.zeros(2), phases=("APPROACH", "HOLDOFF"),
                     recovery_s=(1.0, 9.0), battery_pct=(None, None), ids=(1, 3))
    assert place(me(5.0), two, MUST) == 1  # the one that asked before it waits too: one level farther
    assert place(me(12.0), two, MUST) == 0  # it asked before the waiting one: the first level
    assert place(me(12.0), None, MUST) == 0


def test_one_already_on_its_glide_path_gives_way_to_a_docking_one_or_one_that_goes_first():
    assert "docking" in yield_reason(me(1.0), others("DOCKED", 0.5), MUST)
    assert "goes first" in yield_reason(me(1.0), others("APPROACH", 3.0), MUST)
    assert yield_reason(me(3.0), others("APPROACH", 1.0), MUST) is None
    assert yield_reason(me(3.0), others("HOLDOFF", 9.0), MUST) is None  # it did not begin: the first goes on


def test_the_queue_point_is_back_and_up_and_clear_of_every_other_slots_approach():
    team = load_config(CONFIGS / "team.toml")
    q = mission_model(passenger_config(team, "bravo")).queue
    assert q is not None and (q.distance_m, q.height_m) == (3.0, 3.8)
    h = np.array([1.0, 2.0, -3.0])
    np.testing.assert_allclose(queue_point(h, np.array([0.0, 1.0, 0.0]), 3.0, 3.5), [1.0, -1.0, -6.5])
    r = team.recovery
    holdoff_h = -holdoff_point(np.zeros(3), np.array([1.0, 0.0, 0.0]), mission_model(passenger_config(team, "bravo"))
                               .recovery.geometry)[2]
    ratio = team.safety.vertical_ratio  # 3.5 / 3 m: the pairwise barrier's vertical ellipsoid
    clear = queue_clearance_m(team.team, r.holdoff_distance_m, holdoff_h, r.decision_height_m, ratio)
    # worst course: along the slots, 1.5 m apart, 3.8 m up, heights weighed 3/3.5: |(-1.5, 0, 3.257)| = 3.59 m
    assert clear == pytest.approx(3.586, abs=1e-3) and clear >= team.safety.passenger_separation_m + team.safety.margin_m
    assert queue_clearance_m(team.team, r.holdoff_distance_m, holdoff_h, r.decision_height_m) == pytest.approx(4.085, abs=1e-3)
    # 1.5 m higher only, a queue point on a course along the slots comes 1.98 m from the other's holdoff point
    # in the barrier's metric (or from the queue point of the one before it)
    data = team.model_dump(exclude_unset=True)
    data["team"] = {**data["team"], "queue_height_m": 1.5}
    with pytest.raises(ConfigError) as err:
        from_dict(data)
    assert err.value.field == "team.queue_height_m" and "1.98 m" in err.value.rule


def _holdoff_flight(flip: list[tuple[int, str]], ticks: int):
    """bravo of configs/team.toml in HOLDOFF at its holdoff point behind a carrier driving north at
    1.5 m/s, an ideal vehicle on its reference; alpha's phase set at the given ticks. The
    reference's positions [m] and velocities [m/s], and the phase at each tick."""
    m = mission_model(passenger_config(load_config(CONFIGS / "team.toml"), "bravo"))
    r = m.recovery
    v_c = np.array([1.5, 0.0, 0.0])
    course = np.array([1.0, 0.0, 0.0])
    carrier0 = np.array([0.0, 0.0, 0.0])
    h = holdoff_point(carrier0 + m.dock_offset_ned_m, course, r.geometry)
    rec = RecoveryState(started_s=0.0, why="task done", course=course, carrier_seen_s=0.0)
    state = MissionState(phase=Phase.HOLDOFF, since_s=0.0, x_ref=h.copy(), u_ref=v_c.copy(), u_cmd=v_c.copy(),
                         integral=np.zeros(3), recovery=rec, anchor=np.zeros(3), separation_time_s=-30.0)
    phase, xs, us, phases = "NAVIGATING", [], [], []
    for k in range(ticks):
        phase = dict(flip).get(k, phase)
        t = k * m.dt_s
        carrier = carrier0 + v_c * t
        nb = Neighbours(np.array([carrier + [0.0, -0.75, -1.5]]), v_c[None], np.zeros(1), phases=(phase,),
                        recovery_s=(t + 10.0,), battery_pct=(None,), ids=(1,), targets_ned_m=np.zeros((1, 3)))
        obs = Observation(t, VehicleObs(state.x_ref.copy(), state.u_ref.copy(), True, "OFFBOARD", 0.0),
                          CarrierObs(carrier, v_c, 0.0), neighbours=nb, carrier_target_ned_m=np.ones(3))
        handler = recovery.holdoff if state.phase is Phase.HOLDOFF else recovery.approach
        state, _ = handler(state, obs, m)
        xs.append(state.x_ref - (carrier + m.dock_offset_ned_m))
        us.append(state.u_ref.copy())
        phases.append(state.phase)
    return m, np.array(xs), np.array(us), phases, h - m.dock_offset_ned_m


def test_waiting_its_turn_and_its_turn_coming_step_the_command_no_more_than_the_pursuit_allows():
    # alpha begins its approach at 0.5 s: bravo leaves its holdoff point for its queue point; alpha
    # docks and goes home at 9 s: bravo's turn, back to its holdoff point, settles, approaches
    m, xs, us, phases, h_rel = _holdoff_flight([(25, "APPROACH"), (300, "DOCKED"), (450, "HOME")], 800)
    q, r = m.queue, m.recovery
    steps = np.linalg.norm(np.diff(us, axis=0), axis=1)
    assert steps.max() <= r.approach.accel_m_s2 * m.dt_s + 1e-9 <= 0.05  # 0.03 m/s a tick at most
    waiting = xs[440]  # settled at the queue point while alpha docked
    np.testing.assert_allclose(waiting, h_rel - q.distance_m * np.array([1.0, 0.0, 0.0]) + [0.0, 0.0, -q.height_m],
                               atol=0.05)
    assert Phase.APPROACH not in phases[:450]  # never while alpha was on the deck's approach
    assert Phase.APPROACH in phases[450:]  # its turn: it settled at its holdoff point and began


def test_on_the_decks_approach_the_seated_neighbours_are_obstacles_moving_with_the_deck():
    from mission.phases.queue import on_deck

    v_c = np.array([1.5, 0.0, 0.0])
    nb = Neighbours(np.array([[0.0, 1.1, -1.5], [-8.0, 0.0, -6.0]]), np.array([[1.8, 0.25, 0.1], [1.5, 0.0, 0.0]]),
                    np.zeros(2), phases=("HOME", "HOLDOFF"))
    obs = Observation(0.0, None, CarrierObs(np.zeros(3), v_c, 0.0), neighbours=nb)
    seated = on_deck(nb, obs)
    assert seated is not None and len(seated) == 1  # the one waiting in the air is the queue's, not an obstacle
    np.testing.assert_allclose(seated.positions_m, [[0.0, 1.1, -1.5]])
    np.testing.assert_allclose(seated.velocities_m_s, [v_c])  # not its reported (erring) velocity
    airborne = Neighbours(nb.positions_m[1:], nb.velocities_m_s[1:], np.zeros(1), phases=("RETURNING",))
    assert on_deck(airborne, obs) is None


def test_a_go_around_beside_a_seated_neighbour_climbs_to_its_goal_keeping_the_span():
    """bravo of configs/team.toml goes round 1 m behind and 0.8 m above its slot, drifting to
    starboard at 1.5 m/s, alpha seated
    (HOME) on the port slot 1.5 m away; the go-around's goal (the holdoff height above where it
    was) lies 3.1 m from alpha. In the air phases of the recovery a seated neighbour is the deck's
    obstacle, kept at team.passenger_span_m and moving with the deck (as on the approach): the
    reference reaches its goal and holds off. Kept at the air's 3.5 m it circled the goal until
    recovery.timeout_s (the team Monte-Carlo's fall-backs)."""
    from mission.phases.queue import apart

    m = mission_model(passenger_config(load_config(CONFIGS / "team.toml"), "bravo"))
    q = m.queue
    v_c = np.array([1.5, 0.0, 0.0])
    course = np.array([1.0, 0.0, 0.0])
    alpha_slot = np.array([0.0, -0.75, -0.5])
    start = m.dock_offset_ned_m + np.array([-1.0, 0.0, -0.8])
    rec = RecoveryState(started_s=0.0, why="task done", course=course, carrier_seen_s=0.0)
    drift = v_c + np.array([0.0, 1.5, 0.0])  # it went round drifting off the glide path, away from alpha
    state = MissionState(phase=Phase.APPROACH, since_s=0.0, x_ref=start.copy(), u_ref=drift, u_cmd=drift.copy(),
                         integral=np.zeros(3), recovery=rec, anchor=np.zeros(3), separation_time_s=-30.0)

    def observe(k):
        t = 10.0 + k * m.dt_s
        carrier = v_c * t
        nb = Neighbours(np.array([carrier + alpha_slot]), np.array([[1.8, 0.3, 0.1]]), np.zeros(1), phases=("HOME",),
                        recovery_s=(None,), battery_pct=(None,), ids=(1,), targets_ned_m=np.zeros((1, 3)))
        return carrier, Observation(t, VehicleObs(state.x_ref.copy(),
                                                  state.u_ref.copy(), True, "OFFBOARD", 0.0),
                                    CarrierObs(carrier, v_c, 0.0), neighbours=nb, carrier_target_ned_m=np.ones(3))

    state = MissionState(**{**state.__dict__, "x_ref": v_c * 10.0 + start})
    carrier, obs = observe(0)
    state, _ = recovery.go_around(state, obs, m, "test")
    goal = m.dock_offset_ned_m + state.recovery.climb_to
    assert np.linalg.norm(goal - alpha_slot) < q.separation_m  # the goal lies inside the air's distance of alpha
    cfg, kept = apart(state, obs, m)
    assert kept is not None and cfg.separation_m == q.separation_m
    np.testing.assert_allclose(kept.distance_m, [q.deck_clearance_m])  # alpha, seated: the span
    np.testing.assert_allclose(kept.velocities_m_s, [v_c])  # moving with the deck, not as it reports itself
    least = np.inf
    for k in range(1, 1500):
        carrier, obs = observe(k)
        state, _ = recovery.go_around_phase(state, obs, m)
        least = min(least, float(np.linalg.norm(state.x_ref - (carrier + alpha_slot))))
        if state.phase is not Phase.GO_AROUND:
            break
    assert state.phase is Phase.HOLDOFF, k  # climbed: back to the holdoff point
    assert k * m.dt_s < 6.0, k  # [s] (3.2 s; kept at 3.5 m from alpha it circled its goal for 20 s)
    assert least >= q.deck_clearance_m
