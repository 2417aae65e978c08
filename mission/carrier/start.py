"""The carrier's gentle start (pure): how fast its command may grow while it has not moved yet,
and how far ahead of its measured speed it may run once it moves.

A rover with static friction stands until its throttle overcomes it, then leaps; asked to speed
up gently while it stands, it breaks free at a low speed instead, and from there the law's own
acceleration limit applies (what was measured on PX4's SIH rover: docs/carrier.md, a gentle start).

Rule: while the vehicle's measured speed is below ``moving_m_s`` [m/s], the command's speed
[m/s] grows by at most ``accel_m_s2 * dt_s`` per step (its direction kept, never turned); it may
always shrink. Scaling a command down never breaks a satisfied barrier (the CBF filter's
constraints hold for every speed between 0 and the filtered one along its direction), and the
P3 guard acts after it.

Once it moves (measured speed at least ``moving_m_s``), with a lead ``lead_m_s`` > 0 [m/s], the
command's speed is at most the measured speed plus the lead (:func:`speed_lead`): a rover that
crawls while its command runs on at the law's acceleration winds up its speed loop and leaps to
the command (0.2 -> 0.9 m/s in 0.25 s on PX4's SIH rover, while a passenger rode its dock).
"""
from __future__ import annotations

import numpy as np

MOVING_M_S = 0.15  # [m/s] measured speed above which the carrier counts as moving (SIH rover's EKF at rest: <= 0.05)


def gentle_start(u: np.ndarray, u_prev: np.ndarray, measured_speed_m_s: float, accel_m_s2: float, dt_s: float,
                 moving_m_s: float = MOVING_M_S) -> np.ndarray:
    """The command ``u`` [m/s] with its speed capped at ``|u_prev| + accel_m_s2 * dt_s`` while the
    vehicle's ``measured_speed_m_s`` [m/s] is below ``moving_m_s``; ``u`` itself otherwise (or
    when ``accel_m_s2 <= 0``: off)."""
    if accel_m_s2 <= 0 or measured_speed_m_s >= moving_m_s:
        return u
    speed = float(np.linalg.norm(u))
    cap = float(np.linalg.norm(u_prev)) + accel_m_s2 * max(dt_s, 0.0)
    return u * (cap / speed) if speed > cap else u


def speed_lead(u: np.ndarray, measured_speed_m_s: float, lead_m_s: float, moving_m_s: float = MOVING_M_S) -> np.ndarray:
    """The command ``u`` [m/s] with its speed capped at ``measured_speed_m_s + lead_m_s`` [m/s]
    once the vehicle moves (``measured_speed_m_s >= moving_m_s``); ``u`` itself otherwise (or when
    ``lead_m_s <= 0``: off). Its direction is kept."""
    if lead_m_s <= 0 or measured_speed_m_s < moving_m_s:
        return u
    speed = float(np.linalg.norm(u))
    cap = measured_speed_m_s + lead_m_s
    return u * (cap / speed) if speed > cap else u
