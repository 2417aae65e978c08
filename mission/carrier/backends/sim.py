"""The built-in kinematic carrier robot (``carrier.backend = "sim"``, the demo's default).

A planar robot of the scenario's dimension that moves exactly as commanded over each period:
holonomic (the command is its velocity, as in the paper), or along its heading (diff-drive,
Ackermann: forward speed and yaw rate, integrated with the heading at the middle of the step).
Its yaw is the heading of travel (holonomic) or its body heading. Time advances only through
:meth:`SimRobot.advance`, which the controller calls with the clock's step.
"""
from __future__ import annotations

import math

import numpy as np

from mission.carrier.backends import OwnState
from mission.carrier.controller import _pad3
from mission.carrier.tracking import Tracked, heading_of
from mission.core.geodesy import wrap_pi
from mission.time.clock import Clock
from mission.config.schema import Config


def open_backend(cfg: Config, clock: Clock, session: object) -> SimRobot:
    """The built-in robot of ``cfg`` (``session`` unused)."""
    return SimRobot(cfg, clock)


def describe(cfg: Config) -> str:
    return "built-in kinematic robot"


class SimRobot:
    """Kinematic carrier at ``scenario.carrier_start`` [m], heading ``carrier.start_yaw_rad``
    (default: towards the target)."""

    name = "sim"
    brakes_itself = False  # braking is the law's acceleration limit

    def __init__(self, cfg: Config, clock: Clock) -> None:
        self.clock = clock
        self.kind = cfg.carrier.kinematics
        self.position_m = np.array(cfg.scenario.carrier_start, dtype=float)
        self.velocity_m_s = np.zeros_like(self.position_m)
        e_tc = np.array(cfg.scenario.target, dtype=float) - self.position_m
        start_yaw = cfg.carrier.start_yaw_rad
        self.yaw_rad = math.atan2(e_tc[1], e_tc[0]) if start_yaw is None else float(start_yaw)
        self.speed_m_s = 0.0
        self.yaw_rate_rad_s = 0.0
        self.t_s = clock.now()  # [s] the clock time the integrated state refers to

    def advance(self, dt_s: float) -> None:
        self.t_s += dt_s
        if self.kind == "holonomic":
            self.position_m = self.position_m + self.velocity_m_s * dt_s
            return
        mid = self.yaw_rad + 0.5 * self.yaw_rate_rad_s * dt_s
        self.position_m = self.position_m.copy()
        self.position_m[:2] += heading_of(self.speed_m_s * dt_s, mid)
        self.yaw_rad = wrap_pi(self.yaw_rad + self.yaw_rate_rad_s * dt_s)
        self.velocity_m_s = np.zeros_like(self.position_m)
        self.velocity_m_s[:2] = heading_of(self.speed_m_s, self.yaw_rad)

    def own_state(self) -> OwnState:
        # The state at the time it is stamped with: moved on under the held command from the time
        # it was integrated to (a loop stalled between its tick and its publication would
        # otherwise stamp a position of the tick with a later time, and a receiver sees it jump).
        now = self.clock.now()
        position = self.position_m + self.velocity_m_s * max(now - self.t_s, 0.0)
        return OwnState(now, _pad3(position), _pad3(self.velocity_m_s), self.yaw_rad)

    def engage(self) -> None:
        pass

    def park(self) -> None:
        pass

    def lockstep_relay(self, session: object) -> None:
        return None  # the robot is the carrier's own code: it steps with it

    def control_fault(self) -> str | None:
        return None

    def command(self, cmd: Tracked) -> None:
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

    def close(self) -> None:
        pass
