"""What the carrier does, decided from the passenger's published phase (pure; no clock, no I/O).

The passenger's phase says what the carrier's duty is (:class:`~mission.phases.phase.Duty`, a
property of each :class:`~mission.phases.phase.Phase`). Transitions, evaluated once per carrier
tick from :class:`PassengerView`::

    WAITING     --duty CARRY, not lost---------------------------> APPROACHING
    APPROACHING --passenger lost (status older than passenger_timeout_s,
                  no status, or its liveliness token gone)--------> PAUSED     (stop; a safe reaction)
    PAUSED      --duty CARRY, not lost---------------------------> APPROACHING
    any but SEPARATED/STOPPED --duty RELEASED, or the
                  status says separated---------------------------> SEPARATED  (latched)
    WAITING/APPROACHING/PAUSED --duty STOP------------------------> STOPPED    (latched)

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

from mission.phases.phase import Duty, Phase


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
    whether that status says the latch fired, why it counts as lost (None if it does not), and
    why it aborted (phase ABORT; None if it did not say)."""

    phase: Phase | None
    separated: bool = False
    lost: str | None = None
    reason: str | None = None


def next_mode(mode: CarrierMode, view: PassengerView) -> tuple[CarrierMode, str]:
    """The mode after ``mode`` given ``view``, and why (``""`` when unchanged)."""
    if mode in (CarrierMode.SEPARATED, CarrierMode.STOPPED):
        return mode, ""
    duty = view.phase.duty if view.phase is not None else Duty.WAIT
    if view.phase is not None and (duty is Duty.RELEASED or view.separated):
        return CarrierMode.SEPARATED, f"passenger phase {view.phase}"
    if duty is Duty.STOP:
        return CarrierMode.STOPPED, f"passenger aborted: {view.reason}" if view.reason else "passenger aborted"
    riding = duty is Duty.CARRY
    if mode is CarrierMode.APPROACHING and view.lost:
        return CarrierMode.PAUSED, f"passenger lost: {view.lost}"
    if mode in (CarrierMode.WAITING, CarrierMode.PAUSED) and riding and not view.lost:
        return CarrierMode.APPROACHING, "passenger riding"
    return mode, ""
