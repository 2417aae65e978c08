"""The mission's phases: the one list, and what each phase means to the vehicle, the carrier and
the flight record; and the vehicle commands a phase asks for (:class:`Request`). Pure; imports
nothing of ours.

A phase is added here (its member and its properties) and in the machine's handler table
(:data:`mission.phases.machine.HANDLERS`); the wire's phase names (:mod:`mission.bus.wire`), the
carrier's reaction (:mod:`mission.carrier.modes`), the record's figures (:mod:`mission.record.figures`)
and the colours of the plots (:mod:`mission.plots`, :mod:`mission.flightdata.view`) are derived
from this enum.
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
      its estimate onto the passenger's);
    - ``colour``: how plots and the flight-data view draw it (``#rrggbb``, one per phase).
    """

    flying: bool
    separated: bool
    duty: Duty
    on_deck: bool
    colour: str

    def __new__(cls, name: str, flying: bool, separated: bool, duty: Duty, on_deck: bool, colour: str) -> Phase:
        member = str.__new__(cls, name)
        member._value_ = name
        member.flying, member.separated, member.duty, member.on_deck = flying, separated, duty, on_deck
        member.colour = colour
        return member

    #            name          flying separated duty           on_deck colour
    PREFLIGHT = ("PREFLIGHT", False, False, Duty.WAIT, True, "#5b5b7a")
    STREAMING = ("STREAMING", False, False, Duty.WAIT, True, "#6b6b8f")
    ARMING = ("ARMING", False, False, Duty.WAIT, True, "#7a6bb0")
    OFFBOARD = ("OFFBOARD", False, False, Duty.WAIT, False, "#8f6bc4")
    JOIN = ("JOIN", True, False, Duty.WAIT, False, "#4e98e2")
    RIDING = ("RIDING", True, False, Duty.CARRY, False, "#3fb37f")
    TRANSIT = ("TRANSIT", True, False, Duty.REPOSITION, False, "#2e8b57")
    SEPARATED = ("SEPARATED", True, True, Duty.RELEASED, False, "#f7df71")
    NAVIGATING = ("NAVIGATING", True, True, Duty.RELEASED, False, "#f5a54d")
    ARRIVED = ("ARRIVED", True, True, Duty.RELEASED, False, "#9cd86b")
    RETURNING = ("RETURNING", True, True, Duty.RECOVER, False, "#61cbff")
    HOLDOFF = ("HOLDOFF", True, True, Duty.RECOVER, False, "#f1c232")
    APPROACH = ("APPROACH", True, True, Duty.RECOVER, False, "#6fa8dc")
    GO_AROUND = ("GO_AROUND", True, True, Duty.RECOVER, False, "#e06666")
    DOCKED = ("DOCKED", True, True, Duty.RECOVER, False, "#93c47d")
    HOME = ("HOME", True, True, Duty.PARK, False, "#76a5af")
    FALLBACK = ("FALLBACK", True, True, Duty.RELEASED, False, "#c27ba0")
    HOLD = ("HOLD", False, True, Duty.RELEASED, False, "#cfcfe0")
    LAND = ("LAND", False, True, Duty.RELEASED, False, "#b4a7d6")
    DONE = ("DONE", False, True, Duty.RELEASED, False, "#a8a8b8")
    ABORT = ("ABORT", False, False, Duty.STOP, False, "#f05b5b")


#: Phases in which the vehicle is ours in OFFBOARD and must stay there.
FLYING = frozenset(p for p in Phase if p.flying)
#: Phases before the separation latch fired (ABORT excluded): the carrier's state is needed.
BEFORE_SEPARATION = frozenset(p for p in Phase if not p.separated and p is not Phase.ABORT)
#: Phases after the separation latch fired.
AFTER_SEPARATION = frozenset(p for p in Phase if p.separated)
#: The phases that bring the passenger home to the carrier (mission.final_action = "return").
RECOVERY = frozenset({Phase.RETURNING, Phase.HOLDOFF, Phase.APPROACH, Phase.GO_AROUND, Phase.DOCKED})
#: The phases over the deck: the climb to the dock point, the ride, the recovery's holdoff, approach and
#: go-around, the contact and the ride home. The vehicle's velocity follows its position's rate closer there
#: (``mission.near_deck_velocity_bias_tau_s``): the speed relative to the deck decides the contact and the ride.
NEAR_DECK = frozenset({Phase.JOIN, Phase.RIDING, Phase.TRANSIT, Phase.HOLDOFF, Phase.APPROACH, Phase.GO_AROUND,
                       Phase.DOCKED, Phase.HOME})
#: The phases in which a downward range (the feed ``rangefinder``) is handed to the relative estimator (which
#: fuses it only with the vehicle over the deck by its estimate): all over the deck. Without them a ride that
#: loses the marker holds the deck's height by the vehicle's own height estimate, which wanders by decimetres
#: in seconds (docs/relnav.md, "The range on the ride").
RANGED = NEAR_DECK
#: The recovery and how it ends (home on the deck, or the fallback): the recovery's figure.
HOMEWARD = RECOVERY | {Phase.HOME, Phase.FALLBACK}
#: The flight to the target, from the separation to the handover (the arrival's figures).
OUTBOUND = frozenset({Phase.SEPARATED, Phase.NAVIGATING, Phase.ARRIVED})
#: Phases in which the vehicle must be armed: ours, switching to OFFBOARD or flying in it.
ARMED = frozenset({Phase.OFFBOARD, *FLYING})
#: Phases in which the vehicle must be in the air: not JOIN (it lifts off the deck, and PX4's land
#: detector takes seconds to see the take-off), nor DOCKED and HOME (on a carrier with a real deck
#: at the dock point the passenger touches it).
AIRBORNE = FLYING - {Phase.JOIN, Phase.DOCKED, Phase.HOME}
