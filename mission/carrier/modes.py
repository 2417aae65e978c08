"""What the carrier does, decided from the passenger's published phase (pure; no clock, no I/O).

Transitions, evaluated once per carrier tick from :class:`PassengerView`::

    WAITING     --phase RIDING, not lost-------------------------> APPROACHING
    APPROACHING --passenger lost (status older than passenger_timeout_s,
                  no status, or its liveliness token gone)--------> PAUSED     (stop; a safe reaction)
    PAUSED      --phase RIDING, not lost-------------------------> APPROACHING
    any but SEPARATED/STOPPED --phase SEPARATED or later, or the
                  status says separated---------------------------> SEPARATED  (latched)
    WAITING/APPROACHING/PAUSED --phase ABORT----------------------> STOPPED    (latched)

- WAITING (before the passenger has joined: phases PREFLIGHT..JOIN, or no status yet): stationary.
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

#: Phases during which the passenger is on (or joining) the carrier before it rides.
BEFORE_RIDING = frozenset({"PREFLIGHT", "STREAMING", "ARMING", "OFFBOARD", "JOIN"})
#: Phases after the separation event.
AFTER_SEPARATION = frozenset({"SEPARATED", "NAVIGATING", "ARRIVED", "HOLD", "LAND", "DONE"})


class CarrierMode(enum.Enum):
    """What the carrier is doing (see the module docstring for transitions)."""

    WAITING = "waiting"
    APPROACHING = "approaching"
    PAUSED = "paused"
    SEPARATED = "separated"
    STOPPED = "stopped"


@dataclass(frozen=True)
class PassengerView:
    """The passenger as the carrier sees it now: its newest phase (None: nothing received),
    whether that status says the latch fired, and why it counts as lost (None if it does not)."""

    phase: str | None
    separated: bool = False
    lost: str | None = None


def next_mode(mode: CarrierMode, view: PassengerView) -> tuple[CarrierMode, str]:
    """The mode after ``mode`` given ``view``, and why (``""`` when unchanged)."""
    if mode in (CarrierMode.SEPARATED, CarrierMode.STOPPED):
        return mode, ""
    if view.phase is not None and (view.phase in AFTER_SEPARATION or view.separated):
        return CarrierMode.SEPARATED, f"passenger phase {view.phase}"
    if view.phase == "ABORT":
        return CarrierMode.STOPPED, "passenger aborted"
    riding = view.phase == "RIDING"
    if mode is CarrierMode.APPROACHING and view.lost:
        return CarrierMode.PAUSED, f"passenger lost: {view.lost}"
    if mode in (CarrierMode.WAITING, CarrierMode.PAUSED) and riding and not view.lost:
        return CarrierMode.APPROACHING, "passenger riding"
    return mode, ""
