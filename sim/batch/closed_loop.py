"""Numeric closed loop of the paper, for one scenario or a batch of thousands at once (pure).

The loop is what a digital controller does: every ``dt_s`` the tick of :mod:`mission.core.tick`
computes the carrier's and the passenger's commands (law, latch, safety filter), which are held
over the step (zero-order hold, so positions advance exactly along straight segments). The
passenger is integrated in error coordinates ``e_pc = x_p - anchor`` (docs/how-it-works.md, facts about the law 2): an
exactly-docked passenger stays at ``e_pc = 0`` bit for bit, and leaves by increments that are not
lost below one ULP of an absolute position. The separation event (docked carrier reaching
``b c - departure_margin``) is located exactly inside its step (the step is a straight segment,
so the crossing is a quadratic root) and the carrier is put on the crossing point.

Arrays: batch axis first, ``(B, n)``; time series ``(K, B, ...)`` recorded every
``record_every`` steps. All units SI.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from mission.config.schema import Config
from mission.errors import ConfigError
from mission.core.law import norm, uniform, where_rows
from mission.model import model_from_config
from mission.core.tick import DEPARTURE_THRESHOLD_M, TickModel, carrier_tick, latch_point, passenger_tick, separation_due


@dataclass
class ClosedLoopResult:
    """Time series and per-scenario summary of a closed-loop run.

    Series (recorded): t [s] (K,); x_c, x_p [m] (K, B, n); u_c, u_p [m/s] (K, B, n); P [1/s]
    (K, B); separated (K, B). Summary arrays have shape (B,); NaN where undefined (no
    separation). ``summary(i)`` gives the JSON dict of scenario ``i``.
    """

    t: np.ndarray
    x_c: np.ndarray
    x_p: np.ndarray
    u_c: np.ndarray
    u_p: np.ndarray
    P: np.ndarray
    separated: np.ndarray
    target: np.ndarray
    separation_time_s: np.ndarray
    carrier_target_distance_at_separation_m: np.ndarray
    relative_speed_at_separation_m_s: np.ndarray
    relative_input_jump_m_s: np.ndarray
    departure_delay_s: np.ndarray
    final_passenger_target_distance_m: np.ndarray
    min_carrier_target_distance_m: np.ndarray
    min_obstacle_clearance_m: np.ndarray
    max_passenger_speed_m_s: np.ndarray
    max_passenger_accel_m_s2: np.ndarray
    max_offset_before_separation_m: np.ndarray
    p1: np.ndarray
    p2: np.ndarray
    p3: np.ndarray
    has_obstacles: bool
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def batch_size(self) -> int:
        return int(self.p1.shape[0])

    def distances(self, i: int = 0) -> dict[str, np.ndarray]:
        """|e_pc|, |e_tc|, |e_pt| [m] over time for scenario ``i`` (the paper's distance figure)."""
        tgt = self.target[i] if self.target.ndim == 2 else self.target
        return {
            "e_pc": norm(self.x_p[:, i] - self.x_c[:, i]),
            "e_tc": norm(tgt - self.x_c[:, i]),
            "e_pt": norm(self.x_p[:, i] - tgt),
        }

    def summary(self, i: int = 0) -> dict[str, Any]:
        """JSON-ready summary of scenario ``i`` (keys shared with the flight log's summary)."""

        def num(a: np.ndarray) -> float | None:
            v = float(a[i])
            return None if not np.isfinite(v) else round(v, 6)

        return {
            "separation_time_s": num(self.separation_time_s),
            "carrier_target_distance_at_separation_m": num(self.carrier_target_distance_at_separation_m),
            "relative_speed_at_separation_m_s": num(self.relative_speed_at_separation_m_s),
            "relative_input_jump_m_s": num(self.relative_input_jump_m_s),
            "departure_delay_s": num(self.departure_delay_s),
            "final_passenger_target_distance_m": num(self.final_passenger_target_distance_m),
            "min_carrier_target_distance_m": num(self.min_carrier_target_distance_m),
            "min_obstacle_clearance_m": num(self.min_obstacle_clearance_m) if self.has_obstacles else None,
            "max_passenger_speed_m_s": num(self.max_passenger_speed_m_s),
            "max_passenger_accel_m_s2": num(self.max_passenger_accel_m_s2),
            "p1": bool(self.p1[i]),
            "p2": bool(self.p2[i]),
            "p3": bool(self.p3[i]),
        }


def simulate(
    model: TickModel,
    carrier_start: np.ndarray,
    *,
    duration_s: float,
    dt_s: float,
    passenger_offset: np.ndarray | None = None,
    record_every: int = 10,
    p1_tolerance_m: float = 1e-6,
    p2_tolerance_m: float = 0.1,
    progress: Callable[[int], None] | None = None,
) -> ClosedLoopResult:
    """Integrate the closed loop from ``carrier_start`` [m] ((n,) or (B, n)).

    ``passenger_offset`` [m] is the passenger's start relative to the carrier (zero: exactly
    docked, Assumption 2). ``progress(k)`` is called with the number of steps done, now and then.
    """
    x_c = np.atleast_2d(np.asarray(carrier_start, dtype=float)).copy()
    B, n = x_c.shape
    target = np.broadcast_to(model.target, (B, n)).astype(float)
    model = TickModel(**{**model.__dict__, "target": target})
    anchor = x_c.copy()
    e_pc = np.zeros((B, n)) if passenger_offset is None else np.broadcast_to(passenger_offset, (B, n)).astype(float).copy()
    sep = np.zeros(B, dtype=bool)
    v_own = np.zeros((B, n))
    u_c_prev = np.zeros((B, n))
    u_p_prev = np.zeros((B, n))
    zero_velocity = np.zeros((B, n))
    zero_velocity.setflags(write=False)
    nan = np.full(B, np.nan)
    T, d_sep, rel_before, rel_after, depart = nan.copy(), nan.copy(), nan.copy(), nan.copy(), nan.copy()
    rel_before_vec = np.zeros((B, n))
    pending = np.zeros(B, dtype=bool)
    max_before = np.zeros(B)
    dist_ct = norm(target - anchor)  # |target - anchor| [m] of the current step, reused by the law
    min_ct = dist_ct.copy()  # (x_c == anchor at the start)
    has_obs = len(model.obstacles) > 0
    carrier_obs = model.obstacles.planar() if model.planar_carrier else model.obstacles
    min_clear = np.full(B, np.inf)
    max_speed = np.zeros(B)
    max_accel = np.zeros(B)
    use_accel = model.passenger_safety.max_accel_m_s2 is not None
    use_accel_c = model.carrier_safety.max_accel_m_s2 is not None
    steps = int(round(duration_s / dt_s))
    rec: dict[str, list] = {k: [] for k in ("t", "x_c", "x_p", "u_c", "u_p", "P", "sep")}

    # Per step every norm is computed once and reused; arrays the step owns are updated in place.
    for k in range(steps + 1):
        t = k * dt_s
        u_c = carrier_tick(x_c, sep, model, v_own, u_c_prev if use_accel_c else None, dt_s).u
        v_anchor = where_rows(sep, zero_velocity, u_c)  # read-only: u_c or zero_velocity itself when uniform
        pt = passenger_tick(anchor, v_anchor, e_pc, sep, model, u_p_prev if use_accel else None, dt_s, dist_ct)
        u_p = pt.u
        recording = k % record_every == 0 or k == steps
        x_p = anchor + e_pc if has_obs or recording else None
        # bookkeeping at time t
        if pending.any():
            rel_after_vec = pt.relative[pending]
            rel_after[pending] = norm(rel_after_vec)
            rel_before[pending] = norm(rel_after_vec - rel_before_vec[pending])
            pending[:] = False
        a = pt.e_pc_norm_m  # |e_pc| [m], as the law computed it
        docked = uniform(~sep)
        if docked is None:
            max_before = np.where(sep, max_before, np.maximum(max_before, a))
        elif docked:
            np.maximum(max_before, a, out=max_before)
        if docked is not True:
            newly_departed = sep & np.isnan(depart) & (a > DEPARTURE_THRESHOLD_M)
            depart[newly_departed] = t - T[newly_departed]
        np.minimum(min_ct, norm(target - x_c), out=min_ct)
        if has_obs:
            clear = model.obstacles.clearance(x_p).min(axis=-1)
            xc_obs = carrier_obs.clearance(x_c[:, :2]) if model.planar_carrier else carrier_obs.clearance(x_c)
            np.minimum(min_clear, np.minimum(clear, xc_obs.min(axis=-1)), out=min_clear)
        speed = norm(u_p)
        np.maximum(max_speed, speed, out=max_speed)
        if k > 0:
            accel = norm(u_p - u_p_prev)
            accel /= dt_s
            np.maximum(max_accel, accel, out=max_accel)
        if recording:
            for key, val in (("t", t), ("x_c", x_c), ("x_p", x_p), ("u_c", u_c), ("u_p", u_p), ("P", pt.P), ("sep", sep)):
                rec[key].append(np.copy(val))
            if progress is not None:
                progress(k)
        if k == steps:
            break
        # zero-order hold step
        x_c_new = u_c * dt_s
        x_c_new += x_c
        step_anchor = v_anchor * dt_s
        anchor_new = anchor + step_anchor
        de_pc = u_p - v_anchor
        de_pc *= dt_s
        e_pc += de_pc  # (e_pc is this loop's own array)
        dist_ct = norm(target - anchor_new)
        due = separation_due(anchor_new, sep, model, dist_ct)
        if due.any():
            theta, anchor_new[due] = latch_point(anchor[due], anchor_new[due], target[due], model)
            if model.carrier_mode == "stop":
                x_c_new[due] = anchor_new[due]
            v_own[due] = u_c[due]
            sep = sep | due
            T[due] = t + theta * dt_s
            d_sep[due] = dist_ct[due] = norm(target[due] - anchor_new[due])
            rel_before_vec[due] = pt.relative[due]
            pending = due.copy()
        x_c, anchor = x_c_new, anchor_new
        u_c_prev, u_p_prev = u_c, u_p

    final = norm(anchor + e_pc - target)
    p1 = sep & (max_before <= p1_tolerance_m) & ~np.isnan(depart)
    p2 = sep & (final <= p2_tolerance_m)
    p3 = min_ct > 0.0
    stack = {k: np.asarray(v) for k, v in rec.items()}
    return ClosedLoopResult(
        t=stack["t"], x_c=stack["x_c"], x_p=stack["x_p"], u_c=stack["u_c"], u_p=stack["u_p"], P=stack["P"],
        separated=stack["sep"], target=target,
        separation_time_s=T, carrier_target_distance_at_separation_m=d_sep,
        relative_speed_at_separation_m_s=rel_after, relative_input_jump_m_s=rel_before,
        departure_delay_s=depart, final_passenger_target_distance_m=final,
        min_carrier_target_distance_m=min_ct,
        min_obstacle_clearance_m=min_clear if has_obs else np.full(B, np.nan),
        max_passenger_speed_m_s=max_speed, max_passenger_accel_m_s2=max_accel,
        max_offset_before_separation_m=max_before, p1=p1, p2=p2, p3=p3, has_obstacles=has_obs,
        settings={"dt_s": dt_s, "duration_s": duration_s, "p1_tolerance_m": p1_tolerance_m, "p2_tolerance_m": p2_tolerance_m},
    )


def is_mission_config(cfg: Config) -> bool:
    """True when the configuration file has a ``[mission]`` section: it describes a flight
    (``marsupial run``), and ``simulate`` models what the flight does (:func:`simulate_config`)."""
    return "mission" in cfg.model_fields_set


def as_flown(cfg: Config) -> tuple[np.ndarray, float]:
    """The start of the law's carrier [m] and the P2 tolerance [m] of the scenario ``run`` flies.

    In a flight the passenger's law treats the carrier's *dock point* (carrier position +
    ``mission.dock_offset_ned_m``) as the carrier: it joins the dock point (JOIN), and riding
    starts there, docked, while the carrier is still at ``scenario.carrier_start`` (the carrier
    waits for RIDING). The carrier's own law is planar, so its motion does not depend on the
    offset. P2 is arrival within ``mission.arrival_radius_m``. Raises :class:`ConfigError` for
    what a flight refuses (dim 2)."""
    if cfg.scenario.dim != 3:
        raise ConfigError("scenario.dim", cfg.scenario.dim, "the file has a [mission] section, so it describes a "
                          "flight, which needs dim = 3 (local NED); remove [mission] to simulate the 2D law")
    start = np.asarray(cfg.scenario.carrier_start, dtype=float) + np.asarray(cfg.mission.dock_offset_ned_m, dtype=float)
    return start, cfg.mission.arrival_radius_m


def simulate_config(cfg: Config, progress: Callable[[int], None] | None = None, record_every: int = 10,
                    flown: bool | None = None) -> ClosedLoopResult:
    """Run the single scenario of a configuration, from the start of riding (t = 0).

    ``flown`` (default: :func:`is_mission_config`) simulates what ``run`` flies (:func:`as_flown`:
    the dock point as the law's carrier, the passenger docked on it, P2 within the arrival
    radius); otherwise the paper's scenario as written (``scenario.passenger_start`` relative to
    the carrier, P2 within ``sim.p2_tolerance_m``).
    """
    s = cfg.scenario
    flown = is_mission_config(cfg) if flown is None else flown
    if flown:
        start, p2_tol = as_flown(cfg)
        offset = None
    else:
        start, p2_tol = np.asarray(s.carrier_start, dtype=float), cfg.sim.p2_tolerance_m
        offset = None if s.passenger_start is None else np.asarray(s.passenger_start) - np.asarray(s.carrier_start)
    return simulate(
        model_from_config(cfg), start, duration_s=cfg.sim.duration_s,
        dt_s=cfg.sim.dt_s, passenger_offset=offset, record_every=record_every,
        p1_tolerance_m=cfg.sim.p1_tolerance_m, p2_tolerance_m=p2_tol, progress=progress,
    )


def target_reachable(cfg: Config, target: np.ndarray) -> np.ndarray:
    """Which targets (B, n) the filtered passenger can reach (B,): not inside an obstacle's
    keep-out disc (radius + ``safety.margin_m``) widened by ``sim.p2_tolerance_m``. A target in
    there is unreachable by design (the CBF keeps the passenger out), so P2 cannot hold."""
    obstacles = cfg.scenario.obstacle_set()
    if len(obstacles) == 0:
        return np.ones(target.shape[0], dtype=bool)
    return (obstacles.clearance(target) > cfg.safety.margin_m + cfg.sim.p2_tolerance_m).all(axis=-1)


def random_scenarios(cfg: Config, count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` random (carrier_start, target) pairs [m] that satisfy the paper's assumptions:
    the carrier at the origin, the target at a horizontal distance drawn from
    ``monte_carlo.distance_m`` (always > b c) and, in 3D, a height from ``monte_carlo.height_m``
    clipped to ``b c`` (planar carrier). A target the passenger cannot reach (inside an
    obstacle's keep-out disc, :func:`target_reachable`) is drawn again (the draws of the
    reachable ones do not change)."""
    rng = np.random.default_rng(seed)
    n = cfg.scenario.dim
    bc = cfg.law.params().separation_distance_m
    lo, hi = cfg.monte_carlo.distance_m
    h_lo, h_hi = cfg.monte_carlo.height_m
    sign = -1.0 if cfg.scenario.frame == "local_ned" else 1.0

    def draw(k: int) -> np.ndarray:
        dist = rng.uniform(max(lo, bc * 1.05), max(hi, bc * 1.1), k)
        ang = rng.uniform(0, 2 * np.pi, k)
        target = np.zeros((k, n))
        target[:, 0], target[:, 1] = dist * np.cos(ang), dist * np.sin(ang)
        if n == 3:
            target[:, 2] = sign * np.minimum(rng.uniform(h_lo, h_hi, k), 0.95 * bc)
        return target

    target = draw(count)
    for _ in range(1000):
        bad = ~target_reachable(cfg, target)
        if not bad.any():
            break
        target[bad] = draw(int(bad.sum()))
    return np.zeros((count, n)), target
