"""The setpoint: what the mission asks of the vehicle in one tick (pure, one type end to end).

A :class:`Setpoint` is made by the tracking loop (:func:`mission.core.tracking.setpoint`, or a
phase that holds still), carried by the phase machine's ``Decision``, sent by the controller
through ``Vehicle.send`` and encoded to MAVLink only in :mod:`mission.mavlink.setpoints`.
Whether it is a velocity setpoint or a full one is decided where it is made; nothing downstream
looks at anything but its fields.

Frames: local NED. Units: position [m], velocity [m/s], acceleration [m/s^2], yaw [rad].
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Setpoint:
    """One setpoint in local NED.

    ``velocity_ned_m_s`` [m/s] always. A *full* setpoint also has ``position_ned_m`` [m] and
    ``acceleration_ned_m_s2`` [m/s^2] (PX4 closes position itself; velocity and acceleration are
    feed-forward) on the axes ``position_axes`` (north, east, down) names; on the others only the
    velocity is sent (their position and acceleration ignored: PX4's receiver reads them as NaN
    per axis). ``yaw_rad`` [rad] is an absolute heading, or None to keep the vehicle's.

    Invariants (checked on construction: ValueError naming the field): position and acceleration
    come together or not at all; north and east are sent or ignored together (PX4's position
    controller refuses one without the other, ``PositionControl::_inputValid``); a full setpoint
    sends at least one axis. Every vector has shape (3,) and is held as a float array.
    Finiteness is not required here (see :meth:`is_finite`); the encoder refuses a non-finite one.
    """

    velocity_ned_m_s: np.ndarray
    position_ned_m: np.ndarray | None = None
    acceleration_ned_m_s2: np.ndarray | None = None
    yaw_rad: float | None = None
    position_axes: tuple[bool, bool, bool] = (True, True, True)

    def __post_init__(self) -> None:
        if (self.position_ned_m is None) != (self.acceleration_ned_m_s2 is None):
            given, missing = (("position_ned_m", "acceleration_ned_m_s2") if self.acceleration_ned_m_s2 is None
                              else ("acceleration_ned_m_s2", "position_ned_m"))
            raise ValueError(f"setpoint has {given} but no {missing}: position and acceleration come together")
        for name in ("velocity_ned_m_s", "position_ned_m", "acceleration_ned_m_s2"):
            value = getattr(self, name)
            if value is None:
                continue
            vec = np.asarray(value, dtype=float)
            if vec.shape != (3,):
                raise ValueError(f"setpoint {name} must have shape (3,), got {vec.shape}")
            object.__setattr__(self, name, vec)
        if self.yaw_rad is not None:
            object.__setattr__(self, "yaw_rad", float(self.yaw_rad))
        axes = tuple(bool(a) for a in self.position_axes)
        if len(axes) != 3 or axes[0] != axes[1] or not any(axes):
            raise ValueError(f"setpoint position_axes {self.position_axes} must name north and east together "
                             "and at least one axis")
        object.__setattr__(self, "position_axes", axes)

    @classmethod
    def hold_still(cls) -> Setpoint:
        """Zero velocity, no position, keep the heading: the vehicle stays where it is."""
        return cls(np.zeros(3))

    @classmethod
    def velocity_only(cls, velocity_ned_m_s: np.ndarray, yaw_rad: float | None = None) -> Setpoint:
        """A velocity setpoint [m/s] (and optionally an absolute yaw [rad])."""
        return cls(velocity_ned_m_s, yaw_rad=yaw_rad)

    @classmethod
    def triple(cls, position_ned_m: np.ndarray, velocity_ned_m_s: np.ndarray, acceleration_ned_m_s2: np.ndarray,
               yaw_rad: float | None = None, position_axes: tuple[bool, bool, bool] = (True, True, True)) -> Setpoint:
        """A full setpoint: position [m], velocity [m/s], acceleration [m/s^2] (optionally yaw
        [rad]), position and acceleration sent on ``position_axes`` (north, east, down)."""
        return cls(velocity_ned_m_s, position_ned_m, acceleration_ned_m_s2, yaw_rad, position_axes)

    @property
    def full(self) -> bool:
        """True for position + velocity + acceleration (on :attr:`position_axes`), False for velocity only."""
        return self.position_ned_m is not None

    @property
    def kind(self) -> str:
        """``velocity`` (velocity only), ``full`` (position and acceleration on every axis),
        ``full_horizontal`` or ``full_vertical`` (on those axes only; velocity on the other)."""
        if not self.full:
            return "velocity"
        if all(self.position_axes):
            return "full"
        return "full_horizontal" if self.position_axes[0] else "full_vertical"

    def is_finite(self) -> bool:
        """Every component (and the yaw, if any) is finite."""
        vectors = [v for v in (self.velocity_ned_m_s, self.position_ned_m, self.acceleration_ned_m_s2) if v is not None]
        return all(bool(np.isfinite(v).all()) for v in vectors) and (self.yaw_rad is None or math.isfinite(self.yaw_rad))
