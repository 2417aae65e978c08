"""The keep-out round a moving deck in the safety filter (mission.core.safety.DeckKeepOut)."""
from __future__ import annotations

import numpy as np
import pytest

from mission.core.safety import DeckKeepOut, Obstacles, SafetyConfig, filter_velocity

NONE = Obstacles.none(3)
CFG = SafetyConfig(cbf_gain=1.0)


def deck(v=(0.0, 0.0, 0.0)):
    return DeckKeepOut(np.array([10.0, 0.0, -0.5]), np.array(v, dtype=float), radius_m=0.15, slope=3.0,
                       clear_height_m=1.0)


def test_on_the_deck_a_sideways_command_is_turned_into_a_climb():
    """Standing on the deck, moving out at 1 m/s relative to it: the filter keeps the outward
    speed and adds the climb the funnel asks (about outward / slope)."""
    d = deck()
    x = np.array([10.1, 0.0, -0.5])  # 0.1 m out from the dock point, on the deck
    out = filter_velocity(x, np.array([1.0, 0.0, 0.0]), NONE, CFG, deck=d)
    assert out.changed and out.cbf_active
    assert out.u[2] < -0.2  # climbing (NED)
    # the barrier's condition holds: d/dt (radius + slope height - r) >= -gain (radius - r)
    r = np.hypot(0.1, DeckKeepOut.SMOOTH_M)
    grad_r = 0.1 / r
    assert -out.u[2] * 3.0 - out.u[0] * grad_r >= -(0.15 - r) - 1e-9
    # on the axis (the gradient of r vanishes there) it may slide up to the radius first
    assert not filter_velocity(np.array([10.0, 0.0, -0.5]), np.array([0.2, 0.0, 0.0]), NONE, CFG, deck=d).changed


def test_the_keep_out_moves_with_the_deck():
    """Riding the deck's velocity is no motion relative to it: nothing to correct."""
    d = deck(v=(2.0, 0.5, 0.0))
    x = np.array([10.05, 0.0, -0.5])
    out = filter_velocity(x, np.array([2.0, 0.5, 0.0]), NONE, CFG, deck=d)
    assert not out.changed
    # falling behind the moving deck (the passenger brakes, the deck does not) is moving out of it
    behind = filter_velocity(np.array([9.9, 0.0, -0.5]), np.array([1.0, 0.5, 0.0]), NONE, CFG, deck=d)
    assert behind.cbf_active and behind.u[2] < 0.0


@pytest.mark.parametrize("x", [[10.0, 0.0, -1.6], [15.0, 0.0, -0.8]])
def test_above_the_clear_height_or_beyond_the_rim_nothing_acts(x):
    out = filter_velocity(np.array(x), np.array([1.0, 0.0, 0.3]), NONE, CFG, deck=deck())
    assert not out.changed


def test_pressed_below_the_deck_only_the_radius_holds():
    """The landing presses the reference into the deck: below its plane the funnel does not
    narrow (it would hold the reference up), the radius still holds."""
    d = deck()
    out = filter_velocity(np.array([10.0, 0.0, -0.45]), np.array([0.0, 0.0, 0.3]), NONE, CFG, deck=d)
    assert not out.changed


def test_batched_like_one_vector():
    d = deck(v=(1.0, 0.0, 0.0))
    xs = np.array([[10.0, 0.0, -0.5], [10.0, 0.0, -1.7], [10.1, 0.05, -0.6]])
    us = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.8, 0.3, 0.0]])
    batch = filter_velocity(xs, us, NONE, CFG, deck=d)
    for i in range(3):
        one = filter_velocity(xs[i], us[i], NONE, CFG, deck=d)
        np.testing.assert_allclose(batch.u[i], one.u, atol=1e-9)
