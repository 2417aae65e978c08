"""The CBF-QP safety filter and the limits (pure)."""
from __future__ import annotations

import numpy as np
import pytest

from mission.core.law import norm
from mission.core.safety import Obstacles, SafetyConfig, _solve_qp, barrier_constraints, filter_velocity, project_cbf


def test_no_constraint_active_leaves_command_unchanged():
    obs = Obstacles.of([([10.0, 10.0], 1.0)], 2)
    r = filter_velocity(np.zeros(2), np.array([1.0, 0.0]), obs, SafetyConfig())
    assert not r.changed and r.feasible and not r.cbf_active
    np.testing.assert_array_equal(r.u, [1.0, 0.0])


def test_single_obstacle_closed_form_is_the_qp_optimum():
    obs = Obstacles.of([([3.0, 0.2], 1.0)], 2)
    cfg = SafetyConfig(cbf_gain=1.0, margin_m=0.5)
    x, u_des = np.zeros(2), np.array([4.0, 0.0])
    r = filter_velocity(x, u_des, obs, cfg)
    A, b = barrier_constraints(x, obs, cfg)
    ref = _solve_qp(u_des, A, b)
    np.testing.assert_allclose(r.u, ref, atol=1e-6)
    assert r.changed and r.cbf_active and (A @ r.u >= b - 1e-9).all()


def test_two_conflicting_obstacles_use_the_qp_and_satisfy_both():
    obs = Obstacles.of([([1.8, 0.5, 0.0], 1.0), ([1.8, -0.5, 0.0], 1.0)], 3)
    cfg = SafetyConfig(margin_m=0.2)
    x, u_des = np.zeros(3), np.array([3.0, 0.0, 0.0])
    r = filter_velocity(x, u_des, obs, cfg)
    A, b = barrier_constraints(x, obs, cfg)
    assert r.feasible and (A @ r.u >= b - 1e-7).all()
    assert r.u[0] < u_des[0]


def test_batch_matches_single_including_qp_rows():
    rng = np.random.default_rng(3)
    obs = Obstacles.of([([2.0, 0.5, 0.0], 1.0), ([2.0, -0.6, 0.0], 1.0), ([0.0, 4.0, 1.0], 1.5)], 3)
    cfg = SafetyConfig(margin_m=0.3, cbf_gain=2.0)
    x = rng.uniform(-1, 1, size=(40, 3))
    u = rng.normal(size=(40, 3)) * 4
    batch = filter_velocity(x, u, obs, cfg)
    for i in range(40):
        one = filter_velocity(x[i], u[i], obs, cfg)
        np.testing.assert_allclose(batch.u[i], one.u, atol=1e-6)


def test_infeasible_falls_back_to_zero_velocity():
    # Two barriers that demand opposite vertical motion: z >= 1 and z <= -1 from z = 0.
    cfg = SafetyConfig(z_min_m=1.0, z_max_m=-1.0)
    r = filter_velocity(np.zeros(3), np.array([1.0, 0.0, 0.0]), Obstacles.none(3), cfg)
    assert not r.feasible
    np.testing.assert_array_equal(r.u, 0.0)


def test_altitude_floor_in_ned():
    # NED: floor 2 m above ground = z <= -2. At z = -2.5 descending fast must be slowed.
    cfg = SafetyConfig(cbf_gain=1.0, z_max_m=-2.0)
    r = filter_velocity(np.array([0, 0, -2.5]), np.array([0.0, 0.0, 3.0]), Obstacles.none(3), cfg)
    assert r.u[2] == pytest.approx(0.5)


def test_speed_limit_keeps_direction():
    cfg = SafetyConfig(max_speed_m_s=2.0)
    u = np.array([30.0, 40.0])
    r = filter_velocity(np.zeros(2), u, Obstacles.none(2), cfg)
    assert norm(r.u) == pytest.approx(2.0)
    np.testing.assert_allclose(r.u / norm(r.u), u / norm(u))


def test_accel_limit_bounds_the_change():
    cfg = SafetyConfig(max_accel_m_s2=3.0)
    r = filter_velocity(np.zeros(2), np.array([10.0, 0.0]), Obstacles.none(2), cfg, u_prev=np.array([0.0, 1.0]), dt_s=0.1)
    assert norm(r.u - np.array([0.0, 1.0])) == pytest.approx(0.3)


def test_projection_reports_active_rows_only():
    A = np.array([[[1.0, 0.0]], [[1.0, 0.0]]])
    b = np.array([[0.0], [0.0]])
    u, feasible, active = project_cbf(np.array([[-1.0, 0.0], [1.0, 0.0]]), A, b)
    assert active.tolist() == [True, False] and feasible.all()
    np.testing.assert_allclose(u, [[0.0, 0.0], [1.0, 0.0]])
