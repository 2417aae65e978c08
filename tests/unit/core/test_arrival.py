"""Arrival judged on a window of estimated positions (mission.core.arrival), not on the velocity
estimate, and the phase that uses it."""
from __future__ import annotations

import numpy as np
import pytest

from mission.core import arrival
from mission.phases import MissionState, Observation, Phase, VehicleObs, step

DT = 0.02
TARGET = np.array([10.0, 5.0, -3.0])


def _fill(points, radius: float = 0.5, dwell: float = 1.0) -> tuple[arrival.Window, float]:
    window: arrival.Window = ()
    t = 0.0
    for k, x in enumerate(points):
        t = k * DT
        window = arrival.extend(window, t, x, bool(np.linalg.norm(x - TARGET) <= radius), dwell)
    return window, t


def test_still_within_the_radius_for_the_dwell_arrives() -> None:
    window, t = _fill([TARGET + [0.1, 0.0, 0.0]] * 51)
    assert arrival.spread_m(window) == pytest.approx(0.0)
    assert arrival.arrived(window, t, 1.0, 0.3, DT)
    assert not arrival.arrived(window[:-5], t - 5 * DT, 1.0, 0.3, DT)  # 0.1 s short of the dwell


def test_moving_or_swinging_through_the_radius_does_not_arrive_and_leaving_empties_the_window() -> None:
    moving = [TARGET + [-0.25 + 0.5 * k * DT, 0.0, 0.0] for k in range(51)]  # 0.5 m/s, all inside
    window, t = _fill(moving)
    assert arrival.spread_m(window) == pytest.approx(0.25, rel=0.02)
    assert not arrival.arrived(window, t, 1.0, 0.3, DT)
    swing = [TARGET + [0.2 * np.sin(2 * np.pi * k * DT), 0.0, 0.0] for k in range(51)]  # +-0.2 m at 1 Hz: no net drift
    window, t = _fill(swing)
    assert not arrival.arrived(window, t, 1.0, 0.3, DT)
    window, t = _fill(moving)
    assert arrival.arrived(window, t, 1.0, None, DT)  # no speed rule: the dwell alone
    assert arrival.extend(window, t + DT, TARGET + [0.6, 0.0, 0.0], False, 1.0) == ()


def test_the_window_keeps_only_the_dwell() -> None:
    window, t = _fill([TARGET] * 200)
    assert window[0][0] == pytest.approx(t - 1.0) and len(window) == 51


def test_a_vehicle_held_on_the_target_arrives_though_its_velocity_estimate_says_0_4_m_s(model_px4) -> None:
    """PX4 SITL's velocity estimate errs by 0.3-0.45 m/s for seconds while its position stands
    still: the vehicle arrives after the dwell, judged on its positions."""
    m = model_px4
    target = m.tick.target
    state = MissionState(phase=Phase.NAVIGATING, since_s=0.0, start_s=0.0, anchor=target - [8.0, 0.0, 0.0],
                         e_ref=np.array([8.0, 0.0, 0.0]), x_ref=target.copy(), u_ref=np.zeros(3))
    arrived_at = None
    for k in range(200):
        t = k * DT
        x = target + [0.05 * np.sin(t), 0.03, 0.0]  # centimetres of wander
        vehicle = VehicleObs(x, np.array([0.0, -0.4, 0.0]), True, "OFFBOARD", heartbeat_age_s=0.1)
        state, _ = step(state, Observation(t_s=t, vehicle=vehicle, carrier=None), m)
        if state.phase == Phase.ARRIVED:
            arrived_at = t
            break
    assert arrived_at == pytest.approx(m.arrival_dwell_s, abs=2 * DT)


@pytest.fixture
def model_px4():
    from mission.config.schema import load_config
    from mission.controller import mission_model
    from tests.conftest import CONFIGS

    return mission_model(load_config(CONFIGS / "px4_sitl.toml"))
