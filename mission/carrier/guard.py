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
never crosses the circle. A measured inward speed above both the cap and every command sent
within ``delay_s`` (which the vehicle may still be following) by :data:`OVERSPEED_M_S` (a vehicle
that overshoots its speed setpoint) brakes outright: no inward motion until it is back under.
Against the cap alone a vehicle with a response delay tripped it a tick or two after the cap
first bound, every time (it still drives what it was told ``delay_s`` ago, which ``v_fly``
already counts): PX4's SIH rover (0.8 s) was stopped dead from 1.2 m/s and leapt off again under
its riding passenger, 0.49-0.52 m off the dock. Only the inward component is cut (a Remark-1 carrier slides along the circle), and the
cap falls at rate ``a`` as the carrier closes in: the guard brakes, it does not slam.

A robot that moves along its heading (:meth:`P3Guard.limit_heading`) with a turning model
(``turn_radius_m`` set) is guarded on its whole stopping path instead, a turn in progress
included (:mod:`mission.carrier.stopping`): its forward speed ``v`` is capped so that the path it
drives before it stands, ``s = v_fly max(delay_s, age_s) + v T + v^2 / 2a`` (``v_fly`` the
largest of its measured forward speed and the forward speeds sent since ``t_s - delay_s``), closes
on the target by at most the room left, in the plane (a target above the carrier's plane counted
in ``r_guard``), however it steers within its turning radius, plus ``turn_reserve_m``'s turn away
from where it then faces (a robot that cannot reverse drives on while it turns round). A command
that turns it away from the target (:func:`turns_away`: its bearing at least sideways from the
target, the turn the way that does not face it more), with every command in flight one too or a
stop, is not capped while that turn, at radius ``turn_reserve_m``, stays out of the circle: the
reserve kept for it is spent on it.

Its frame (:mod:`mission.carrier.frames`): given a :class:`~mission.carrier.frames.GuardFrame`, the
guard runs on the carrier's position moved into the frame it names (the passenger's, by the frames'
bias) and with the radius it names (``r_guard`` less the widening without a usable bias); its
velocity is the same in both frames.
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass

import numpy as np

from mission.carrier.frames import GuardFrame
from mission.carrier.stopping import allowed_path_m, closing_m, turn_away_m
from mission.core.geodesy import wrap_pi

OVERSPEED_M_S = 0.1  # [m/s] measured inward speed above the cap at which the guard brakes outright
AWAY_TURN_BAND_M = 3.0  # [m] a robot turns round away from a target (P3Guard.away_turn) within b c + this of it


