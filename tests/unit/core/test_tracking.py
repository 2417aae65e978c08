"""The tracking loop (mission.core.tracking): what is sent for each setpoint kind, the integral's
window and clamp, the reference's progress when the vehicle lags."""
from __future__ import annotations

import numpy as np
import pytest

from mission.core.tracking import TrackingGains, progress, setpoint, update_integral, velocity_demand

X_REF = np.array([10.0, 5.0, -2.0])
U_REF = np.array([1.6, 1.2, 0.0])
A_REF = np.array([0.8, 0.6, 0.0])
X_P = np.array([9.8, 5.1, -2.0])  # 0.2 m behind north, 0.1 m ahead east

# What a test's gains start from: velocity setpoints pulled at 1/s, every other term off, the
# integral clamped at 2 and windowed at 0.5 m; each test sets what it checks (a flight's gains come
# from the configuration, mission.model.mission_model).
BASE = dict(kind="velocity", position_gain_per_s=1.0, position_lead=0.0, integral_gain=0.0, integral_limit=2.0,
            drag_ff_per_s=0.0, integral_window_m=0.5, damping_per_s=0.0, bias_compensation_s=0.0, accel_lead_s=0.0,
            accel_lead_filter_s=0.1, accel_limit_m_s2=None, slow_lag_m=None, stop_lag_m=None)


def gains(**changes) -> TrackingGains:
    return TrackingGains(**{**BASE, **changes})


def test_velocity_setpoint_is_the_law_plus_our_pull_and_integral() -> None:
    g = gains(kind="velocity", position_gain_per_s=1.5, integral_gain=0.5)
    integral = np.array([0.1, 0.0, 0.0])
    v = velocity_demand(X_REF, U_REF, X_P, integral, g)
    np.testing.assert_allclose(v, U_REF + 1.5 * (X_REF - X_P) + integral)
    sp = setpoint(X_REF, U_REF, A_REF, X_P, v, integral, g)
    assert not sp.full and sp.acceleration_ned_m_s2 is None
    assert sp.velocity_ned_m_s is v


def test_full_setpoint_sends_the_law_velocity_lead_position_and_feed_forward() -> None:
    g = gains(kind="full", position_gain_per_s=0.0, position_lead=2.0, drag_ff_per_s=1.0)
    integral = np.array([0.0, 0.2, 0.0])
    v = velocity_demand(X_REF, U_REF, X_P, integral, g)
    np.testing.assert_allclose(v, U_REF)  # the law's own command, not the integral (an acceleration)
    sp = setpoint(X_REF, U_REF, A_REF, X_P, v, integral, g)
    assert sp.full
    np.testing.assert_allclose(sp.position_ned_m, X_REF + 2.0 * (X_REF - X_P))
    np.testing.assert_allclose(sp.acceleration_ned_m_s2, A_REF + 1.0 * U_REF + integral)


def test_a_filtered_velocity_goes_alone_even_with_full_gains() -> None:
    """The safety filter wins over the reference: once it changed the velocity, neither the
    reference position nor the feed-forward is sent (decided here, nowhere downstream)."""
    g = gains(kind="full", position_lead=2.0, drag_ff_per_s=1.0)
    safe = np.array([0.3, 0.0, 0.0])
    sp = setpoint(X_REF, U_REF, A_REF, X_P, safe, np.zeros(3), g, filtered=True)
    assert not sp.full and sp.position_ned_m is None and sp.acceleration_ned_m_s2 is None
    assert sp.velocity_ned_m_s is safe


