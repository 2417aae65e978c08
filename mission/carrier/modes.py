"""What the carrier does, decided from the passenger's published phase (pure; no clock, no I/O).

The passenger's phase says what the carrier's duty is (:class:`~mission.phases.phase.Duty`, a
property of each :class:`~mission.phases.phase.Phase`). Transitions, evaluated once per carrier
tick from :class:`PassengerView`, in this order (the first that applies)::

    STOPPED     --anything---------------------------------------> STOPPED    (latched)
    any         --duty PARK--------------------------------------> PARKED     (latched: only CARRY leaves it)
    PARKED      --duty CARRY, not lost---------------------------> APPROACHING (the next target)
    PARKED      --anything else----------------------------------> PARKED
    SEPARATED/PAUSED --duty RECOVER, not lost--------------------> RECOVERING
    SEPARATED/PAUSED --duty RECOVER, lost--------------------------> unchanged
    RECOVERING  --duty STOP----------------------------------------> STOPPED
    RECOVERING  --passenger lost (as below)------------------------> PAUSED     (stop)
    RECOVERING  --duty RELEASED (the recovery fell back)-----------> SEPARATED
    RECOVERING  --duty CARRY (riding again: the next target)-------> APPROACHING
    RECOVERING/PAUSED --duty REPOSITION, not lost------------------> REPOSITIONING (the next leg's start)
    RECOVERING  --anything else (duty RECOVER)----------------------> RECOVERING
    REPOSITIONING --duty STOP-------------------------------------> STOPPED
    REPOSITIONING --passenger lost---------------------------------> PAUSED
    REPOSITIONING --duty CARRY, not lost---------------------------> APPROACHING (the next target)
    REPOSITIONING --duty RELEASED----------------------------------> SEPARATED
    REPOSITIONING --anything else----------------------------------> REPOSITIONING
    SEPARATED   --anything else----------------------------------> SEPARATED  (latched otherwise)
    any         --duty RELEASED, or the status says separated------> SEPARATED
    WAITING/APPROACHING/PAUSED --duty STOP-------------------------> STOPPED    (latched)
    APPROACHING --passenger lost (status older than passenger_timeout_s,
                  no status, or its liveliness token gone), or it
                  holds (its feed of the carrier is not consistent)-> PAUSED     (stop; a safe reaction)
    WAITING/PAUSED --duty CARRY confirmed, not lost, not holding-> APPROACHING

CARRY confirmed: the status comes from the passenger's bound source (the feed binds only to a
source that began on the deck with :data:`BIND_STATUSES` statuses in a phase of duty WAIT,
:class:`mission.bus.feeds.PassengerFeed`) and puts the passenger on the carrier's own dock point
(``on_dock``): a RIDING claimed from elsewhere, or by a passenger that is not on the deck, never
starts the carrier.

- WAITING (duty WAIT: the passenger has not joined yet, or no status yet): stationary.
- APPROACHING: ``u_c = k_c e_tc`` (planar), filtered.
- PAUSED / STOPPED / PARKED: command zero (through the filter, so an acceleration limit still
  applies). PARKED: the passenger came home (its phase HOME, duty PARK); a PX4 vehicle is handed to
  its own Hold once at rest; HOLD or DONE after it (duty RELEASED) never unpark it, whatever
  ``scenario.carrier_mode`` says.
- SEPARATED: ``scenario.carrier_mode = "stop"``: zero; ``"remark1"``: the velocity commanded at the
  instant of separation (the carrier's own plan), still filtered. Passenger silence no longer
  matters once separated: the passenger has left.
- REPOSITIONING (duty REPOSITION: the passenger, docked again, rides while the next leg waits for
  the paper's Assumption 1): the carrier drives straight away from the next leg's target until it
  is ``b c + mission.leg_start_margin_m`` from it (with a little to spare), then stands; a
  diff-drive or Ackermann one with ``carrier.min_moving_speed_m_s`` first turns to face that
  target (:meth:`mission.carrier.legs.Legs.turn_velocity`).
- RECOVERING (duty RECOVER: the passenger returns, holds off, approaches, docks): the steady
  recovery course (:mod:`mission.carrier.course`: ``carrier.recovery_course`` legs, then
  ``carrier.recovery_heading_deg`` at ``carrier.recovery_speed_m_s``), filtered. A passenger lost
  meanwhile stops the carrier (PAUSED) until it is heard again: a carrier driving on with nobody
  coming home would only run away from PX4's home.

Whatever the mode, the P3 guard (:mod:`mission.carrier.guard`) still caps the command: a
passenger that lies (RIDING forever, RETURNING towards the target) cannot bring the carrier closer
than ``b c - margin``.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from mission.carrier.frames import HeardBias
from mission.phases.phase import Duty, Phase

#: Phases a passenger's status may bind its source in: before riding (duty WAIT), on the deck or joining.
BEFORE_RIDING = frozenset(p for p in Phase if p.duty is Duty.WAIT)


class CarrierMode(enum.Enum):
    """What the carrier is doing (see the module docstring for transitions)."""

    WAITING = "waiting"
    APPROACHING = "approaching"
    PAUSED = "paused"
    SEPARATED = "separated"
    RECOVERING = "recovering"
    REPOSITIONING = "repositioning"
    PARKED = "parked"
    STOPPED = "stopped"


BIND_STATUSES = 3  # statuses in order, before riding, that bind the passenger's source
DOCK_SLACK_M = 0.5  # [m] on the dock point: within mission.dock_tolerance_m + this (two estimators)


@dataclass(frozen=True)
class PassengerView:
    """The passenger as the carrier sees it now: its newest phase (None: nothing received),
    whether that status says the latch fired, why it counts as lost (None if it does not),
    which target's leg it flies, why it aborted (phase ABORT; None if it did not say), whether it
    holds (its carrier feed is not consistent: it waits on the dock point it had), whether it
    says it is on the carrier's dock point, and the frames' bias its status shares (None: none;
    the P3 guard's frame, :mod:`mission.carrier.frames`)."""

    phase: Phase | None
    separated: bool = False
    lost: str | None = None
    leg: int = 0  # the index of the target the passenger serves (scenario.targets)
    reason: str | None = None
    holding: bool = False
    on_dock: bool = True
    bias: HeardBias | None = None


def lost_reason(token_alive: bool | None, age_s: float | None, max_age_s: float) -> str | None:
    """Why the passenger counts as lost, or None: its liveliness token went (``token_alive``
    False), no status (``age_s`` None), or its newest is older than ``max_age_s`` [s]."""
    if token_alive is False:
        return "its liveliness token is gone"
    if age_s is None:
        return "no status received"
    if age_s > max_age_s:
        return f"its status is {age_s:.2f} s old (> {max_age_s} s)"
    return None


def on_dock(position_ned_m: np.ndarray, dock_ned_m: np.ndarray, tolerance_m: float, dim: int = 3) -> bool:
    """Whether a passenger at ``position_ned_m`` [m] NED is on the dock point ``dock_ned_m`` [m],
    within ``tolerance_m`` (mission.dock_tolerance_m) + :data:`DOCK_SLACK_M`; horizontally only
    when ``dim`` is 2."""
    gap = (np.asarray(position_ned_m, dtype=float) - np.asarray(dock_ned_m, dtype=float))[:3 if dim == 3 else 2]
    return float(np.linalg.norm(gap)) <= tolerance_m + DOCK_SLACK_M


def _aborted(view: PassengerView) -> str:
    return f"passenger aborted: {view.reason}" if view.reason else "passenger aborted"


def next_mode(mode: CarrierMode, view: PassengerView) -> tuple[CarrierMode, str]:
    """The mode after ``mode`` given ``view``, and why (``""`` when unchanged)."""
    if mode is CarrierMode.STOPPED:
        return mode, ""
    duty = view.phase.duty if view.phase is not None else Duty.WAIT
    if duty is Duty.PARK:
        return (mode, "") if mode is CarrierMode.PARKED else (CarrierMode.PARKED, f"passenger phase {view.phase}")
    if mode is CarrierMode.PARKED:
        if duty is Duty.CARRY and not view.lost:
            return CarrierMode.APPROACHING, "passenger riding again"
        return mode, ""
    if duty is Duty.RECOVER and mode in (CarrierMode.SEPARATED, CarrierMode.PAUSED):
        return (mode, "") if view.lost else (CarrierMode.RECOVERING, f"passenger phase {view.phase}")
    if duty is Duty.REPOSITION and mode in (CarrierMode.RECOVERING, CarrierMode.PAUSED) and not view.lost:
        return CarrierMode.REPOSITIONING, f"passenger phase {view.phase}: leg {view.leg + 1} starts farther out"
    if mode in (CarrierMode.REPOSITIONING, CarrierMode.RECOVERING):
        if duty is Duty.STOP:
            return CarrierMode.STOPPED, _aborted(view)
        if view.lost:
            return CarrierMode.PAUSED, f"passenger lost: {view.lost}"
        if duty is Duty.CARRY:
            return CarrierMode.APPROACHING, f"passenger riding: leg {view.leg + 1}"
        if duty is Duty.RELEASED:
            return CarrierMode.SEPARATED, f"passenger phase {view.phase}"
        return mode, ""
    if mode is CarrierMode.SEPARATED:
        return mode, ""
    if view.phase is not None and (duty is Duty.RELEASED or view.separated):
        return CarrierMode.SEPARATED, f"passenger phase {view.phase}"
    if duty is Duty.STOP:
        return CarrierMode.STOPPED, _aborted(view)
    if mode is CarrierMode.APPROACHING and view.lost:
        return CarrierMode.PAUSED, f"passenger lost: {view.lost}"
    if mode is CarrierMode.APPROACHING and view.holding:
        return CarrierMode.PAUSED, "passenger holds: its feed of the carrier is not consistent"
    if mode in (CarrierMode.WAITING, CarrierMode.PAUSED) and duty is Duty.CARRY and not view.lost and not view.holding \
            and view.on_dock:
        return CarrierMode.APPROACHING, "passenger riding (confirmed on the dock point)"
    return mode, ""
