"""The deck's landing point for the vehicle's own precision landing (pure): PX4's backstop.

:func:`deck_target` computes it from the passenger's own position estimate and the relative
estimate of the deck (``[relnav]``), in the vehicle's local NED frame, as PX4's LANDING_TARGET
carries it (:func:`mission.mavlink.px4.encode_landing_target`); the loop spaces the sends
(``relnav.landing_target_rate_hz``, :class:`mission.time.rate.RateGate`). No I/O: the mission loop sends it through
:meth:`mission.interfaces.Vehicle.send_landing_target`. What PX4 does with it, and what was seen
on PX4 SITL: docs/px4-precland.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class LandingTarget:
    """Where PX4 should land: ``position_ned_m`` the deck's landing point in the vehicle's local
    NED frame [m] (the frame of its LOCAL_POSITION_NED, z down, so its z is the height PX4's own
    z reads with the vehicle standing there); ``time_usec`` [us] when it held, on the sender's
    clock; ``yaw_rad`` [rad] the deck's heading (None: unknown, the identity quaternion is sent)."""

    position_ned_m: tuple[float, float, float]
    time_usec: int
    yaw_rad: float | None = None


def deck_target(own_position_ned_m: Any, relative_ned_m: Any, dock_offset_ned_m: Any, sample_t_s: float,
                yaw_rad: float | None = None) -> LandingTarget | None:
    """The landing point on the deck in the vehicle's local NED frame: its own position estimate
    ``own_position_ned_m`` [m] (at ``sample_t_s`` [s]) plus the relative estimate of the
    carrier's reference point ``relative_ned_m`` [m] (at the same time) plus the dock point's
    offset from that point ``dock_offset_ned_m`` [m] (``mission.dock_offset_ned_m``: where the
    vehicle sits when docked). ``time_usec`` is ``sample_t_s`` in microseconds. None if a value
    is not finite, or the time is negative."""
    point = np.asarray(own_position_ned_m, float) + np.asarray(relative_ned_m, float) + np.asarray(dock_offset_ned_m, float)
    if point.shape != (3,) or not bool(np.all(np.isfinite(point))) or not math.isfinite(sample_t_s) or sample_t_s < 0:
        return None
    if yaw_rad is not None and not math.isfinite(yaw_rad):
        yaw_rad = None
    return LandingTarget((float(point[0]), float(point[1]), float(point[2])), int(round(sample_t_s * 1e6)), yaw_rad)
