"""The passenger's one step (mission/passenger/step.py): it observes a handmade vehicle report as
the controller's observation did before the step existed (the reference below, kept verbatim),
and both loops tick through it: the flight's MissionController and the recovery simulation's
World."""
from __future__ import annotations

import math
from dataclasses import fields
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from mission import phases
from mission.config.schema import load_config, with_overrides
from mission.controller import MissionController
from mission.core.consistent_velocity import PositionConsistentVelocity
from mission.core.safety import Neighbours
from mission.mavlink import px4
from mission.mavlink.telemetry import vehicle_report
from mission.model import mission_model
from mission.passenger.inputs import PassengerInputs, VehicleReport
from mission.passenger.step import PassengerStep, StepResult, observe_vehicle
from mission.phases import MissionState, Phase, VehicleObs
from mission.time.clock import ManualClock
from tests.conftest import CONFIGS
from tests.support.fake_vehicle import FakeWorld


def _reference_vehicle_obs(state: Any, velocity_fix: PositionConsistentVelocity | None = None) -> VehicleObs | None:
    """The controller's ``_vehicle_obs`` as it was before the step (main 7afa372), verbatim."""
    if state.heartbeat_rx_s is None:
        return None
    pos = state.position_ned_m
    vel = state.velocity_ned_m_s
    age = float("inf") if state.position_rx_s is None else state.t_s - state.position_rx_s
    sample_t = state.position_t_s
    bias = None
    if velocity_fix is not None and pos is not None and vel is not None and sample_t is not None:
        raw = np.asarray(vel, dtype=float)
        vel = velocity_fix.update(sample_t, np.asarray(pos, dtype=float), raw)
        bias = raw - vel
    if pos is not None and vel is not None and age <= phases.TELEMETRY_SILENT_S and sample_t is not None:
        ahead = min(max(state.t_s - sample_t, 0.0), phases.TELEMETRY_SILENT_S)
        pos = np.asarray(pos, dtype=float) + np.asarray(vel, dtype=float) * ahead
    return VehicleObs(
        position_ned_m=np.zeros(3) if pos is None else np.asarray(pos, dtype=float),
        velocity_ned_m_s=np.zeros(3) if vel is None else np.asarray(vel, dtype=float),
        armed=state.believed_armed, mode=state.mode, heartbeat_age_s=state.heartbeat_age_s,
        position_valid=bool(state.position_valid and pos is not None),
        position_age_s=age,
        in_failsafe=state.system_status == px4.MAV_STATE_CRITICAL,
        battery_pct=state.battery_pct,
        velocity_bias_ned_m_s=bias,
        on_ground=state.believed_on_ground,
    )


def _state(t: float, **kw: Any) -> SimpleNamespace:
    """A link's VehicleState by hand (the fields the observation reads)."""
    base = dict(t_s=t, heartbeat_rx_s=t - 0.1, heartbeat_age_s=0.1, position_ned_m=np.array([1.0, -2.0, -3.0]),
                velocity_ned_m_s=np.array([0.5, 0.25, -0.1]), position_rx_s=t - 0.03, position_t_s=t - 0.05,
                position_valid=True, believed_armed=True, mode="OFFBOARD", system_status=px4.MAV_STATE_ACTIVE,
                battery_pct=71.0, believed_on_ground=False)
    base.update(kw)
    return SimpleNamespace(**base)


def _same(a: VehicleObs | None, b: VehicleObs | None) -> None:
    assert (a is None) == (b is None)
    if a is None or b is None:
        return
    for f in fields(VehicleObs):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            np.testing.assert_array_equal(x, y, err_msg=f.name)
        else:
            assert x == y, f.name


