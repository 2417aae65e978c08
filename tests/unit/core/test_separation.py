"""The pairwise separation barrier (issue 36, item 3): passengers that leave together keep apart."""
from __future__ import annotations

import numpy as np
import pytest

from mission.core.law import LawParams, dot
from mission.core.safety import Neighbours, Obstacles, SafetyConfig, filter_velocity, neighbour_rows
from mission.core.tick import TickModel, passenger_tick
from sim.batch.team import fly_team

D = 3.0
TOL_M = 0.01  # [m] the tolerance on D: a tick's discretisation and the neighbours' one-tick-old states
CFG = SafetyConfig(max_speed_m_s=3.0, max_accel_m_s2=2.0, z_max_m=-0.5, separation_m=D)
LAW = LawParams()  # b c = 8 m: every target within 8 m of its slot, so all leave at t = 0


def _fly(slots, targets, separate=True):
    return fly_team(np.array([slots], dtype=float), np.array([targets], dtype=float), LAW, CFG, 0.02, 20.0,
                    separate=separate)


def _roundabout(k: int, spacing: float, reach: float) -> tuple[list, list]:
    """``k`` slots on a circle ``spacing`` [m] apart, each target ``reach`` [m] beyond the deck's
    centre on the far side: every path through the centre at once."""
    radius = spacing / (2 * np.sin(np.pi / k))
    ang = np.pi / 2 + 2 * np.pi * np.arange(k) / k
    slots = [[radius * np.cos(a), radius * np.sin(a), -1.5] for a in ang]
    return slots, [[-reach * np.cos(a), -reach * np.sin(a), -3.0] for a in ang]


CASES = {
    "head-on 2D": ([[0.0, 0.0], [3.5, 0.0]], [[7.0, 0.0], [-3.5, 0.0]]),
    "head-on 3D": ([[0.0, 0.0, -1.5], [3.5, 0.0, -1.5]], [[7.0, 0.0, -1.5], [-3.5, 0.0, -1.5]]),
    "crossing 3D": ([[0.0, 0.0, -1.5], [0.0, 3.5, -1.5]], [[4.0, 5.0, -3.0], [4.0, -1.5, -3.0]]),
    "three leave one deck": _roundabout(3, 3.5, 5.5),
    "three packed 2 m apart": _roundabout(3, 2.0, 5.5),
}


@pytest.mark.parametrize("name", list(CASES))
def test_passengers_never_closer_than_the_separation_and_all_arrive(name):
    slots, targets = CASES[name]
    alone = _fly(slots, targets, separate=False)
    assert alone.min_distance_m[0] < 0.5 * D  # the paths do meet: without the rows they nearly collide
    team = _fly(slots, targets)
    start = np.linalg.norm(np.subtract(slots[0], slots[1]))
    assert team.min_distance_m[0] >= min(D, start) - TOL_M
    assert team.shortfall_m[0] <= TOL_M  # and once a pair has been D apart, never closer than D
    assert not np.isnan(team.arrived_s).any()  # no deadlock: the head-on tie-break lets them pass
    assert team.infeasible[0] == 0


def test_a_pair_closer_than_the_separation_is_held_not_pushed_apart():
    x, other = np.array([0.0, 0.0, -1.5]), np.array([1.5, 0.0, -1.5])
    near = Neighbours(other[None], np.zeros((1, 3)))
    at_rest = filter_velocity(x, np.zeros(3), Obstacles.none(3), CFG, np.zeros(3), 0.02, neighbours=near)
    np.testing.assert_array_equal(at_rest.u, 0.0)  # no jump out of the slot
    closing = filter_velocity(x, np.array([1.0, 0.0, 0.0]), Obstacles.none(3), CFG, np.zeros(3), 0.02, neighbours=near)
    assert closing.cbf_active and closing.u[0] <= 1e-12  # ... but no closer either


def test_the_two_reciprocal_rows_add_up_to_the_pairs_condition():
    rng = np.random.default_rng(7)
    cfg = SafetyConfig(cbf_gain=1.5, separation_m=D)
    for _ in range(20):
        xi, xj = rng.uniform(-5, 5, 3), rng.uniform(-5, 5, 3)
        vi, vj = rng.normal(size=3), rng.normal(size=3)
        Ai, bi = neighbour_rows(xi, vi, Neighbours(xj[None], vj[None]), cfg)
        Aj, bj = neighbour_rows(xj, vj, Neighbours(xi[None], vi[None]), cfg)
        # rows met with equality by u_i and u_j: their sum is dh/dt = 2 (xi - xj).(ui - uj) >= -gain h
        h = max(float(dot(xi - xj, xi - xj)) - D * D, 0.0)
        np.testing.assert_allclose(Ai[0], -Aj[0])
        np.testing.assert_allclose(bi[0] + bj[0], -cfg.cbf_gain * h, atol=1e-9)


