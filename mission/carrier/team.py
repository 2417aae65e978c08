"""The carrier of a team (pure: no clock, no I/O): one carrier, N passengers on their dock slots,
each with its own targets (``[team]``, docs/team.md), served in the mission's order.

The carrier hears each passenger's status (its phase and its leg, as one passenger's: a
:class:`~mission.carrier.modes.PassengerView` per passenger) and keeps one
:class:`~mission.carrier.step.CarrierStepper` (its mode machine, law, legs, P3 guards of every
target, keep-out rows of the other targets, recovery course, calibration), driven by the view
of the passenger it serves:

- **Which targets are done.** Target ``k`` of the mission (``scenario.targets[k]``) is done once
  its passenger's status says it separated on the leg of ``k`` (or flies a later leg): latched.
- **Whom it serves.** The next target of the mission's order that is not done, if its passenger
  is on board for it (its duty WAIT, CARRY or REPOSITION, on the leg of that target): the paper's
  ``u_c = k_c e_tc`` towards it (APPROACHING), the stepper's leg being that target. Otherwise (that
  passenger is away, or every target is done) the carrier keeps serving the passenger it served
  last, exactly as the single-passenger carrier does after separation: it stops (or keeps its own
  plan), drives the recovery course while that passenger comes home, repositions and approaches
  its next target when it docks again, parks when it is home. It never skips ahead in the order
  (docs/team.md: Assumption 1 is checked for this order).
- **Several coming home.** While any passenger comes home (duty RECOVER) and the one served has
  left or is home, the stepper sees that one's recovery: the carrier keeps one steady recovery
  course through the whole recovery queue (:mod:`mission.phases.queue`: one approaches at a time)
  and parks only once nobody comes home. A passenger on board for the next target is still served
  first (the order above); the others wait for the course (the queue holds them off meanwhile).
- **A hand-over** (the passenger served changes: the next one is on board) starts the stepper's
  mode afresh for it (:meth:`CarrierStepper.hand_over`); its command goes on from where it is, at
  the acceleration limit, and every target's P3 guard still caps it.
- **The start.** The carrier leaves only once no passenger is still joining (duty WAIT): the
  stepper is told the first passenger holds until then.
- **The announcement.** :meth:`TeamCarrier.heading_for` is the target the carrier serves; a
  passenger separates only when it is its own (:func:`mission.phases.types.my_turn`), so an
  on-board passenger whose target lies within ``b c`` of the carrier's path never leaves early.

With one passenger (a file without ``[team]``, or a team of one) the stepper sees that
passenger's own view, unchanged: the carrier is the single-passenger carrier, command for command.

Frames: local NED [m], [m/s]; times [s] of the caller's clock.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from mission.carrier.backends import OwnState
from mission.carrier.modes import CarrierMode, PassengerView
from mission.carrier.step import CarrierStepper, Command, ModeUpdate
from mission.config.passenger import carrier_config, has_team
from mission.config.schema import Config
from mission.core.tick import TickModel
from mission.phases.phase import Duty

#: Duties of a passenger on board: joining (before the first ride), riding, riding while the carrier repositions.
ON_BOARD = frozenset({Duty.WAIT, Duty.CARRY, Duty.REPOSITION})


class TeamCarrier:
    """The carrier of ``cfg``'s team (one passenger without ``[team]``) on a backend that
    ``brakes_itself`` or not (see the module docstring)."""

    def __init__(self, cfg: Config, brakes_itself: bool) -> None:
        own, docks = carrier_config(cfg)
        n = len(own.scenario.legs())
        self.names = [p.name for p in cfg.team.passengers] if has_team(cfg) else ["passenger"]
        #: each passenger's targets: indices into the mission's targets, in its order
        self.targets_of = [list(p.targets) for p in cfg.team.passengers] if has_team(cfg) else [list(range(n))]
        self.owner = [next(i for i, own_targets in enumerate(self.targets_of) if k in own_targets) for k in range(n)]
        self.stepper = CarrierStepper(own, brakes_itself, dock_offsets_m=np.asarray(docks) if has_team(cfg) else None)
        self.done: set[int] = set()  # the mission's targets whose passenger separated for them
        self.focus = self.owner[0] if n else 0  # the passenger served
        self.hand_overs: list[tuple[int, int]] = []  # (from, to) passengers, in order

    @property
    def mode(self) -> CarrierMode:
        return self.stepper.mode

    @property
    def model(self) -> TickModel:
        """The tick model of the target served."""
        return self.stepper.model

    def heading_for(self) -> int:
        """The index of the target the carrier serves (``scenario.targets``): what it announces."""
        return self.stepper.legs.index

    def heading_for_ned_m(self) -> np.ndarray:
        """[m] NED the target the carrier serves (:meth:`heading_for`)."""
        return np.asarray(self.stepper.legs.targets[self.stepper.legs.index], dtype=float)

    def mission_target(self, i: int, view: PassengerView) -> int:
        """The index in the mission's targets of the leg passenger ``i`` flies (its ``view.leg``)."""
        own = self.targets_of[i]
        return own[min(max(view.leg, 0), len(own) - 1)]

    def next_target(self) -> int | None:
        """The first target of the mission's order not done yet (None: all done)."""
        return next((k for k in range(len(self.owner)) if k not in self.done), None)

    def update_mode(self, views: Sequence[PassengerView]) -> ModeUpdate:
        """Learn from every passenger's ``views`` (one per passenger, in the team's order) which
        targets are done, choose the passenger served, and take the stepper's next mode on its view."""
        if len(views) != len(self.targets_of):
            raise ValueError(f"{len(views)} passenger views for a team of {len(self.targets_of)}")
        for i, view in enumerate(views):
            if view.phase is None:
                continue
            own = self.targets_of[i]
            leg = min(max(view.leg, 0), len(own) - 1)
            self.done.update(own[:leg])
            if view.phase.separated or view.separated:
                self.done.add(own[leg])
        nxt = self.next_target()
        if nxt is not None:
            i = self.owner[nxt]
            view = views[i]
            duty = view.phase.duty if view.phase is not None else Duty.WAIT
            if i != self.focus and duty in ON_BOARD and self.mission_target(i, view) == nxt:
                self.hand_overs.append((self.focus, i))
                self.focus = i
                self.stepper.hand_over(replace(view, leg=nxt))
        view = replace(views[self.focus], leg=self.mission_target(self.focus, views[self.focus]))
        coming = self.coming_home(views)
        focus_duty = view.phase.duty if view.phase is not None else Duty.WAIT
        if coming is not None and focus_duty not in ON_BOARD and focus_duty is not Duty.RECOVER:
            # the one served has left (or is home) while others come home: the course is theirs
            other = views[coming]
            view = replace(view, phase=other.phase, separated=True, lost=other.lost)
        if self.stepper.mode is CarrierMode.WAITING and any(
                (v.phase.duty if v.phase is not None else Duty.WAIT) is Duty.WAIT
                for j, v in enumerate(views) if j != self.focus):
            view = replace(view, holding=True)  # another passenger is still joining: the carrier waits for it
        return self.stepper.update_mode(view)

    @staticmethod
    def coming_home(views: Sequence[PassengerView]) -> int | None:
        """The first passenger whose status says it comes home (duty RECOVER: returning, holding
        off, approaching, docking), or None. While one does and the passenger served has left
        (or is home), the carrier keeps its recovery course: one course through every recovery
        of the queue (:mod:`mission.phases.queue`), never parked under an approach."""
        return next((j for j, v in enumerate(views) if v.phase is not None and v.phase.duty is Duty.RECOVER), None)

    def decide(self, state: OwnState, dt_s: float, age_s: float, now_s: float,
               recovery_velocity_m_s: np.ndarray | None = None) -> Command:
        """The stepper's command (:meth:`CarrierStepper.decide`)."""
        return self.stepper.decide(state, dt_s, age_s, now_s, recovery_velocity_m_s)