CASES = {
    "late sample": {},
    "sample from the future (clock offset)": dict(position_t_s=10.2),
    "stale sample: not moved on": dict(position_rx_s=10.0 - 2 * phases.TELEMETRY_SILENT_S),
    "sample time unknown": dict(position_t_s=None),
    "no position yet": dict(position_ned_m=None, velocity_ned_m_s=None, position_rx_s=None, position_t_s=None,
                            position_valid=False),
    "failsafe, landed, disarmed": dict(system_status=px4.MAV_STATE_CRITICAL, believed_on_ground=True,
                                       believed_armed=False, battery_pct=None),
    "no HEARTBEAT yet": dict(heartbeat_rx_s=None),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_step_observes_a_report_as_the_controller_did(case: str) -> None:
    state = _state(10.0, **CASES[case])
    _same(observe_vehicle(vehicle_report(state)), _reference_vehicle_obs(state))  # type: ignore[arg-type]


def test_the_late_sample_is_moved_on_by_its_age() -> None:
    """The numbers, not only the agreement: 50 ms old, moved on by its velocity."""
    obs = observe_vehicle(vehicle_report(_state(10.0)))  # type: ignore[arg-type]
    assert obs is not None
    np.testing.assert_allclose(obs.position_ned_m, [1.0 + 0.5 * 0.05, -2.0 + 0.25 * 0.05, -3.0 - 0.1 * 0.05])
    assert obs.position_age_s == pytest.approx(0.03) and obs.in_failsafe is False and obs.battery_pct == 71.0


def test_the_step_s_consistent_velocity_is_the_controller_s_over_a_flight() -> None:
    """With mission.velocity_bias_tau_s: the same corrected velocity, bias and predicted position
    on every tick of 3 s of a vehicle whose estimator's velocity disagrees with its position, its
    samples arriving late and sometimes twice (a sample read again changes nothing)."""
    model = mission_model(load_config(CONFIGS / "demo.toml"))
    step, reference = PassengerStep(model, 0.5), PositionConsistentVelocity(0.5)
    for k in range(150):
        t = k * 0.02
        sample_t = (k - k % 3) * 0.02 - 0.01  # a new sample every third tick, 10 ms before it
        state = _state(t, position_ned_m=np.array([0.0, -0.12 * sample_t, -1.5]), position_t_s=sample_t,
                       velocity_ned_m_s=np.array([0.0, 0.44, 0.0]), position_rx_s=sample_t + 0.005)
        obs = step.observe(PassengerInputs(t, vehicle_report(state), None))  # type: ignore[arg-type]
        _same(obs.vehicle, _reference_vehicle_obs(state, reference))
    assert obs.vehicle is not None and obs.vehicle.velocity_bias_ned_m_s is not None
    assert float(obs.vehicle.velocity_ned_m_s[1]) == pytest.approx(-0.12, abs=0.02)


def test_the_step_runs_the_phases_and_returns_setpoint_request_and_decision() -> None:
    model = mission_model(load_config(CONFIGS / "demo.toml"))
    step = PassengerStep(model)
    inputs = PassengerInputs(0.0, vehicle_report(_state(0.0)), None, failed={"arm": "no"}, interrupted=True)  # type: ignore[arg-type]
    result = step(MissionState(), inputs)
    state, decision = phases.step(MissionState(), step.observe(inputs), model)
    assert isinstance(result, StepResult)
    assert result.observation.failed == {"arm": "no"} and result.observation.interrupted
    assert result.state.phase == state.phase and result.decision.request == decision.request
    assert result.setpoint is result.decision.setpoint and result.request is result.decision.request


def test_the_step_passes_the_other_passengers_on_to_the_phases() -> None:
    """``PassengerInputs.neighbours`` (the other passengers' shared states, from the bus once
    wired) reach the observation the phases see as they came; none heard: none."""
    step = PassengerStep(mission_model(load_config(CONFIGS / "demo.toml")))
    others = Neighbours(np.array([[4.0, 0.0, -3.0]]), np.array([[0.0, 1.0, 0.0]]), np.array([0.04]))
    assert step.observe(PassengerInputs(0.0, vehicle_report(_state(0.0)), None, neighbours=others)).neighbours is others  # type: ignore[arg-type]
    assert step.observe(PassengerInputs(0.02, vehicle_report(_state(0.02)), None)).neighbours is None  # type: ignore[arg-type]


class _Spy:
    """Wraps a step and keeps what each call got and gave."""

    def __init__(self, step: PassengerStep) -> None:
        self.step, self.calls = step, []  # type: ignore[var-annotated]

    def __call__(self, state: MissionState, inputs: PassengerInputs) -> StepResult:
        result = self.step(state, inputs)
        self.calls.append((inputs, result))
        return result


def test_the_flight_ticks_through_the_step() -> None:
    """MissionController hands the step the link's report (late samples and all) and sends what
    it decided; the published and recorded vehicle is the step's observation."""
    cfg = load_config(CONFIGS / "demo.toml")
    clock = ManualClock()
    world = FakeWorld(clock, target_ned_m=np.asarray(cfg.scenario.target, dtype=float))
    controller = MissionController(cfg, world, world.feed, clock, publisher=world, command_thread=False)
    spy = _Spy(controller.step)
    controller.step = spy  # type: ignore[assignment]
    outcome = controller.run()
    assert outcome.ok and len(spy.calls) == controller.ticks
    assert all(isinstance(inputs.vehicle, VehicleReport) for inputs, _ in spy.calls[1:])
    sent = [r.setpoint for _, r in spy.calls if r.setpoint is not None]
    assert len(sent) == len(world.setpoints) > 0
    inputs, last = spy.calls[-1]
    assert last.state is controller.state and last.observation.t_s == inputs.t_s


def test_the_recovery_simulation_ticks_through_the_same_step() -> None:
    """World calls the controller's step on MockDynamics' report: the consistent velocity (the
    configuration's velocity_bias_tau_s) and the prediction by the sample's age are the flight's."""
    from sim.batch.recovery import World, configured

    cfg = with_overrides(load_config(CONFIGS / "recovery.toml"), {"mission.velocity_bias_tau_s": 0.5})
    world = World(cfg, configured())
    assert isinstance(world.step, PassengerStep) and world.step.velocity_fix is not None
    spy = _Spy(world.step)
    world.step = spy  # type: ignore[assignment]
    for _ in range(100):
        world.tick()
    assert len(spy.calls) == 100 and world.state.phase is not Phase.PREFLIGHT
    inputs, result = spy.calls[-1]
    assert isinstance(inputs.vehicle, VehicleReport) and inputs.vehicle.sample_t_s == inputs.t_s
    assert result.observation.vehicle is not None and result.observation.vehicle.velocity_bias_ned_m_s is not None
    np.testing.assert_array_equal(world.rows.vecs["x_p"][-1], result.observation.vehicle.position_ned_m)
    assert math.isfinite(float(result.observation.vehicle.position_age_s))