@pytest.mark.parametrize(("changed", "kind"), [
    ([False, False, True], "full_horizontal"),  # a floor acting down: the horizontal tracking stays whole
    ([True, False, False], "full_vertical"),  # an obstacle north: north and east go velocity only together
    ([True, True, True], "velocity"),  # a speed limit scaling the whole command
])
def test_only_the_axes_the_filter_changed_lose_their_position_and_feed_forward(changed, kind) -> None:
    """PX4 reads an ignored field as NaN per axis (north and east together): the axes the filter
    left alone keep their reference position and acceleration, the others get velocity only."""
    g = gains(kind="full", position_lead=2.0, drag_ff_per_s=1.0)
    safe = np.array([1.5, 1.2, 0.4])
    sp = setpoint(X_REF, U_REF, A_REF, X_P, safe, np.zeros(3), g, filtered=np.array(changed))
    assert sp.kind == kind and sp.velocity_ned_m_s is safe
    if sp.full:
        sent = np.array(sp.position_axes)
        whole = setpoint(X_REF, U_REF, A_REF, X_P, safe, np.zeros(3), g)
        np.testing.assert_allclose(sp.position_ned_m[sent], whole.position_ned_m[sent])
        np.testing.assert_allclose(sp.acceleration_ned_m_s2[sent], whole.acceleration_ned_m_s2[sent])
        assert not sp.acceleration_ned_m_s2[~sent].any()  # nothing left for the axis not sent


def test_integral_integrates_inside_its_window_and_is_clamped() -> None:
    g = gains(kind="full", integral_gain=2.0, integral_limit=0.5, integral_window_m=0.5)
    zero = np.zeros(3)
    step = update_integral(zero, X_REF, X_P, g, 0.02)
    np.testing.assert_allclose(step, 2.0 * (X_REF - X_P) * 0.02)
    far = X_REF - np.array([0.6, 0.0, 0.0])  # catching up, not a steady deficit: left alone
    assert update_integral(step, X_REF, far, g, 0.02) is step
    big = update_integral(np.array([0.49, 0.0, 0.0]), X_REF, X_P, g, 1.0)
    assert np.linalg.norm(big) == pytest.approx(0.5)
    assert update_integral(zero, X_REF, X_P, gains(kind="full"), 0.02) is zero  # no gain: never integrates


@pytest.mark.parametrize(("lag", "rate"), [(0.0, 1.0), (0.3, 1.0), (0.65, 0.5), (1.0, 0.0), (2.0, 0.0)])
def test_reference_slows_then_waits_for_a_lagging_vehicle(lag: float, rate: float) -> None:
    g = gains(slow_lag_m=0.3, stop_lag_m=1.0)
    assert progress(lag, g) == pytest.approx(rate)
    assert progress(lag, gains()) == 1.0  # unset: the reference never waits


def test_damping_feeds_the_velocity_error_against_the_reference_back_into_the_acceleration() -> None:
    """damping_per_s: a full setpoint's acceleration carries -k (v_p - u_ref); nothing without the
    vehicle's velocity, with k = 0, or for velocity setpoints."""
    x, u, a, i = np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.5, 0.0, 0.0]), np.zeros(3)
    g = gains(kind="full", drag_ff_per_s=1.0, damping_per_s=2.0)
    sp = setpoint(x, u, a, x, u, i, g, v_p=np.array([1.3, -0.1, 0.0]))
    np.testing.assert_allclose(sp.acceleration_ned_m_s2, [0.5 + 1.0 - 2.0 * 0.3, 0.2, 0.0])
    np.testing.assert_allclose(setpoint(x, u, a, x, u, i, g).acceleration_ned_m_s2, [1.5, 0.0, 0.0])
    off = gains(kind="full", drag_ff_per_s=1.0)
    np.testing.assert_allclose(setpoint(x, u, a, x, u, i, off, v_p=np.array([1.3, -0.1, 0.0])).acceleration_ned_m_s2,
                               [1.5, 0.0, 0.0])
    assert setpoint(x, u, a, x, u, i, gains(kind="velocity", damping_per_s=2.0), v_p=u).acceleration_ned_m_s2 is None


