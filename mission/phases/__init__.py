"""The mission state machine (pure): :func:`step` takes the state, one tick's observation and the
mission's model, and returns the next state and the tick's decision.

- :mod:`.phase`: the one :class:`Phase` enum with what each phase means (flying, separated, the
  carrier's duty, on the deck, its colour), the phase sets, and the vehicle commands a phase asks
  for (:class:`~mission.phases.phase.Request`);
- :mod:`.types`: abort reasons, what a tick observes, keeps and decides, the mission's model;
- :mod:`.measurements`: the measurement feeds' readings as a tick observes them (a
  :class:`~mission.phases.measurements.Measurement` per reading, stamped at capture);
- :mod:`.machine`: :func:`step`, the failsafes any phase takes, and the phases before flight;
- :mod:`.flying`: the phases that fly the reference (JOIN, RIDING, SEPARATED/NAVIGATING, ARRIVED);
- :mod:`.deck`: riding seated on the carrier's deck (``mission.ride = "deck"``);
- :mod:`.recovery`: bringing the passenger home (RETURNING, HOLDOFF, APPROACH, GO_AROUND, DOCKED,
  HOME, FALLBACK) and on to the next target (TRANSIT);
- :mod:`.battery`: whether the battery calls the passenger home, or forbids the next leg;
- :mod:`.stall`: after a stall (a gap with no tick), the reference goes on from where the vehicle is.
"""
from mission.phases.machine import (
    AIRBORNE,
    ARMED,
    BEFORE_SEPARATION,
    FLYING,
    TELEMETRY_SILENT_S,
    AbortReason,
    CarrierObs,
    Decision,
    MissionModel,
    MissionState,
    Observation,
    Phase,
    VehicleObs,
    finished,
    live_geometry_problem,
    step,
)
from mission.phases.measurements import Measurement, Measurements, RelativePosition

__all__ = [
    "AIRBORNE", "ARMED", "BEFORE_SEPARATION", "FLYING", "TELEMETRY_SILENT_S", "AbortReason", "CarrierObs", "Decision",
    "Measurement", "Measurements", "MissionModel", "MissionState", "Observation", "Phase", "RelativePosition",
    "VehicleObs", "finished", "live_geometry_problem", "step",
]
