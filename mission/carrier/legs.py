"""The carrier's side of a mission with several targets (``scenario.targets``; pure).

The passenger's status names the leg it flies; the carrier follows it forward (never back), so the
law drives at that leg's target. Every target is hazardous whichever leg is flown: each has its
own P3 guard, and the command passes all of them. Before a leg after the first, the carrier drives
straight out from the leg's target until its dock point is ``b c + mission.leg_start_margin_m``
(and :data:`mission.config.legs.REPOSITION_SPARE_M`) from it: the paper's Assumption 1 at the leg's start.
That distance is measured where the passenger measures it, in the frame the targets are in: the
guards' frame (:mod:`mission.carrier.frames`: the passenger's while its shared bias is usable), and,
in the carrier's own frame, ``carrier.p3_unaligned_margin_m`` farther out (the frames may disagree
by that much; the passenger waits in TRANSIT until it sees the distance itself). Should it still
wait once the carrier stands there, the carrier takes the start farther out step by step
(:meth:`Legs.wait_out`).

Frames: NED [m], [m/s], in the scenario's dimension (2 or 3).
"""
from __future__ import annotations

import math

import numpy as np

from mission.carrier.frames import GuardFrame
from mission.carrier.guard import GuardParams, P3Guard
from mission.config.legs import REPOSITION_SPARE_M
from mission.core.tick import TickModel

#: [m] room beyond the leg-start distance that a non-holonomic carrier needs to turn towards the
#: leg's target before it stands (:meth:`Legs.turn_velocity`): its turn at a walking pace drives it
#: a metre or two, part of it towards the target
TURN_ROOM_M = 2.0
#: [rad] heading error to the leg's target at which the turn is done
LINED_UP_RAD = math.radians(10.0)
#: [s] how long the carrier stands at the leg's start while the passenger still waits (in TRANSIT: it
#: sees the dock point nearer than the start, its frame farther off than the carrier allowed for)
#: before it takes the start :data:`LEG_START_STEP_M` farther out, up to :data:`LEG_START_EXTRA_MAX_M`
#: in all (farther from the target is never less safe; standing, both would wait for the timeout)
LEG_START_PATIENCE_S = 20.0
LEG_START_STEP_M = 2.0  # [m]
LEG_START_EXTRA_MAX_M = 12.0  # [m] as far as configs/relnav.toml's bound on the frames' bias


class Legs:
    """``targets`` [m] (one per leg), the carrier's tick ``models`` for each, their P3 guards
    (``guard`` params; ``planar``), the dock offset [m] (one for every leg, or a team's: one per
    leg, the slot of the passenger that flies it, shape (legs, dim)) and the leg-start distance [m];
    ``frame`` the frame every guard runs in (None: the carrier's own)."""

    def __init__(self, targets: list[np.ndarray], models: list[TickModel], guard: GuardParams, planar: bool,
                 dock_offset_m: np.ndarray, leg_start_m: float, frame: GuardFrame | None = None) -> None:
        self.targets, self.models = targets, models
        self.guards = [P3Guard(guard, t, planar=planar, frame=frame) for t in targets]
        self.planar, self.start_m, self.frame = planar, leg_start_m + REPOSITION_SPARE_M, frame
        offsets = np.asarray(dock_offset_m, dtype=float)
        self.dock_offsets_m = offsets if offsets.ndim == 2 else np.tile(offsets, (len(targets), 1))
        self.index = 0
        self.extra_m = 0.0  # [m] the leg's start moved out this far while the passenger waited (:meth:`wait_out`)
        self._stood: tuple[float, float | None] | None = None  # (the last wait_out's time, standing since) [s]

    @property
    def model(self) -> TickModel:
        """The tick model of the leg flown (its target is the law's)."""
        return self.models[self.index]

    def follow(self, leg: int) -> bool:
        """Take the passenger's leg if it is a later one that exists; True when it changed."""
        if self.index < leg < len(self.targets):
            self.index, self.extra_m, self._stood = leg, 0.0, None
            return True
        return False

    def closest_m(self, x_c: np.ndarray) -> float:
        """Distance [m] from ``x_c`` to the nearest target."""
        return min(float(np.linalg.norm(t - x_c)) for t in self.targets)

    def _from_target(self, x_c: np.ndarray) -> tuple[np.ndarray, float]:
        """The carrier at ``x_c`` [m] (its own frame) from the leg's target, in the guards' frame
        [m], and how far its dock point is from the leg's start there [m] (< 0: nearer the target;
        the own frame's widening counts as nearer)."""
        x = np.asarray(x_c, dtype=float)
        if self.frame is not None:
            x = x - self.frame.shift_ned_m(x.shape[0], self.planar)
        target = self.targets[self.index]
        beyond = float(np.linalg.norm(target - (x + self.dock_offsets_m[self.index]))) - self.start_m
        return x - target, beyond - self.extra_m - (0.0 if self.frame is None else self.frame.widen_m)

    def wait_out(self, x_c: np.ndarray, now_s: float) -> bool:
        """Each repositioning step at ``now_s`` [s] (the passenger waits in TRANSIT): with the
        carrier at ``x_c`` [m] standing at the leg's start for :data:`LEG_START_PATIENCE_S`, the
        start moves :data:`LEG_START_STEP_M` farther out (True: it moved). A gap of over a second
        between the calls (another mode in between) starts the wait afresh."""
        last_s, since = self._stood if self._stood is not None else (None, None)
        if self._from_target(x_c)[1] < 0.0:  # not at the start: driving out to it
            since = None
        elif since is None or last_s is None or now_s - last_s > 1.0:
            since = now_s
        moved = since is not None and now_s - since >= LEG_START_PATIENCE_S and self.extra_m < LEG_START_EXTRA_MAX_M
        if moved:
            self.extra_m, since = min(self.extra_m + LEG_START_STEP_M, LEG_START_EXTRA_MAX_M), None
        self._stood = (now_s, since)
        return moved

    def reposition_velocity(self, x_c: np.ndarray, speed_m_s: float, room_m: float = 0.0) -> np.ndarray:
        """Straight away from the leg's target at ``speed_m_s`` [m/s] until the dock point is far
        enough for the leg to start (and ``room_m`` [m] farther), in the guards' frame (module
        docstring); zero from there."""
        away, beyond = self._from_target(x_c)
        if self.planar:
            away[2:] = 0.0
        size = float(np.linalg.norm(away))
        if beyond >= room_m or size < 1e-9:
            return np.zeros_like(away)
        return away / size * speed_m_s

    def turn_velocity(self, x_c: np.ndarray, yaw_rad: float, speed_m_s: float) -> np.ndarray | None:
        """A non-holonomic carrier at ``x_c`` [m] heading ``yaw_rad`` [rad], far enough out: towards
        the leg's target at ``speed_m_s`` [m/s] (planar), so that it stands facing it when the
        leg's ride begins; None when the turn is done (heading within :data:`LINED_UP_RAD` of the
        target's bearing) or there is no room for it (the dock point nearer the target than the
        leg-start distance, in the guards' frame)."""
        away, beyond = self._from_target(x_c)
        if beyond < 0.0:
            return None
        bearing = math.atan2(-float(away[1]), -float(away[0]))
        if abs(math.remainder(bearing - yaw_rad, 2 * math.pi)) <= LINED_UP_RAD:
            return None
        v = np.zeros_like(away)
        v[0], v[1] = speed_m_s * math.cos(bearing), speed_m_s * math.sin(bearing)
        return v