@dataclass(frozen=True)
class GuardParams:
    """radius_m [m] ``b c - margin``; brake_decel_m_s2 [m/s^2] > 0; delay_s [s] >= 0 the
    vehicle's response delay; period_s [s] > 0 how long a command is held; turn_radius_m [m] >= 0
    the tightest turn of a robot that moves along its heading (None: guard only the inward
    component of its motion); turn_reserve_m [m] >= 0 the radius of its turn away from a target
    it faces (0: it can turn on the spot or reverse)."""

    radius_m: float
    brake_decel_m_s2: float
    delay_s: float = 0.0
    period_s: float = 0.01
    turn_radius_m: float | None = None
    turn_reserve_m: float = 0.0

    def __post_init__(self) -> None:
        if not (self.radius_m > 0 and self.brake_decel_m_s2 > 0 and self.delay_s >= 0 and self.period_s > 0
                and (self.turn_radius_m is None or self.turn_radius_m >= 0) and self.turn_reserve_m >= 0):
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

    Pure apart from that memory: times come from the caller's clock [s]. ``frame``: the frame
    it runs in (None: the carrier's own, as given).
    """

    def __init__(self, params: GuardParams, target: np.ndarray, planar: bool = True,
                 frame: GuardFrame | None = None) -> None:
        self.p = params
        self.frame = frame
        self.target = np.asarray(target, dtype=float)
        self.k = self.target.shape[-1]
        self.planar = planar  # the carrier moves in the first two axes only: cut the command there
        self._sent: collections.deque[tuple[float, float]] = collections.deque()
        self._sent_forward: collections.deque[tuple[float, float, bool]] = collections.deque()  # (t, v, away)

    @property
    def radius_m(self) -> float:
        """[m] ``r_guard`` now: ``b c - margin``, less its frame's widening."""
        return self.p.radius_m - (0.0 if self.frame is None else self.frame.widen_m)

    def _here(self, x_c: np.ndarray) -> np.ndarray:
        """[m] (k,) the carrier's position ``x_c`` [m] (its own frame) in the guard's frame."""
        x = np.asarray(x_c, dtype=float)[:self.k]
        return x if self.frame is None else x - self.frame.shift_ned_m(self.k, self.planar)

    def _geometry(self, x_c: np.ndarray) -> tuple[np.ndarray | None, float]:
        e = self.target[:self.k] - self._here(x_c)
        dist = float(math.sqrt(float(e @ e)))
        return (None if dist < 1e-9 else e / dist), dist - self.radius_m

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
        told = max((v for _, v in self._sent), default=0.0) if horizon > 0 else 0.0
        v_fly = max(v_fly, told)
        h_pred = h - v_fly * horizon
        cap = stopping_speed(h_pred, self.p.brake_decel_m_s2, self.p.period_s)
        return (0.0 if measured > max(cap, told) + OVERSPEED_M_S else cap), h, n

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
                      velocity_m_s: np.ndarray | None = None, age_s: float = 0.0,
                      bearing_rad: float | None = None) -> tuple[float, bool]:
        """For a robot that moves only along its heading ``yaw_rad`` [rad]: the largest forward
        speed [m/s] (<= ``speed_m_s``) whose inward component respects the cap (with a turning
        model: whose stopping path keeps out of the circle, or whose turn away does, steering
        to ``bearing_rad`` [rad], the command's bearing, None: unknown), and whether it was cut."""
        if self.p.turn_radius_m is not None:
            cap, away = self.heading_cap(t_s, x_c, yaw_rad, velocity_m_s, age_s, bearing_rad)
            out = min(speed_m_s, cap)
            self._sent_forward.append((t_s + max(age_s, 0.0), out, away))
            return out, out < speed_m_s
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

    def away_turn(self, x_c: np.ndarray, yaw_rad: float, bearing_rad: float, within_m: float) -> int:
        """Which way round a robot at ``x_c`` [m] heading ``yaw_rad`` [rad] turns onto the bearing
        ``bearing_rad`` [rad] (:func:`mission.carrier.tracking.track`'s ``turn``): 0 the shortest
        way, or, within ``within_m`` [m] of the target (as the law measures, in the guard's frame),
        for a turn of more than a right angle onto a bearing at least sideways from the target
        whose shortest way faces the target more on the way (:func:`turns_away`), the other way
        round (+1 towards east from north). Why: PX4's SIH rover, standing facing 25-35 deg off
        the target at 8 m, turned round onto its recovery course (180 deg, either way alike)
        through the target's bearing, and came 0.8-1.0 m closer before it drove away
        (docs/recovery.md)."""
        e = self.target[:self.k] - self._here(x_c)
        err = wrap_pi(bearing_rad - yaw_rad)
        if float(math.sqrt(float(e @ e))) > within_m or abs(err) <= 0.5 * math.pi:
            return 0
        to_target = math.atan2(float(e[1]), float(e[0]))
        if abs(wrap_pi(bearing_rad - to_target)) < 0.5 * math.pi or turns_away(yaw_rad, bearing_rad, to_target):
            return 0
        return -1 if err > 0 else 1

    def heading_cap(self, t_s: float, x_c: np.ndarray, yaw_rad: float, velocity_m_s: np.ndarray | None,
                    age_s: float = 0.0, bearing_rad: float | None = None) -> tuple[float, bool]:
        """The forward speed cap [m/s] of a robot with a turning model at ``x_c`` [m], heading
        ``yaw_rad`` [rad], moving at ``velocity_m_s`` [m/s] (None: unknown), a state measured at
        ``t_s`` [s] and ``age_s`` [s] old, and whether the command's bearing ``bearing_rad`` [rad]
        turns it away from the target (module docstring). The cap is 0 while its measured forward
        speed is over it by more than :data:`OVERSPEED_M_S`; inf where it cannot reach the
        circle, or where it turns away (so have the commands in flight) with the room to."""
        horizon = max(self.p.delay_s, age_s)
        while self._sent_forward and self._sent_forward[0][0] < t_s - self.p.delay_s - 1e-9:
            self._sent_forward.popleft()
        e = self.target[:self.k] - self._here(x_c)
        rho = math.hypot(float(e[0]), float(e[1]))
        above2 = float(e[2:] @ e[2:])  # the target's height over the carrier's plane, squared
        r2 = self.radius_m * self.radius_m
        if above2 >= r2:
            return math.inf, False
        if rho < 1e-9:
            return 0.0, False
        clearance = rho - math.sqrt(r2 - above2)
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        forward = 0.0 if velocity_m_s is None else c * float(velocity_m_s[0]) + s * float(velocity_m_s[1])
        to_target = math.atan2(float(e[1]), float(e[0]))
        phi = abs(wrap_pi(yaw_rad - to_target))
        if forward < -OVERSPEED_M_S:  # moving backwards: it faces the target as its back does
            phi = min(phi, math.pi - phi)
        radius = float(self.p.turn_radius_m or 0.0)
        away = (self.p.turn_reserve_m > 0 and bearing_rad is not None and forward >= -OVERSPEED_M_S
                and turns_away(yaw_rad, bearing_rad, to_target))
        if away and all(a or v == 0.0 for _, v, a in self._sent_forward):
            # It turns round, as the commands in flight do (or they stop it): what it still rolls
            # on its measured speed (all of it, if a stop is in flight), then the turn away.
            roll = 0.0 if all(a for _, _, a in self._sent_forward) else (
                abs(forward) * horizon + forward * forward / (2.0 * self.p.brake_decel_m_s2))
            end = max(phi - roll / radius, 0.0) if radius > 0 else (0.0 if roll > 0 else phi)
            if closing_m(phi, roll, radius) + turn_away_m(end, self.p.turn_reserve_m) <= clearance:
                return math.inf, True
        told = max((v for _, v, _ in self._sent_forward), default=0.0) if horizon > 0 else 0.0
        v_fly = max(abs(forward), told)
        path = allowed_path_m(phi, clearance, radius, self.p.turn_reserve_m)
        cap = stopping_speed(path - v_fly * horizon, self.p.brake_decel_m_s2, self.p.period_s)
        return (0.0 if abs(forward) > max(cap, told) + OVERSPEED_M_S else cap), away


def turns_away(yaw_rad: float, bearing_rad: float, to_target_rad: float) -> bool:
    """Whether a robot at heading ``yaw_rad`` [rad] that steers the shortest way to
    ``bearing_rad`` [rad] turns away from a target at bearing ``to_target_rad`` [rad]: the
    bearing at least sideways from it, and the turn one that does not face it more on the way."""
    if abs(wrap_pi(bearing_rad - to_target_rad)) < 0.5 * math.pi:
        return False
    rel = wrap_pi(yaw_rad - to_target_rad)  # its heading off the line to the target
    if abs(rel) >= 0.5 * math.pi or abs(rel) < 1e-6:
        return True  # facing away, the shortest turn stays in the back half; head-on, both ways are alike
    return (wrap_pi(bearing_rad - yaw_rad) > 0.0) == (rel > 0.0)