def test_bias_compensation_moves_the_position_by_the_estimators_velocity_bias() -> None:
    """bias_compensation_s: the position sent carries s times the estimator's velocity bias, so
    PX4's velocity setpoint (MPC_XY_P times the position error) carries the bias; nothing without
    a bias, with s = 0, or for velocity setpoints."""
    bias = np.array([0.0, -0.4, 0.1])
    g = gains(kind="full", position_gain_per_s=0.0, position_lead=2.0, bias_compensation_s=1.05)
    v = velocity_demand(X_REF, U_REF, X_P, np.zeros(3), g)
    sp = setpoint(X_REF, U_REF, A_REF, X_P, v, np.zeros(3), g, velocity_bias=bias)
    np.testing.assert_allclose(sp.position_ned_m, X_REF + 2.0 * (X_REF - X_P) + 1.05 * bias)
    np.testing.assert_allclose(sp.velocity_ned_m_s, U_REF)  # the law's command is untouched
    plain = setpoint(X_REF, U_REF, A_REF, X_P, v, np.zeros(3), g)
    np.testing.assert_allclose(plain.position_ned_m, X_REF + 2.0 * (X_REF - X_P))
    off = setpoint(X_REF, U_REF, A_REF, X_P, v, np.zeros(3), gains(kind="full", position_lead=2.0), velocity_bias=bias)
    np.testing.assert_allclose(off.position_ned_m, plain.position_ned_m)
    assert setpoint(X_REF, U_REF, A_REF, X_P, v, np.zeros(3), gains(kind="velocity", bias_compensation_s=1.0),
                    velocity_bias=bias).position_ned_m is None


def test_acceleration_lead_turns_a_vehicle_lag_tau_into_lag_t() -> None:
    """accel_lead_s: a reference acceleration step, sent through the lead-lag and then through the
    vehicle's own first-order lag tau, arrives as if through a lag T (accel_lead_filter_s); off, it
    is sent as it is."""
    from mission.core.tracking import lead_acceleration

    tau, t_lag, dt = 0.28, 0.1, 0.002
    g = gains(kind="full", accel_lead_s=tau, accel_lead_filter_s=t_lag)
    lp, felt = None, 0.0
    a_ref = np.zeros(3)
    sent, lp = lead_acceleration(a_ref, lp, g, dt)
    np.testing.assert_allclose(sent, a_ref)  # no kick at the start
    step = np.array([1.0, 0.0, 0.0])
    for k in range(1, 400):  # 0.8 s
        sent, lp = lead_acceleration(step, lp, g, dt)
        felt += (sent[0] - felt) * (1.0 - np.exp(-dt / tau))  # the vehicle's lag
        if k in (50, 100, 200):  # 0.1, 0.2, 0.4 s
            assert felt == pytest.approx(1.0 - np.exp(-k * dt / t_lag), abs=0.03)
    off, _ = lead_acceleration(step, np.zeros(3), gains(kind="full"), dt)
    np.testing.assert_allclose(off, step)


def test_the_acceleration_sent_is_clamped_to_the_commands_limit() -> None:
    """PX4 flies the last setpoint on through a stall of ours: what we add to the acceleration
    never exceeds the command's acceleration limit (its direction kept)."""
    g = gains(kind="full", drag_ff_per_s=1.0, damping_per_s=2.0, accel_limit_m_s2=3.0)
    v_p = U_REF + np.array([-2.0, -1.5, 0.0])  # 2.5 m/s slower than the reference: damping asks +5 m/s^2
    sp = setpoint(X_REF, U_REF, A_REF, X_P, U_REF, np.zeros(3), g, v_p)
    raw = A_REF + U_REF + 2.0 * (U_REF - v_p)
    assert np.linalg.norm(sp.acceleration_ned_m_s2) == pytest.approx(3.0)
    np.testing.assert_allclose(sp.acceleration_ned_m_s2 / 3.0, raw / np.linalg.norm(raw))
    small = setpoint(X_REF, U_REF, np.zeros(3), X_P, U_REF, np.zeros(3), gains(kind="full", accel_limit_m_s2=3.0))
    np.testing.assert_allclose(small.acceleration_ned_m_s2, np.zeros(3))
