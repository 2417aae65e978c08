"""The pairwise separation barrier: passengers that leave together keep apart."""
from __future__ import annotations

import numpy as np
import pytest

from mission.core.law import LawParams, dot
from dataclasses import replace

from mission.core.safety import Neighbours, Obstacles, SafetyConfig, filter_velocity, neighbour_rows, phase_in_weight
from mission.core.tick import TickModel, passenger_tick
from sim.batch.team import fly_team

D = 3.0
TOL_M = 0.01  # [m] the tolerance on D: a tick's discretisation and the neighbours' one-tick-old states
CFG = SafetyConfig(max_speed_m_s=3.0, max_accel_m_s2=2.0, z_max_m=-0.5, separation_m=D)
LAW = LawParams()  # b c = 8 m: every target within 8 m of its slot, so all leave at t = 0


PHASED = replace(CFG, separation_phase_in_s=0.5)  # the rows phasing in from the separation, as the mission flies them
STEP_MAX_M_S = 0.05  # [m/s] no jump of the command at the separation


def _fly(slots, targets, separate=True, cfg=CFG):
    return fly_team(np.array([slots], dtype=float), np.array([targets], dtype=float), LAW, cfg, 0.02, 20.0,
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


@pytest.mark.parametrize("cfg", [CFG, PHASED], ids=["rows in at once", "rows phased in"])
@pytest.mark.parametrize("name", list(CASES))
def test_passengers_never_closer_than_the_separation_and_all_arrive(name, cfg):
    slots, targets = CASES[name]
    alone = _fly(slots, targets, separate=False)
    assert alone.min_distance_m[0] < 0.5 * D  # the paths do meet: without the rows they nearly collide
    team = _fly(slots, targets, cfg=cfg)
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


# The latch beside a riding neighbour (configs/team.toml's alpha at 17.2 s with PX4 SITL's estimate
# errors): the carrier's velocity, the neighbour on the next slot 1.5 m to the east (inside D), its
# sample 0.12 m/s slower eastwards than the passenger's riding command (its estimate's error), and
# the law's command just after the latch nearly zero (the carrier's velocity no longer fed forward).
V_C = np.array([1.3068, 0.9801, 0.0])
AT_LATCH = dict(x=np.array([0.0, 0.0, -1.5]), u_des=np.array([0.005, 0.005, -0.004]),
                neighbours=Neighbours(np.array([[0.1, 1.5, -1.55]]), (V_C - [0.0, 0.12, 0.0])[None]))


def _latch_step(cfg, since_s):
    r = filter_velocity(AT_LATCH["x"], AT_LATCH["u_des"], Obstacles.none(3), cfg, V_C, 0.02,
                        neighbours=AT_LATCH["neighbours"], since_separation_s=since_s)
    return float(np.linalg.norm(r.u - V_C))


def test_the_rows_phase_in_from_the_separation_so_the_latch_does_not_jump():
    accel_step = CFG.max_accel_m_s2 * 0.02
    # in at once, the row makes up half the neighbour's apparent closing speed in one tick: a jump
    assert _latch_step(CFG, 0.01) > STEP_MAX_M_S
    assert _latch_step(PHASED, None) > STEP_MAX_M_S  # (no time since the separation: in at once too)
    # phased in, the first ticks ask almost nothing beyond the acceleration limit's step
    for since in (0.0, 0.01, 0.02, 0.06):
        assert _latch_step(PHASED, since) <= accel_step + 0.002, since
    # and from the end of the phase-in on they are the very rows of the barrier
    x, nb = AT_LATCH["x"], AT_LATCH["neighbours"]
    full = neighbour_rows(x, V_C, nb, PHASED)
    for since in (0.5, 3.0):
        A, b = neighbour_rows(x, V_C, nb, PHASED, since)
        np.testing.assert_array_equal(A, full[0])
        np.testing.assert_array_equal(b, full[1])


def test_the_phase_in_is_smooth_and_refuses_a_new_approach_from_the_first_tick():
    w = phase_in_weight(np.linspace(-0.1, 0.7, 81), 0.5)
    assert w[0] == 0.0 and w[-1] == 1.0 and (np.diff(w) >= 0).all() and np.abs(np.diff(w, 2)).max() < 0.01
    # a pair held at its distance (1.5 m, D = 3 m), both at rest: turning towards the neighbour is
    # refused in full at the latch, phase-in or not (what it relaxes is only what the previous command lacked)
    x, near = np.array([0.0, 0.0, -1.5]), Neighbours(np.array([[1.5, 0.0, -1.5]]), np.zeros((1, 3)))
    closing = filter_velocity(x, np.array([1.0, 0.0, 0.0]), Obstacles.none(3), PHASED, np.zeros(3), 0.02,
                              neighbours=near, since_separation_s=0.0)
    assert closing.cbf_active and closing.u[0] <= 1e-12
    # in a batch each passenger phases in on its own clock
    xs = np.stack([AT_LATCH["x"]] * 2)
    nbs = Neighbours(np.stack([AT_LATCH["neighbours"].positions_m] * 2), np.stack([AT_LATCH["neighbours"].velocities_m_s] * 2))
    both = filter_velocity(xs, np.stack([AT_LATCH["u_des"]] * 2), Obstacles.none(3), PHASED, np.stack([V_C] * 2), 0.02,
                           neighbours=nbs, since_separation_s=np.array([0.01, 2.0]))
    assert np.linalg.norm(both.u[0] - V_C) == pytest.approx(_latch_step(PHASED, 0.01))
    assert np.linalg.norm(both.u[1] - V_C) == pytest.approx(_latch_step(PHASED, 2.0))


def _flown_at(cfg, s0):
    """A passenger separating at rest with a neighbour exactly D away flying at it at ``s0`` [m/s]
    that does not react, for 3 s: (how far inside D the pair came [m], the largest command step [m/s])."""
    x, u, p, v = np.array([0.0, 0.0, -1.5]), np.zeros(3), np.array([0.0, D, -1.5]), np.array([0.0, -s0, 0.0])
    least, step = D, 0.0
    for k in range(150):
        r = filter_velocity(x, np.zeros(3), Obstacles.none(3), cfg, u, 0.02, neighbours=Neighbours(p[None], v[None]),
                            since_separation_s=k * 0.02)
        step, u = max(step, float(np.linalg.norm(r.u - u))), r.u
        x, p = x + u * 0.02, p + v * 0.02
        least = min(least, float(np.linalg.norm(p - x)))
    return D - least, step


@pytest.mark.parametrize("s0", [0.1, 0.25, 0.5])
def test_the_price_of_the_phase_in_against_a_neighbour_flying_at_the_passenger(s0):
    """docs/team.md: in at once the row jumps the command by half the closing speed and gives up
    s0 x 0.02 s; phased in over 0.5 s it steps by at most a tenth and gives up about s0 x 0.2 s."""
    at_once, phased = _flown_at(CFG, s0), _flown_at(PHASED, s0)
    assert at_once[1] == pytest.approx(s0 / 2) and at_once[0] == pytest.approx(0.02 * s0, rel=0.05)
    assert phased[1] <= 0.1 * s0 and phased[0] <= 0.21 * s0


TALL = replace(CFG, separation_vertical_ratio=2.0)  # 3 m level, 6 m straight above or below


def test_an_ellipsoid_keeps_a_neighbour_below_twice_as_far_and_a_level_one_as_before():
    """A passenger descends towards a point 4 m straight above one that sits at its target. The
    sphere (3 m) lets it arrive; the ellipsoid of ratio 2 (3 m level, 6 m straight above or below)
    holds it on its surface (the head-on tie-break slides it round to the right a little), higher
    than the sphere would have let it come. Level, both keep 3 m."""
    below, above = [0.0, 0.0, -1.5], [0.0, 0.1, -9.5]
    stacked = ([below, above], [below, [0.0, 0.1, -5.5]])
    sphere = _fly(*stacked, cfg=CFG)
    assert not np.isnan(sphere.arrived_s).any()
    tall = _fly(*stacked, cfg=TALL)
    d = tall.final_m[0, 1] - tall.final_m[0, 0]
    assert np.isnan(tall.arrived_s[0, 1]) and tall.infeasible[0] == 0
    assert D - TOL_M <= np.sqrt(d[0] ** 2 + d[1] ** 2 + (d[2] / 2.0) ** 2) <= D + 0.1, d  # on the ellipsoid
    assert -d[2] > 4.0 + 0.5, d  # above where the sphere let it arrive
    level = ([below, [6.5, 0.0, -1.5]], [below, [0.5, 0.0, -1.5]])
    for cfg in (CFG, TALL):
        flown = _fly(*level, cfg=cfg)
        apart = float(np.linalg.norm(flown.final_m[0, 1] - flown.final_m[0, 0]))
        assert D - TOL_M <= apart <= D + 0.1, apart


def test_with_a_vertical_ratio_of_one_the_rows_are_the_spheres():
    x, own = np.array([0.2, -0.1, -4.0]), np.array([0.5, 0.0, 0.3])
    near = Neighbours(np.array([[2.0, 1.0, -2.5], [-1.0, 2.5, -6.0]]), np.array([[0.1, 0.0, 0.0], [0.0, -0.2, 0.4]]))
    A1, b1 = neighbour_rows(x, own, near, CFG)  # type: ignore[misc]
    A2, b2 = neighbour_rows(x, own, near, replace(CFG, separation_vertical_ratio=1.0))  # type: ignore[misc]
    np.testing.assert_array_equal(A1, A2)
    np.testing.assert_array_equal(b1, b2)
    At, bt = neighbour_rows(x, own, near, TALL)  # type: ignore[misc]
    np.testing.assert_array_equal(At[:, :2], A1[:, :2])  # level components unchanged
    np.testing.assert_allclose(At[:, 2], A1[:, 2] / 4.0)  # heights weigh a quarter: W = diag(1, 1, 1/2^2)


@pytest.mark.parametrize("name", list(CASES))
def test_the_ellipsoid_keeps_every_pair_at_least_the_level_distance(name):
    slots, targets = CASES[name]
    team = _fly(slots, targets, cfg=replace(TALL, separation_phase_in_s=0.5))
    start = np.linalg.norm(np.subtract(slots[0], slots[1]))
    assert team.min_distance_m[0] >= min(D, start) - TOL_M
    assert not np.isnan(team.arrived_s).any() and team.infeasible[0] == 0


def test_the_decks_seated_obstacles_stay_spheres_under_the_ellipsoid():
    """A passenger 0.9 m above a neighbour seated on the deck, kept at the span (0.8 m): on a
    sphere it may go on down no faster than the barrier allows, but the row is not in force;
    weighed as the ellipsoid of ratio 2 it would be 0.45 m away, inside, and held. The deck's
    obstacles (``on_deck``) keep the sphere, as an approach beside seated neighbours needs."""
    x, seated = np.array([0.0, 0.0, -2.4]), np.array([[0.0, 0.0, -1.5]])
    cfg = replace(TALL, separation_m=0.8)
    as_air = neighbour_rows(x, np.zeros(3), Neighbours(seated, np.zeros((1, 3))), cfg)
    as_deck = neighbour_rows(x, np.zeros(3), Neighbours(seated, np.zeros((1, 3)), on_deck=np.array([True])), cfg)
    sphere = neighbour_rows(x, np.zeros(3), Neighbours(seated, np.zeros((1, 3))), replace(cfg, separation_vertical_ratio=1.0))
    assert as_air is not None and as_deck is not None and sphere is not None
    np.testing.assert_array_equal(as_deck[0], sphere[0])
    np.testing.assert_array_equal(as_deck[1], sphere[1])
    assert float(as_air[1][0]) == 0.0 and float(sphere[1][0]) < 0.0  # held at its distance / room to descend
