"""When a stopped PX4 carrier counts as at rest, and is then held where it stands
(mission.carrier.backends.mavlink, ``carrier.mavlink.stand = "position"``): a diff-drive or Ackermann
vehicle by its forward speed, since it cannot move sideways; a holonomic one by its horizontal speed."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.carrier.tracking import own_speed_m_s

STAND_M_S = 0.1  # carrier.mavlink.stand_speed_m_s of configs/px4_sitl_cycle.toml


def test_a_standing_rover_s_sideways_estimate_is_not_motion() -> None:
    """PX4's SIH rover standing between the legs, heading -169 deg: its estimator said (+0.19,
    -0.64) m/s, 0.67 m/s mostly sideways, while its position moved 0.08 m/s. Counted as motion, the
    stand never engaged, and PX4's speed loop, left on the 1 mm/s stop with a speed estimate of
    +-0.67 m/s (its size, signed by the forward part), rocked the rover for 6 s."""
    yaw = math.radians(-169.0)
    v = np.array([0.19, -0.64, 0.0])
    assert math.hypot(v[0], v[1]) > STAND_M_S  # before: "still rolling", never held
    assert own_speed_m_s(v, yaw, "ackermann") < STAND_M_S
    assert own_speed_m_s(v, yaw, "diff_drive") < STAND_M_S


@pytest.mark.parametrize("kind", ["ackermann", "diff_drive"])
def test_a_rover_rolling_forward_or_back_is_not_at_rest(kind: str) -> None:
    yaw = math.radians(30.0)
    ahead = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    assert own_speed_m_s(0.3 * ahead, yaw, kind) == pytest.approx(0.3)
    assert own_speed_m_s(-0.3 * ahead, yaw, kind) == pytest.approx(0.3)


def test_a_holonomic_vehicle_or_one_without_a_heading_counts_its_horizontal_speed() -> None:
    v = np.array([0.19, -0.64, 0.5])
    assert own_speed_m_s(v, math.radians(-169.0), "holonomic") == pytest.approx(math.hypot(0.19, 0.64))
    assert own_speed_m_s(v, None, "ackermann") == pytest.approx(math.hypot(0.19, 0.64))