def test_a_neighbours_sample_is_moved_on_by_its_age():
    x, v = np.zeros(3), np.array([0.0, 1.0, 0.0])
    aged = neighbour_rows(x, np.zeros(3), Neighbours(np.array([[4.0, -0.2, 0.0]]), v[None], np.array([0.2])), CFG)
    now = neighbour_rows(x, np.zeros(3), Neighbours(np.array([[4.0, 0.0, 0.0]]), v[None]), CFG)
    np.testing.assert_allclose(aged[0], now[0])
    np.testing.assert_allclose(aged[1], now[1])


@pytest.mark.parametrize("neighbours", [
    None,
    Neighbours(np.zeros((0, 3)), np.zeros((0, 3))),
    Neighbours(np.array([[1.0, 0.0, -2.0]]), np.array([[-3.0, 0.0, 0.0]]), np.array([CFG.neighbour_max_age_s + 0.01])),
], ids=["absent", "none heard", "stale"])
def test_a_stale_or_absent_neighbour_changes_nothing(neighbours):
    obstacles = Obstacles.of([([2.0, 0.3, -2.0], 1.0)], 3)
    x, u_des, u_prev = np.array([0.0, 0.0, -2.0]), np.array([2.5, 0.0, 0.4]), np.array([2.4, 0.0, 0.3])
    alone = filter_velocity(x, u_des, obstacles, CFG, u_prev, 0.02)
    seen = filter_velocity(x, u_des, obstacles, CFG, u_prev, 0.02, neighbours=neighbours)
    np.testing.assert_array_equal(seen.u, alone.u)
    assert (seen.changed, seen.feasible, seen.cbf_active) == (alone.changed, alone.feasible, alone.cbf_active)


def test_without_a_separation_distance_neighbours_change_nothing():
    cfg = SafetyConfig(max_speed_m_s=3.0)
    near = Neighbours(np.array([[1.0, 0.0]]), np.array([[-2.0, 0.0]]))
    r = filter_velocity(np.zeros(2), np.array([2.0, 0.0]), Obstacles.none(2), cfg, neighbours=near)
    np.testing.assert_array_equal(r.u, [2.0, 0.0])


def test_the_speed_limit_never_undoes_a_neighbours_row():
    # a neighbour flies at the passenger at 2.5 m/s; the passenger wants to go at it too: the row
    # asks it to back away, and the speed limit's scaling must not shrink that below the row.
    x, other = np.zeros(2), np.array([3.2, 0.0])
    cfg = SafetyConfig(max_speed_m_s=0.5, separation_m=D)
    near = Neighbours(other[None], np.array([[-2.5, 0.0]]))
    r = filter_velocity(x, np.array([3.0, 0.0]), Obstacles.none(2), cfg, np.zeros(2), 0.02, neighbours=near)
    A, b = neighbour_rows(x, np.zeros(2), near, cfg)
    assert (A @ r.u >= b - 1e-9).all() and r.u[0] < 0


def test_batch_matches_single_and_the_tick_threads_neighbours():
    rng = np.random.default_rng(11)
    x = rng.uniform(-3, 3, size=(30, 3))
    pos = rng.uniform(-3, 3, size=(30, 2, 3))
    vel = rng.normal(size=(30, 2, 3))
    age = rng.uniform(0, 1, size=(30, 2))
    u_des, u_prev = rng.normal(size=(30, 3)) * 2, rng.normal(size=(30, 3))
    obstacles = Obstacles.of([([0.0, 4.0, 0.0], 1.0)], 3)
    batch = filter_velocity(x, u_des, obstacles, CFG, u_prev, 0.02, neighbours=Neighbours(pos, vel, age))
    for i in range(30):
        one = filter_velocity(x[i], u_des[i], obstacles, CFG, u_prev[i], 0.02, neighbours=Neighbours(pos[i], vel[i], age[i]))
        np.testing.assert_allclose(batch.u[i], one.u, atol=1e-6)
    model = TickModel(law=LAW, target=np.array([6.0, 0.0, -1.5]), obstacles=Obstacles.none(3), passenger_safety=CFG,
                      carrier_safety=SafetyConfig(), planar_carrier=False)
    anchor, ahead = np.array([0.0, 0.0, -1.5]), Neighbours(np.array([[3.2, 0.0, -1.5]]), np.zeros((1, 3)))
    free = passenger_tick(anchor, np.zeros(3), np.zeros(3), True, model, np.array([2.0, 0, 0]), 0.02)
    kept = passenger_tick(anchor, np.zeros(3), np.zeros(3), True, model, np.array([2.0, 0, 0]), 0.02, neighbours=ahead)
    assert kept.safety.cbf_active and kept.u[0] < free.u[0]
