"""What the carrier does, decided from the passenger's published phase (pure; no clock, no I/O).

The passenger's phase says what the carrier's duty is (:class:`~mission.phases.phase.Duty`, a
property of each :class:`~mission.phases.phase.Phase`). Transitions, evaluated once per carrier
tick from :class:`PassengerView`::

    WAITING     --duty CARRY confirmed, not lost, not holding----> APPROACHING
    APPROACHING --passenger lost (status older than passenger_timeout_s,
                  no status, or its liveliness token gone), or it
                  holds (its feed of the carrier is not consistent)-> PAUSED     (stop; a safe reaction)
    PAUSED      --duty CARRY confirmed, not lost, not holding----> APPROACHING
    any but SEPARATED/STOPPED --duty RELEASED, or the
                  status says separated---------------------------> SEPARATED  (latched)
    WAITING/APPROACHING/PAUSED --duty STOP------------------------> STOPPED    (latched)

CARRY confirmed: the status comes from the passenger's bound source (the feed binds only to a
source that began on the deck with :data:`BIND_STATUSES` statuses in a phase of duty WAIT,
:class:`mission.bus.feeds.PassengerFeed`) and puts the passenger on the carrier's own dock point
(``on_dock``): a RIDING claimed from elsewhere, or by a passenger that is not on the deck, never
starts the carrier.

- WAITING (duty WAIT: the passenger has not joined yet, or no status yet): stationary.
- APPROACHING: ``u_c = k_c e_tc`` (planar), filtered.
- PAUSED / STOPPED: command zero (through the filter, so an acceleration limit still applies).
- SEPARATED: ``scenario.carrier_mode = "stop"``: zero; ``"remark1"``: the velocity commanded at the
  instant of separation (the carrier's own plan), still filtered. Passenger silence no longer
  matters once separated: the passenger has left.

Whatever the mode, the P3 guard (:mod:`mission.carrier.guard`) still caps the command: a
passenger that lies (RIDING forever) cannot bring the carrier closer than ``b c - margin``.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from mission.phases.phase import Duty, Phase

#: Phases a passenger's status may bind its source in: before riding (duty WAIT), on the deck or joining.
BEFORE_RIDING = frozenset(p for p in Phase if p.duty is Duty.WAIT)


class CarrierMode(enum.Enum):
    """What the carrier is doing (see the module docstring for transitions)."""

    WAITING = "waiting"
    APPROACHING = "approaching"
    PAUSED = "paused"
    SEPARATED = "separated"
    STOPPED = "stopped"


BIND_STATUSES = 3  # statuses in order, before riding, that bind the passenger's source
DOCK_SLACK_M = 0.5  # [m] on the dock point: within mission.dock_tolerance_m + this (two estimators)


@dataclass(frozen=True)
class PassengerView:
    """The passenger as the carrier sees it now: its newest phase (None: nothing received),
    whether that status says the latch fired, why it counts as lost (None if it does not),
    whether it holds (its carrier feed is not consistent: it waits on the dock point it had), and
    whether it says it is on the carrier's dock point."""

    phase: Phase | None
    separated: bool = False
    lost: str | None = None
    holding: bool = False
    on_dock: bool = True


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


def next_mode(mode: CarrierMode, view: PassengerView) -> tuple[CarrierMode, str]:
    """The mode after ``mode`` given ``view``, and why (``""`` when unchanged)."""
    if mode in (CarrierMode.SEPARATED, CarrierMode.STOPPED):
        return mode, ""
    duty = view.phase.duty if view.phase is not None else Duty.WAIT
    if view.phase is not None and (duty is Duty.RELEASED or view.separated):
        return CarrierMode.SEPARATED, f"passenger phase {view.phase}"
    if duty is Duty.STOP:
        return CarrierMode.STOPPED, "passenger aborted"
    riding = duty is Duty.CARRY
    if mode is CarrierMode.APPROACHING and view.lost:
        return CarrierMode.PAUSED, f"passenger lost: {view.lost}"
    if mode is CarrierMode.APPROACHING and view.holding:
        return CarrierMode.PAUSED, "passenger holds: its feed of the carrier is not consistent"
    if mode in (CarrierMode.WAITING, CarrierMode.PAUSED) and riding and not view.lost and not view.holding \
            and view.on_dock:
        return CarrierMode.APPROACHING, "passenger riding (confirmed on the dock point)"
    return mode, ""
