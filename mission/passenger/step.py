"""The passenger's whole tick, pure: :class:`PassengerStep` takes the mission's state and one
tick's raw observations (:class:`~mission.passenger.inputs.PassengerInputs`), assembles what the
phases observe, runs :func:`mission.phases.step` (the phases, the law, tracking and the safety
filters are inside it) and returns the next state, the observation and the decision (its
setpoint and its request) as a :class:`StepResult`.

The observation of the vehicle: its velocity made consistent with its position
(``mission.velocity_bias_tau_s``, :mod:`mission.core.consistent_velocity`), and its position
moved on by that velocity over the sample's age. The measurement feeds' readings pass through as
they are (:class:`~mission.phases.measurements.Measurements`), with the newest of each kind kept. Frames: local NED [m], [m/s]; times [s] on the
caller's clock.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from mission import phases
from mission.core.consistent_velocity import PositionConsistentVelocity
from mission.core.setpoint import Setpoint
from mission.passenger.inputs import PassengerInputs, VehicleReport
from mission.passenger.relative import RelativeDeck, seat_offset
from mission.phases import CarrierObs, Decision, Measurements, MissionModel, MissionState, Observation, VehicleObs
from mission.phases.phase import NEAR_DECK, RANGED, Phase, Request


def observe_vehicle(report: VehicleReport | None, velocity_fix: PositionConsistentVelocity | None = None) -> VehicleObs | None:
    """The vehicle as the phases see it (None: no vehicle heard yet). With ``velocity_fix`` its
    velocity is made consistent with its position, and what that took off the estimator's
    velocity is ``velocity_bias_ned_m_s``. Its position is the report's sample moved on by the
    velocity over the sample's age (by the vehicle's own clock, up to
    :data:`~mission.phases.TELEMETRY_SILENT_S`), as the dock point is: a late sample, or a burst
    of old ones read after a stall, would otherwise count speed x delay as offset."""
    if report is None:
        return None
    pos, vel = report.position_ned_m, report.velocity_ned_m_s
    age = math.inf if report.rx_s is None else report.t_s - report.rx_s
    sample_t = report.sample_t_s
    bias = None
    if velocity_fix is not None and pos is not None and vel is not None and sample_t is not None:
        raw = np.asarray(vel, dtype=float)
        vel = velocity_fix.update(sample_t, np.asarray(pos, dtype=float), raw)
        bias = raw - vel  # what the estimator's velocity says beyond its position's rate
    if pos is not None and vel is not None and age <= phases.TELEMETRY_SILENT_S and sample_t is not None:
        ahead = min(max(report.t_s - sample_t, 0.0), phases.TELEMETRY_SILENT_S)
        pos = np.asarray(pos, dtype=float) + np.asarray(vel, dtype=float) * ahead
    return VehicleObs(
        position_ned_m=np.zeros(3) if pos is None else np.asarray(pos, dtype=float),
        velocity_ned_m_s=np.zeros(3) if vel is None else np.asarray(vel, dtype=float),
        armed=report.armed, mode=report.mode, heartbeat_age_s=report.heartbeat_age_s,
        position_valid=bool(report.valid and pos is not None),
        position_age_s=age,
        in_failsafe=report.in_failsafe,
        battery_pct=report.battery_pct,
        velocity_bias_ned_m_s=bias,
        on_ground=report.on_ground,
    )


class ReceivedCarrier(Protocol):
    """A carrier feed's newest sample (:class:`mission.bus.feeds.ReceivedCarrierState`): its
    ``value`` (position, velocity, acceleration, yaw as the carrier sent them) and its ``age_s``
    [s]; ``untrusted`` and ``age_bound_s`` when the feed says them."""

    @property
    def value(self) -> Any: ...

    @property
    def age_s(self) -> float: ...


def observe_carrier(received: ReceivedCarrier | None, alive: bool | None) -> CarrierObs | None:
    """The carrier as the phases see it from a feed's newest sample (None: none yet), its
    liveliness ``alive`` (None: unknown), why the feed does not trust it yet and the bound of
    its age."""
    if received is None:
        return None
    st = received.value
    return CarrierObs(position_ned_m=np.asarray(st.position, dtype=float),
                      velocity_ned_m_s=np.asarray(st.velocity_ned_m_s, dtype=float), age_s=received.age_s, alive=alive,
                      acceleration_ned_m_s2=st.acceleration_ned_m_s2, yaw_rad=st.yaw_rad,
                      untrusted=getattr(received, "untrusted", None), age_bound_s=getattr(received, "age_bound_s", 0.0),
                      stamp_s=getattr(st, "stamp_s", None))


@dataclass(frozen=True)
class StepResult:
    """One tick's result: the mission's next ``state``, what the phases ``observation`` saw and
    their ``decision`` (with the setpoint to send and the request to carry out)."""

    state: MissionState
    observation: Observation
    decision: Decision

    @property
    def setpoint(self) -> Setpoint | None:
        """What to send the vehicle (None: nothing this tick)."""
        return self.decision.setpoint

    @property
    def request(self) -> Request | None:
        """The vehicle command to carry out (None: none)."""
        return self.decision.request


class PassengerStep:
    """The passenger's tick for ``model``; ``velocity_bias_tau_s`` [s] the time constant of the
    vehicle's consistent velocity (``mission.velocity_bias_tau_s``; 0: the estimator's velocity
    as it comes), ``near_deck_tau_s`` [s] its time constant instead in
    :data:`~mission.phases.phase.NEAR_DECK` (``mission.near_deck_velocity_bias_tau_s``; None: the
    same). Its only memory is that filter's, the newest measurement of each kind and, with
    ``[relnav]`` enabled (``model.relnav``), the relative estimator
    (:class:`mission.passenger.relative.RelativeDeck`: the carrier's state the phases see is
    then in the passenger's frame, and the estimate is in ``Observation.relative``); the
    mission's state is the caller's."""

    def __init__(self, model: MissionModel, velocity_bias_tau_s: float = 0.0, near_deck_tau_s: float | None = None) -> None:
        self.model = model
        self.velocity_fix = PositionConsistentVelocity(velocity_bias_tau_s) if velocity_bias_tau_s > 0 else None
        self._tau_s, self._near_deck_tau_s = velocity_bias_tau_s, near_deck_tau_s
        self.measurements = Measurements()  # the measurement feeds' readings: the last tick's, the newest of each kind
        # [relnav] enabled: the relative estimator and the carrier's state in the passenger's frame
        self.relative = RelativeDeck(model.relnav, model.dock_offset_ned_m, seat_offset(
            model.dock_offset_ned_m, model.deck is not None)) if model.relnav is not None else None

    def observe(self, inputs: PassengerInputs, phase: Phase | None = None) -> Observation:
        """What the phases observe on this tick (the measurements: this tick's readings, and the
        newest of each kind so far) in ``phase``, the mission's phase before this tick (None: not
        known, taken as off the deck with ranges fused). The relative estimator takes the phase's
        ``on_deck`` (the vehicle still stands on the carrier's deck) as a measurement, and fuses
        downward ranges only in :data:`~mission.phases.phase.RANGED` (the phases over the deck)."""
        self.measurements = self.measurements.then(tuple(inputs.measurements))
        if self.velocity_fix is not None and self._near_deck_tau_s is not None:
            # the filter's bias carries on across a switch: only its gain changes
            self.velocity_fix.tau_s = self._near_deck_tau_s if phase in NEAR_DECK else self._tau_s
        carrier, relative = inputs.carrier, None
        if self.relative is not None:
            carrier, relative = self.relative.observe(inputs.t_s, inputs.vehicle, carrier, self.measurements,
                                                    phase is not None and phase.on_deck,
                                                    phase is None or phase in RANGED)
        return Observation(t_s=inputs.t_s, vehicle=observe_vehicle(inputs.vehicle, self.velocity_fix),
                           carrier=carrier, failed=dict(inputs.failed), interrupted=inputs.interrupted,
                           measurements=self.measurements, relative=relative, neighbours=inputs.neighbours,
                           carrier_target_ned_m=inputs.carrier_target_ned_m)

    def __call__(self, state: MissionState, inputs: PassengerInputs) -> StepResult:
        """One tick: observe, then the phases."""
        obs = self.observe(inputs, state.phase)
        state, decision = phases.step(state, obs, self.model)
        return StepResult(state, obs, decision)
