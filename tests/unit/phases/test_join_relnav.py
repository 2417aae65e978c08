"""JOIN with the relative estimate ([relnav] enabled): the ride begins only on a dock point that has
taken in the estimate's jumps. A team's quadrotors start 0.9 m from their seats; the first markers
move the deck by that much, let through at ``relnav.correction_rate_m_s``; a JOIN that settled on the
seat's dock point while that was pending began a PX4 ride 0.94 m off the deck (docs/team.md)."""
from __future__ import annotations

import numpy as np
import pytest

from mission.config.schema import load_config
from mission.model import mission_model
from mission.phases import Phase
from mission.phases.flying import join
from mission.phases.types import CarrierObs, MissionState, Observation, RelativeView, VehicleObs
from tests.conftest import CONFIGS


@pytest.fixture(scope="module")
def model():
    return mission_model(load_config(CONFIGS / "relnav.toml"))


def _view(pending_m: float) -> RelativeView:
    return RelativeView(position_ned_m=np.zeros(3), bias_ned_m=np.zeros(3), pending_ned_m=np.array([0.0, pending_m, 0.0]),
                        position_sigma_m=0.03, converged=True, since_marker_s=0.05)


def _joined_after(model, views: list[RelativeView | None], dt_s: float = 0.02) -> float | None:
    """[s] when JOIN hands over to RIDING, the vehicle hovering still on the dock point of a carrier
    standing at the origin, the tick k's relative view ``views[k]`` (None: never)."""
    dock = np.asarray(model.dock_offset_ned_m, float)
    carrier = CarrierObs(position_ned_m=np.zeros(3), velocity_ned_m_s=np.zeros(3), age_s=0.0, alive=True, yaw_rad=0.0)
    vehicle = VehicleObs(position_ned_m=dock.copy(), velocity_ned_m_s=np.zeros(3), armed=True, mode="OFFBOARD",
                         heartbeat_age_s=0.0)
    state = MissionState(phase=Phase.JOIN, since_s=0.0, start_s=0.0, x_ref=dock.copy(), u_ref=np.zeros(3))
    for k, view in enumerate(views):
        t = k * dt_s
        state, _ = join(state, Observation(t_s=t, vehicle=vehicle, carrier=carrier, relative=view), model)
        if state.phase is Phase.RIDING:
            return t
    return None


def test_join_rides_only_once_the_estimates_jump_is_taken_in(model):
    settle, limit = model.join_settle_s, model.relnav.pending_limit_m
    ticks = int(round(3 * settle / 0.02)) + 10
    assert _joined_after(model, [_view(0.0)] * ticks) == pytest.approx(settle, abs=0.021)  # nothing pending: as before
    # a 0.8 m correction still pending for the first second, then within the limit: the settle starts over
    first = int(round(1.0 / 0.02))
    pending = [_view(0.8)] * first + [_view(0.5 * limit)] * (ticks - first)
    assert _joined_after(model, pending) == pytest.approx(1.0 + settle, abs=0.021)
    assert _joined_after(model, [_view(limit + 0.05)] * ticks) is None  # never while more than the limit is pending


def test_join_without_a_relative_view_is_not_held(model):
    """No estimate made yet (the vehicle or the carrier not heard): nothing pending to wait for."""
    ticks = int(round(2 * model.join_settle_s / 0.02)) + 5
    assert _joined_after(model, [None] * ticks) == pytest.approx(model.join_settle_s, abs=0.021)
