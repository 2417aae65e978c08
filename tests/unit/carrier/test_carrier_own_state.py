"""The PX4 carrier's own state (mission.carrier.backends.mavlink.own_state_of): stamped with the time
the vehicle took the sample, so that a burst of old samples read after a stall is old, not new."""
from __future__ import annotations

import numpy as np
import pytest

from mission.carrier.backends.mavlink import own_state_of
from mission.mavlink.telemetry import Telemetry, snapshot

OFFSET = np.array([1.0, -2.0, 0.0])  # [m] its local frame into the shared one


def _link(rx_s: float, sample_s: float | None) -> Telemetry:
    return Telemetry(position_ned_m=np.array([10.0, 0.0, 0.0]), velocity_ned_m_s=np.array([1.2, 0.0, 0.0]),
                     position_finite=True, position_rx_s=rx_s, position_t_s=sample_s)


def test_a_sample_read_late_keeps_the_time_it_was_taken() -> None:
    """A carrier process stalled 0.4 s reads a LOCAL_POSITION_NED the rover sent 0.4 s ago (the
    rover has driven 0.5 m on since): its state is 0.4 s old, not new (old: stamped 20.0, the
    receive time, and published as fresh, 0.5 m behind the rover)."""
    st = snapshot(_link(rx_s=20.0, sample_s=19.6), 20.0, (2, 1), 0.6)
    own = own_state_of(st, OFFSET, 0.6)
    assert own is not None
    assert own.t_s == pytest.approx(19.6)
    assert np.allclose(own.position_ned_m, [11.0, -2.0, 0.0]) and np.allclose(own.velocity_ned_m_s, [1.2, 0.0, 0.0])


def test_without_the_vehicle_s_time_the_receive_time_and_without_a_frame_nothing() -> None:
    st = snapshot(_link(rx_s=20.0, sample_s=None), 20.0, (2, 1), 0.6)
    own = own_state_of(st, OFFSET, 0.6)
    assert own is not None and own.t_s == pytest.approx(20.0)
    assert own_state_of(st, None, 0.6) is None  # its EKF origin not known yet
