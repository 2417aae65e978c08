"""The carrier's gentle start (mission.carrier.start): the command's speed grows at most at the start
acceleration while the carrier stands, runs at most a lead ahead of the measured speed once it moves (with a lead), and may always shrink."""
from __future__ import annotations

import numpy as np
import pytest

from mission.carrier.start import MOVING_M_S, gentle_start, speed_lead


def test_while_standing_the_speed_grows_at_most_the_start_acceleration_along_the_same_direction() -> None:
    u = np.array([0.8, 0.6])  # the law asks 1 m/s
    out = gentle_start(u, np.array([0.08, 0.06]), 0.0, 0.25, 0.1)  # was 0.1 m/s
    assert float(np.linalg.norm(out)) == pytest.approx(0.1 + 0.025, rel=1e-12)
    np.testing.assert_allclose(out / np.linalg.norm(out), [0.8, 0.6])


def test_once_moving_or_when_off_or_when_slowing_the_command_is_the_law_s() -> None:
    u, prev = np.array([0.8, 0.6]), np.zeros(2)
    assert gentle_start(u, prev, MOVING_M_S, 0.25, 0.1) is u  # measured moving: the law's own limits
    assert gentle_start(u, prev, 0.0, 0.0, 0.1) is u  # off
    slower = np.array([0.08, 0.06])
    assert gentle_start(slower, np.array([0.4, 0.3]), 0.0, 0.25, 0.1) is slower  # shrinking is never held back
    zero = np.zeros(2)
    assert gentle_start(zero, zero, 0.0, 0.25, 0.1) is zero


def test_once_moving_the_speed_runs_at_most_the_lead_ahead_of_the_measured_speed() -> None:
    u = np.array([0.8, 0.6])  # the law asks 1 m/s of a rover crawling at 0.2 m/s
    out = speed_lead(u, 0.2, 0.3)
    assert float(np.linalg.norm(out)) == pytest.approx(0.5, rel=1e-12)
    np.testing.assert_allclose(out / np.linalg.norm(out), [0.8, 0.6])
    assert speed_lead(u, 0.8, 0.3) is u  # within the lead
    assert speed_lead(u, 0.0, 0.3) is u  # standing: the gentle start's part, not the lead's
    assert speed_lead(u, 0.2, 0.0) is u  # off
