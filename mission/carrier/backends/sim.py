"""The built-in kinematic carrier robot (``carrier.backend = "sim"``, the demo's default).

A planar robot of the scenario's dimension that moves exactly as commanded over each period:
holonomic (the command is its velocity, as in the paper), or along its heading (diff-drive,
Ackermann: forward speed and yaw rate, integrated with the heading at the middle of the step).
Its yaw is the heading of travel (holonomic) or its body heading. :class:`KinematicRobot` is its
motion alone (pure: the in-process recovery simulation, :mod:`sim.batch.recovery`, moves its
carrier with it); :class:`SimRobot` is the backend, whose time advances only through
:meth:`SimRobot.advance`, which the controller calls with the clock's step.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from mission.carrier.backends import OwnState
from mission.carrier.step import pad3
from mission.carrier.tracking import Tracked, heading_of
from mission.core.geodesy import wrap_pi
from mission.config.schema import Config

if TYPE_CHECKING:
    from mission.time.clock import Clock


def open_backend(cfg: Config, clock: Clock, session: object) -> SimRobot:
    """The built-in robot of ``cfg`` (``session`` unused)."""
    return SimRobot(cfg, clock)


def describe(cfg: Config) -> str:
    return "built-in kinematic robot"


class KinematicRobot:
    """The built-in robot's motion: at ``scenario.carrier_start`` [m], heading
    ``carrier.start_yaw_rad`` (default: towards the first target), holding the last command."""

    brakes_itself = False  # braking is the law's acceleration limit

    def __init__(self, cfg: Config) -> None:
        self.kind = cfg.carrier.kinematics
        self.position_m = np.array(cfg.scenario.carrier_start, dtype=float)
        self.velocity_m_s = np.zeros_like(self.position_m)
        e_tc = np.array(cfg.scenario.target, dtype=float) - self.position_m
        start_yaw = cfg.carrier.start_yaw_rad
        self.yaw_rad = math.atan2(e_tc[1], e_tc[0]) if start_yaw is None else float(start_yaw)
        self.speed_m_s = 0.0
        self.yaw_rate_rad_s = 0.0

    def advance(self, dt_s: float) -> None:
        """Move ``dt_s`` [s] under the held command."""
        if self.kind == "holonomic":
            self.position_m = self.position_m + self.velocity_m_s * dt_s
            return
        mid = self.yaw_rad + 0.5 * self.yaw_rate_rad_s * dt_s
        self.position_m = self.position_m.copy()
        self.position_m[:2] += heading_of(self.speed_m_s * dt_s, mid)
        self.yaw_rad = wrap_pi(self.yaw_rad + self.yaw_rate_rad_s * dt_s)
        self.velocity_m_s = np.zeros_like(self.position_m)
        self.velocity_m_s[:2] = heading_of(self.speed_m_s, self.yaw_rad)

    def state_at(self, t_s: float, ahead_s: float = 0.0) -> OwnState:
        """Its state stamped ``t_s`` [s]: where it is ``ahead_s`` [s] after its last integration,
        under the held command."""
        position = self.position_m + self.velocity_m_s * max(ahead_s, 0.0)
        return OwnState(t_s, pad3(position), pad3(self.velocity_m_s), self.yaw_rad)

    def command(self, cmd: Tracked) -> None:
        """Hold ``cmd`` from now on: holonomic, its velocity; else its forward speed and yaw rate."""
        if self.kind == "holonomic":
            v = np.zeros_like(self.position_m)
            n = min(v.shape[0], cmd.velocity_ned_m_s.shape[0])
            v[:n] = cmd.velocity_ned_m_s[:n]
            self.velocity_m_s = v
            if math.hypot(v[0], v[1]) > 1e-6:
                self.yaw_rad = math.atan2(v[1], v[0])
            return
        self.speed_m_s, self.yaw_rate_rad_s = cmd.speed_m_s, cmd.yaw_rate_rad_s
        self.velocity_m_s = np.zeros_like(self.position_m)
        self.velocity_m_s[:2] = heading_of(self.speed_m_s, self.yaw_rad)


class SimRobot(KinematicRobot):
    """The built-in robot as a backend, on ``clock``."""

    name = "sim"

    def __init__(self, cfg: Config, clock: Clock) -> None:
        super().__init__(cfg)
        self.clock = clock
        self.t_s = clock.now()  # [s] the clock time the integrated state refers to

    def advance(self, dt_s: float) -> None:
        self.t_s += dt_s
        super().advance(dt_s)

    def own_state(self) -> OwnState:
        # The state at the time it is stamped with: moved on under the held command from the time
        # it was integrated to (a loop stalled between its tick and its publication would
        # otherwise stamp a position of the tick with a later time, and a receiver sees it jump).
        now = self.clock.now()
        return self.state_at(now, now - self.t_s)

    def engage(self) -> None:
        pass

    def park(self) -> None:
        pass

    def lockstep_relay(self, session: object) -> None:
        return None  # the robot is the carrier's own code: it steps with it

    def control_fault(self) -> str | None:
        return None

    def close(self) -> None:
        pass
