"""Property-based tests of the pure law and safety filter (hypothesis).

Finite in -> finite out; the speed and acceleration limits are never exceeded; a feasible
CBF-QP never leaves a barrier constraint violated; the tick and the batch agree.
"""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from mission.core.law import LawParams, norm, passenger_command
from mission.core.safety import Obstacles, SafetyConfig, barrier_constraints, filter_velocity

coord = st.floats(min_value=-200.0, max_value=200.0, allow_nan=False, allow_infinity=False)
vec3 = arrays(np.float64, 3, elements=coord)
speed = st.floats(min_value=0.1, max_value=20.0)
params = st.builds(LawParams, k_c=st.floats(0.05, 5.0), k_p=st.floats(0.05, 5.0), b=st.floats(1.05, 20.0),
                   c=st.floats(0.05, 5.0), d=st.floats(0.05, 5.0))
obstacle_sets = st.lists(st.tuples(vec3, st.floats(0.1, 5.0)), min_size=0, max_size=8)

SETTINGS = settings(max_examples=300, deadline=None)


@SETTINGS
@given(e_pc=vec3, e_tc=vec3, u_c=vec3, p=params)
def test_law_finite_in_finite_out(e_pc, e_tc, u_c, p):
    cmd = passenger_command(e_pc, e_tc, u_c, p)
    assert np.isfinite(cmd.u_p).all() and np.isfinite(cmd.P)


@SETTINGS
@given(e_tc=vec3, p=params)
def test_docked_passenger_input_equals_carrier_input_outside_bc(e_tc, p):
    if norm(e_tc) < p.separation_distance_m:
        return
    u_c = p.k_c * e_tc
    cmd = passenger_command(np.zeros(3), e_tc, u_c, p)
    np.testing.assert_array_equal(cmd.u_p, u_c)


@SETTINGS
@given(x=vec3, u=vec3, u_prev=vec3, obs=obstacle_sets, vmax=speed, amax=st.floats(0.1, 20.0),
       gain=st.floats(0.1, 10.0), margin=st.floats(0.0, 1.0))
def test_filter_output_is_finite_and_within_speed_limit(x, u, u_prev, obs, vmax, amax, gain, margin):
    cfg = SafetyConfig(cbf_gain=gain, margin_m=margin, max_speed_m_s=vmax, max_accel_m_s2=amax)
    r = filter_velocity(x, u, Obstacles.of([(list(c), rad) for c, rad in obs], 3), cfg, u_prev=u_prev, dt_s=0.02)
    assert np.isfinite(r.u).all()
    assert norm(r.u) <= vmax * (1 + 1e-9)


@SETTINGS
@given(x=vec3, u=vec3, u_prev=vec3, vmax=speed, amax=st.floats(0.1, 20.0))
def test_accel_limit_never_exceeded_without_barriers(x, u, u_prev, vmax, amax):
    # Start from a previous command that already respects the speed limit (as in a running loop).
    u_prev = u_prev * min(1.0, vmax / max(norm(u_prev), 1e-12))
    cfg = SafetyConfig(max_speed_m_s=vmax, max_accel_m_s2=amax)
    r = filter_velocity(x, u, Obstacles.none(3), cfg, u_prev=u_prev, dt_s=0.02)
    assert norm(r.u - u_prev) <= amax * 0.02 * (1 + 1e-9) + 1e-12


@SETTINGS
@given(x=vec3, u=vec3, obs=obstacle_sets, gain=st.floats(0.1, 10.0), margin=st.floats(0.0, 1.0))
def test_feasible_cbf_satisfies_every_barrier(x, u, obs, gain, margin):
    cfg = SafetyConfig(cbf_gain=gain, margin_m=margin)
    obstacles = Obstacles.of([(list(c), rad) for c, rad in obs], 3)
    r = filter_velocity(x, u, obstacles, cfg)
    A, b = barrier_constraints(x, obstacles, cfg)
    if bool(r.feasible):
        slack = A @ r.u - b
        assert (slack >= -1e-6 * (1 + np.abs(b))).all()
    else:
        np.testing.assert_array_equal(r.u, 0.0)


@SETTINGS
@given(x=vec3, u=vec3, obs=obstacle_sets)
def test_filter_is_minimal_when_nothing_is_violated(x, u, obs):
    cfg = SafetyConfig()
    obstacles = Obstacles.of([(list(c), rad) for c, rad in obs], 3)
    A, b = barrier_constraints(x, obstacles, cfg)
    r = filter_velocity(x, u, obstacles, cfg)
    if (A @ u - b >= 0).all():
        np.testing.assert_array_equal(r.u, u)


@settings(max_examples=50, deadline=None)
@given(xs=arrays(np.float64, (16, 3), elements=coord), us=arrays(np.float64, (16, 3), elements=coord), obs=obstacle_sets)
def test_batch_equals_single(xs, us, obs):
    cfg = SafetyConfig(max_speed_m_s=8.0)
    obstacles = Obstacles.of([(list(c), rad) for c, rad in obs], 3)
    batch = filter_velocity(xs, us, obstacles, cfg)
    for i in range(16):
        np.testing.assert_allclose(filter_velocity(xs[i], us[i], obstacles, cfg).u, batch.u[i], rtol=1e-7, atol=1e-7)
