"""The mission state machine (pure): :func:`step` takes the state, one tick's observation and the
mission's model, and returns the next state and the tick's decision.

- :mod:`.phase`: the one :class:`Phase` enum with what each phase means (flying, separated, the
  carrier's duty, on the deck, its colour), the phase sets, and the vehicle commands a phase asks
  for (:class:`~mission.phases.phase.Request`);
- :mod:`.types`: abort reasons, what a tick observes, keeps and decides, the mission's model;
- :mod:`.machine`: :func:`step`, the failsafes any phase takes, and the phases before flight;
- :mod:`.flying`: the phases that fly the reference (JOIN, RIDING, SEPARATED/NAVIGATING, ARRIVED);
- :mod:`.deck`: riding seated on the carrier's deck (``mission.ride = "deck"``);
- :mod:`.recovery`: bringing the passenger home (RETURNING, HOLDOFF, APPROACH, GO_AROUND, DOCKED,
  HOME, FALLBACK) and on to the next target (TRANSIT).
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

__all__ = [
    "AIRBORNE", "ARMED", "BEFORE_SEPARATION", "FLYING", "TELEMETRY_SILENT_S", "AbortReason", "CarrierObs", "Decision", "MissionModel",
    "MissionState", "Observation", "Phase", "VehicleObs", "finished", "live_geometry_problem", "step",
]
