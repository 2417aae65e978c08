"""The P3 guard of the carrier: the carrier never comes closer to the target than
``r_guard = b c - margin`` [m], whatever the passenger does (never separates, vanishes, lies).

It acts last (after the law, the CBF filter and the tracking law), independent of the passenger's
phase, on the carrier's own position and velocity, the target and the command about to be sent.
The command's component towards the target is capped at the speed from which the carrier can
still stop before the guard circle::

    h      = |e_tc| - r_guard                   (|e_tc| as the law measures it: a planar carrier's
                                                 distance to a target above its plane counts the height)
    v_fly  = max(measured inward speed, inward commands sent since t_s - delay_s)
    h_pred = h - v_fly max(delay_s, age_s)      (where the vehicle is when this command acts)
    v_in  <= a (sqrt(T^2 + 2 h_pred / a) - T),  0 if h_pred <= 0   (v T + v^2 / 2a = h_pred)

``a`` [m/s^2] braking deceleration, ``delay_s`` [s] the vehicle's response delay (including a
fresh own state's age), ``age_s`` [s] the own state's age now (counted as already driven), ``T``
[s] the control period. A vehicle that brakes at ``a`` and obeys each command after ``delay_s``
never crosses the circle. A measured inward speed above the cap by :data:`OVERSPEED_M_S` (a
vehicle that overshoots its speed setpoint) brakes outright: no inward motion until it is back
under. Only the inward component is cut (a Remark-1 carrier slides along the circle), and the
cap falls at rate ``a`` as the carrier closes in: the guard brakes, it does not slam.
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass

import numpy as np

OVERSPEED_M_S = 0.1  # [m/s] measured inward speed above the cap at which the guard brakes outright


@dataclass(frozen=True)
class GuardParams:
    """radius_m [m] ``b c - margin``; brake_decel_m_s2 [m/s^2] > 0; delay_s [s] >= 0 the
    vehicle's response delay; period_s [s] > 0 how long a command is held."""

    radius_m: float
    brake_decel_m_s2: float
    delay_s: float = 0.0
    period_s: float = 0.01

    def __post_init__(self) -> None:
        if not (self.radius_m > 0 and self.brake_decel_m_s2 > 0 and self.delay_s >= 0 and self.period_s > 0):
            raise ValueError(f"invalid guard parameters {self}")


@dataclass(frozen=True)
class GuardResult:
    """u [m/s] the guarded command (same shape as the input); cap_m_s [m/s] the inward speed
    allowed here; clearance_m [m] ``h``; active: the guard changed the command."""

    u: np.ndarray
    cap_m_s: float
    clearance_m: float
    active: bool


def stopping_speed(distance_m: float, decel_m_s2: float, hold_s: float) -> float:
    """Largest speed [m/s] ``v`` with ``v hold_s + v^2 / (2 decel) <= distance_m`` (0 if none)."""
    if distance_m <= 0.0:
        return 0.0
    return decel_m_s2 * (math.sqrt(hold_s * hold_s + 2.0 * distance_m / decel_m_s2) - hold_s)


class P3Guard:
    """The guard with its memory of the inward commands still in flight (see the module docstring).

    Pure apart from that memory: times come from the caller's clock [s].
    """

    def __init__(self, params: GuardParams, target: np.ndarray, planar: bool = True) -> None:
        self.p = params
        self.target = np.asarray(target, dtype=float)
        self.k = self.target.shape[-1]
        self.planar = planar  # the carrier moves in the first two axes only: cut the command there
        self._sent: collections.deque[tuple[float, float]] = collections.deque()

    def _geometry(self, x_c: np.ndarray) -> tuple[np.ndarray | None, float]:
        e = self.target[:self.k] - np.asarray(x_c, dtype=float)[:self.k]
        dist = float(math.sqrt(float(e @ e)))
        return (None if dist < 1e-9 else e / dist), dist - self.p.radius_m

    def cap(self, t_s: float, x_c: np.ndarray, velocity_m_s: np.ndarray | None,
            age_s: float = 0.0) -> tuple[float, float, np.ndarray | None]:
        """(inward speed cap [m/s], clearance h [m], unit vector towards the target or None) for a
        state measured at ``t_s`` [s] and ``age_s`` [s] old now. The cap is 0 while the measured
        inward speed is over it by more than :data:`OVERSPEED_M_S`."""
        n, h = self._geometry(x_c)
        horizon = max(self.p.delay_s, age_s)  # from the measurement to when this command acts
        while self._sent and self._sent[0][0] < t_s - self.p.delay_s - 1e-9:  # (sent times are t_s + age)
            self._sent.popleft()
        if n is None:
            return 0.0, h, None
        measured = 0.0 if velocity_m_s is None else float(np.asarray(velocity_m_s, dtype=float)[:self.k] @ n)
        v_fly = max(0.0, measured)
        if self._sent and horizon > 0:
            v_fly = max(v_fly, max(v for _, v in self._sent))
        h_pred = h - v_fly * horizon
        cap = stopping_speed(h_pred, self.p.brake_decel_m_s2, self.p.period_s)
        return (0.0 if measured > cap + OVERSPEED_M_S else cap), h, n

    def limit(self, t_s: float, x_c: np.ndarray, u: np.ndarray, velocity_m_s: np.ndarray | None = None,
              age_s: float = 0.0) -> GuardResult:
        """Cap the inward component of the velocity command ``u`` [m/s] ((2,) or (3,)) of a
        carrier at ``x_c`` [m] moving at ``velocity_m_s`` [m/s] (measured; None: unknown), a state
        ``age_s`` [s] old."""
        u = np.asarray(u, dtype=float)
        cap, h, n = self.cap(t_s, x_c, velocity_m_s, age_s)
        now = t_s + max(age_s, 0.0)
        if n is None:  # on the target: no inward direction; stop (the guard was already broken)
            self._sent.append((now, 0.0))
            return GuardResult(np.zeros_like(u), 0.0, h, bool(np.any(u != 0.0)))
        inward = float(u[:self.k] @ n)
        if inward <= cap:
            self._sent.append((now, inward))
            return GuardResult(u, cap, h, False)
        out = u.copy()
        m = n.copy()
        if self.planar:
            m[2:] = 0.0  # u . n changes only through the plane's components
        out[:self.k] = u[:self.k] - (inward - cap) * m / float(m @ m)  # m @ m > 0: inward > cap >= 0
        self._sent.append((now, cap))
        return GuardResult(out, cap, h, True)

    def limit_heading(self, t_s: float, x_c: np.ndarray, speed_m_s: float, yaw_rad: float,
                      velocity_m_s: np.ndarray | None = None, age_s: float = 0.0) -> tuple[float, bool]:
        """For a robot that moves only along its heading ``yaw_rad`` [rad]: the largest forward
        speed [m/s] (<= ``speed_m_s``) whose inward component respects the cap, and whether it was cut."""
        cap, _, n = self.cap(t_s, x_c, velocity_m_s, age_s)
        now = t_s + max(age_s, 0.0)
        if n is None:
            self._sent.append((now, 0.0))
            return 0.0, speed_m_s != 0.0
        cos_in = math.cos(yaw_rad) * n[0] + math.sin(yaw_rad) * n[1]
        inward = speed_m_s * cos_in
        if inward <= cap:
            self._sent.append((now, inward))
            return speed_m_s, False
        self._sent.append((now, cap))
        return cap / cos_in, True  # cos_in > 0 here (inward > cap >= 0 with speed >= 0)
