"""What a user reads when something is wrong: messages that name what the user controls."""
from __future__ import annotations

import socket

import numpy as np
import pytest

from mission.config.schema import load_config
from mission.controller import mission_model
from mission.errors import PortInUse
from mission.phases import AbortReason, CarrierObs, MissionState, Observation, Phase, VehicleObs, live_geometry_problem, step
from mission.port_holder import port_in_use
from tests.conftest import CONFIGS


@pytest.fixture(scope="module")
def model():
    return mission_model(load_config(CONFIGS / "demo.toml"))


def _preflight_once(model, carrier_ned, vehicle_ned):
    vehicle = VehicleObs(np.asarray(vehicle_ned, float), np.zeros(3), False, "AUTO.LOITER", heartbeat_age_s=0.1)
    carrier = CarrierObs(np.asarray(carrier_ned, float), np.zeros(3), age_s=0.0)
    return step(MissionState(), Observation(t_s=0.0, vehicle=vehicle, carrier=carrier), model)


def test_carrier_already_inside_bc_says_restart_or_move_it(model):
    # A second `run` without restarting the carrier: it stopped 6.2 m from the target.
    target = model.tick.target
    horiz = np.array([target[0], target[1], 0.0]) * (1 - 5.0 / np.hypot(target[0], target[1]))
    state, dec = _preflight_once(model, horiz, horiz + model.dock_offset_ned_m)
    assert state.phase == Phase.ABORT and state.reason == AbortReason.GEOMETRY.value
    assert "inside b*c = 8 m" in state.detail and "restart the carrier" in state.detail
    assert "mission.eta" not in state.detail
    assert dec.setpoint is None and dec.request is None


def test_vehicle_off_the_carrier_names_the_tolerance_field_and_the_fix(model):
    msg = live_geometry_problem(np.array([0, 0, -1.5]), np.array([3.0, 0, 0]), model)
    assert "3.00 m from the carrier's dock point" in msg and "mission.dock_tolerance_m = 0.5" in msg
    assert "--start-ned" in msg


def test_target_too_high_for_the_dock_plane(model):
    msg = live_geometry_problem(np.array([0, 0, 20.0]), np.array([0, 0, 20.0]), model)
    assert "above the dock point" in msg and "scenario.target" in msg


def test_good_geometry_has_no_problem(model):
    assert live_geometry_problem(np.array([0, 0, -1.5]), np.array([0.1, 0, 0]), model) is None


def test_port_in_use_names_the_port_and_this_process():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        err = port_in_use("MAVLink udpin", "127.0.0.1", port)
    assert isinstance(err, PortInUse) and err.exit_code == 6
    text = str(err)
    assert f"127.0.0.1:{port} is already in use" in text
    import os
    assert f"process {os.getpid()}" in text


def test_port_holder_is_found_although_one_of_its_fds_closes_meanwhile(monkeypatch):
    """An fd of the holder that closes between listing and reading (another thread's socket in
    a busy process) must not hide the holder: under load the message said "not found" for the
    test's own process."""
    import os

    from mission import port_holder as ph
    real_readlink = os.readlink
    gone: list[str] = []

    def readlink(path):
        if str(path).startswith(f"/proc/{os.getpid()}/fd/") and not gone:  # the first fd we look at: closed
            gone.append(str(path))
            raise FileNotFoundError(path)
        return real_readlink(path)

    monkeypatch.setattr(ph.os, "readlink", readlink)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        holder = ph.port_holder(s.getsockname()[1])
    assert gone and holder is not None and holder[0] == os.getpid()
