"""The mission state machine (pure): :func:`step` takes the state, one tick's observation and the
mission's model, and returns the next state and the tick's decision.

- :mod:`.types`: the one :class:`Phase` enum, abort reasons, the phase sets, what a tick observes,
  keeps and decides;
- :mod:`.machine`: :func:`step`, the failsafes any phase takes, and the phases before flight;
- :mod:`.flying`: the phases that fly the reference (JOIN, RIDING, SEPARATED/NAVIGATING, ARRIVED).
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
