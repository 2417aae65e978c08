"""The mission's phases: the one list, and what each phase means to the vehicle, the carrier and
the flight record; and the vehicle commands a phase asks for (:class:`Request`). Pure; imports
nothing of ours.

A phase is added here (its member and its three properties) and in the machine's handler table
(:data:`mission.phases.machine.HANDLERS`); the wire's phase names (:mod:`mission.bus.wire`), the
carrier's reaction (:mod:`mission.carrier.modes`) and the record's figures (:mod:`mission.record`)
are derived from this enum.
"""
from __future__ import annotations

from enum import StrEnum


class Request(StrEnum):
    """A vehicle command the mission phases ask to have in flight (equal to its lower-case name)."""

    ARM = "arm"
    OFFBOARD = "offboard"
    HOLD = "hold"
    LAND = "land"
    DISARM = "disarm"  # on the deck only (mission.ride = "deck"): PX4 refuses it unless its land detector says landed


class Duty(StrEnum):
    """What the carrier does while the passenger is in a phase."""

    WAIT = "wait"  # the passenger is not riding yet: stand still
    CARRY = "carry"  # the passenger rides: drive towards the target (u_c = k_c e_tc)
    RELEASED = "released"  # the passenger has left: stop, or keep its own plan (the paper's Remark 1)
    RECOVER = "recover"  # the passenger comes home: hold a steady recovery course
    REPOSITION = "reposition"  # the passenger rides; drive out until the next leg's target is far enough (Assumption 1)
    PARK = "park"  # the passenger is home for good: stop and stay
    STOP = "stop"  # the passenger aborted: stop


class Phase(StrEnum):
    """A phase of the mission, equal to its name (the name travels on the bus and in the record).

    Properties (fixed per phase):

    - ``flying``: the vehicle is ours in OFFBOARD and must stay there (leaving it is a pilot's or
      PX4's takeover);
    - ``separated``: the separation latch has fired (the paper's ``t > T``): the carrier's state is
      no longer needed to fly, the anchor is latched;
    - ``duty``: what the carrier does meanwhile (:class:`Duty`);
    - ``on_deck``: the vehicle still stands on the deck, not yet lifted off (the carrier may align
      its estimate onto the passenger's).
    """

    flying: bool
    separated: bool
    duty: Duty
    on_deck: bool

    def __new__(cls, name: str, flying: bool, separated: bool, duty: Duty, on_deck: bool) -> Phase:
        member = str.__new__(cls, name)
        member._value_ = name
        member.flying, member.separated, member.duty, member.on_deck = flying, separated, duty, on_deck
        return member

    #            name          flying separated duty           on_deck
    PREFLIGHT = ("PREFLIGHT", False, False, Duty.WAIT, True)
    STREAMING = ("STREAMING", False, False, Duty.WAIT, True)
    ARMING = ("ARMING", False, False, Duty.WAIT, True)
    OFFBOARD = ("OFFBOARD", False, False, Duty.WAIT, False)
    JOIN = ("JOIN", True, False, Duty.WAIT, False)
    RIDING = ("RIDING", True, False, Duty.CARRY, False)
    TRANSIT = ("TRANSIT", True, False, Duty.REPOSITION, False)
    SEPARATED = ("SEPARATED", True, True, Duty.RELEASED, False)
    NAVIGATING = ("NAVIGATING", True, True, Duty.RELEASED, False)
    ARRIVED = ("ARRIVED", True, True, Duty.RELEASED, False)
    RETURNING = ("RETURNING", True, True, Duty.RECOVER, False)
    HOLDOFF = ("HOLDOFF", True, True, Duty.RECOVER, False)
    APPROACH = ("APPROACH", True, True, Duty.RECOVER, False)
    GO_AROUND = ("GO_AROUND", True, True, Duty.RECOVER, False)
    DOCKED = ("DOCKED", True, True, Duty.RECOVER, False)
    HOME = ("HOME", True, True, Duty.PARK, False)
    FALLBACK = ("FALLBACK", True, True, Duty.RELEASED, False)
    HOLD = ("HOLD", False, True, Duty.RELEASED, False)
    LAND = ("LAND", False, True, Duty.RELEASED, False)
    DONE = ("DONE", False, True, Duty.RELEASED, False)
    ABORT = ("ABORT", False, False, Duty.STOP, False)


#: Phases in which the vehicle is ours in OFFBOARD and must stay there.
FLYING = frozenset(p for p in Phase if p.flying)
#: Phases before the separation latch fired (ABORT excluded): the carrier's state is needed.
BEFORE_SEPARATION = frozenset(p for p in Phase if not p.separated and p is not Phase.ABORT)
#: Phases after the separation latch fired.
AFTER_SEPARATION = frozenset(p for p in Phase if p.separated)
#: The phases that bring the passenger home to the carrier (mission.final_action = "return").
RECOVERY = frozenset({Phase.RETURNING, Phase.HOLDOFF, Phase.APPROACH, Phase.GO_AROUND, Phase.DOCKED})
#: Phases in which the vehicle must be armed: ours, switching to OFFBOARD or flying in it.
ARMED = frozenset({Phase.OFFBOARD, *FLYING})
#: Phases in which the vehicle must be in the air: not JOIN (it lifts off the deck, and PX4's land
#: detector takes seconds to see the take-off), nor DOCKED and HOME (on a carrier with a real deck
#: at the dock point the passenger touches it).
AIRBORNE = FLYING - {Phase.JOIN, Phase.DOCKED, Phase.HOME}
