"""The team's Monte-Carlo (the team targets; docs/team.md "The team's Monte-Carlo"): random team
scenarios, each a whole mission of 2 or 3 passengers flown in-process by their own steps
(:class:`sim.batch.team_mission.TeamWorld`), and the figures the issue asks for.

A scenario is ``configs/team.toml`` (or the file given) with:

- 2 or 3 passengers on their slots (:data:`SLOTS`: port and starboard 1.5 m apart as in
  ``configs/team.toml``, or three round the deck's centre 1.13 m apart, the least spacing
  allowed, 1.1 m);
- 2 to 4 targets, each passenger at least one, in the mission's order, drawn 14 to 34 m from the
  carrier's start on any bearing, 2 to 5 m up; a draw that the configuration refuses (the
  paper's assumptions, the legs' starts, every passenger flying alone: :mod:`mission.config`), or
  one whose slot keeps its dock point beyond b c of its target from some side (:func:`reachable`,
  which the configuration does not check yet), or one where two targets' carrier keep-outs overlap
  (:func:`keep_outs_apart`, nor that), is drawn again, so every scenario satisfies them;
- each passenger's vehicle estimate erring as PX4 SITL's (``estimate_error``), its own seed;
- in 30 % of the scenarios one passenger reports a battery low enough that it must land
  (``team.queue_battery_pct``), the others a full one: the queue's battery order.

Figures per scenario (:func:`fly`): each leg docked within 2 approaches, its P1-P3, its jump at the
separation (the command's step at the latch, and the step of the command less the carrier's
velocity: the flight log's ``input_jump_m_s`` and ``relative_input_jump_m_s``) and its largest
command step at a phase switch; the largest reference step at a queue switch (waiting -> its turn,
or back); pairwise: the least true distance of two passengers both in the air away from the deck
(:data:`AIR`) against ``safety.passenger_separation_m`` (a *violation*: more than
:data:`VIOLATION_M` inside what the barrier keeps, as :mod:`bench.pairwise_mc` counts it), and of
any two at any time against ``team.passenger_span_m`` (touching); the moment of the largest
shortfall (:func:`_worst`: the pair, their phases, the true and the reported distance); the carrier inside a keep-out;
whether every leg that did not dock ended safe (in PX4's Hold or Land, or DONE; not aborted, not
still flying at the time limit, no pairwise violation).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mission.config.schema import Config, from_dict
from mission.errors import ConfigError
from mission.phases import Phase
from sim.batch.team_mission import HOVER_RAISE_M, TeamWorld

#: Both passengers of a pair in one of these: in the air, away from the deck (the barrier's distance holds).
AIR = frozenset({Phase.SEPARATED, Phase.NAVIGATING, Phase.ARRIVED, Phase.RETURNING, Phase.HOLDOFF,
                 Phase.GO_AROUND, Phase.FALLBACK})
VIOLATION_M = 0.01  # [m] a pair this much inside what the barrier keeps is a violation
SAFE_END = frozenset({Phase.HOLD, Phase.LAND, Phase.DONE})
LOW_BATTERY_SHARE = 0.3
#: [m] north, east of each slot from the carrier's reported position, 0.5 m up, for 2 and 3 passengers
SLOTS = {2: [(0.0, -0.75), (0.0, 0.75)],
         3: [(round(0.65 * math.cos(a), 3), round(0.65 * math.sin(a), 3)) for a in (0.0, 2.0944, 4.1888)]}
REACH_MARGIN_M = 0.05  # [m] a dock point must come this much inside b c of its target (:func:`reachable`)


@dataclass
class Scenario:
    """One drawn team: its index, configuration, the vehicles' seed and each passenger's battery [%]."""

    index: int
    cfg: Config
    seed: int
    batteries: list[float | None]
    n_passengers: int
    n_targets: int


def draw(index: int, rng: np.random.Generator, base: dict[str, Any], tries: int = 200) -> Scenario:
    """Scenario ``index`` drawn from ``rng`` on the team configuration ``base`` (a nested dict)."""
    for _ in range(tries):
        n = int(rng.integers(2, 4))
        k = int(rng.integers(max(n, 2), 5))
        offsets = SLOTS[n]
        owners = list(rng.permutation(list(range(n)) + list(rng.integers(0, n, k - n))))
        targets = []
        for _t in range(k):
            r, bearing = rng.uniform(14.0, 34.0), rng.uniform(-math.pi, math.pi)
            targets.append([round(r * math.cos(bearing), 2), round(r * math.sin(bearing), 2),
                            round(-rng.uniform(2.0, 5.0), 2)])
        data = {key: dict(value) if isinstance(value, dict) else value for key, value in base.items()}
        data["scenario"] = {**data["scenario"], "targets": targets}
        data["scenario"].pop("target", None)
        data["team"] = {**{key: v for key, v in data["team"].items() if key not in ("slots", "passengers")},
                        "slots": [{"name": f"s{j}", "offset_ned_m": [x, y, -0.5]} for j, (x, y) in enumerate(offsets)],
                        "passengers": [{"name": f"p{j}", "system_id": j + 1, "slot": f"s{j}",
                                        "targets": [t for t in range(k) if owners[t] == j]} for j in range(n)]}
        try:
            cfg = from_dict(data)
        except ConfigError:
            continue
        if not reachable(cfg) or not keep_outs_apart(cfg):
            continue
        batteries: list[float | None] = [None] * n
        if rng.uniform() < LOW_BATTERY_SHARE:
            batteries = [90.0] * n
            batteries[int(rng.integers(0, n))] = float(cfg.recovery.battery_reserve_pct + cfg.team.queue_battery_pct - 1.0)
        return Scenario(index, cfg, int(rng.integers(0, 2**31)), batteries, n, k)
    raise RuntimeError(f"no valid team drawn in {tries} tries")


def reachable(cfg: Config) -> bool:
    """Whether the carrier can bring every target's dock point within b c of it from any side: it
    stops at its P3 guard (b c - carrier.p3_margin_m from the target, 3D, on its plane), and a
    slot to the side (as the simulation flies it, hovering :data:`HOVER_RAISE_M` above it) on the
    far side may still be farther than b c. The configuration's legs check treats the dock point
    as standing where the carrier stands (docs/team.md, "The links"), so such a team loads, and
    its passenger would ride for ever: not a scenario that satisfies the paper's assumptions."""
    bc = cfg.law.params().separation_distance_m
    guard = bc - cfg.carrier.p3_margin_m
    ground = float(cfg.scenario.carrier_start[2])
    for k, target in enumerate(cfg.scenario.legs()):
        owner = cfg.team.passengers[cfg.team.owners(len(cfg.scenario.legs()))[k]]
        slot = cfg.team.slots[cfg.team.slot_index(owner.slot)].offset_ned_m
        up = ground - float(target[2])
        across = math.sqrt(max(guard * guard - up * up, 0.0)) + math.hypot(slot[0], slot[1])
        dock_z = ground + slot[2] - HOVER_RAISE_M
        if math.hypot(across, float(target[2]) - dock_z) > bc - REACH_MARGIN_M:
            return False
    return True


def keep_outs_apart(cfg: Config) -> bool:
    """Whether no two targets' carrier keep-outs overlap: on the carrier's plane each target's
    keep-out is the disc its b c sphere cuts (``sqrt((b c)^2 - h^2)``, ``h`` its height above the
    plane) plus ``safety.margin_m`` (the barrier's row, :func:`mission.core.tick.target_keep_outs`),
    and every two must lie at least the sum of theirs apart, horizontally. Overlapping, they form
    one wall that the carrier's barrier rows hold it behind: on its way from one target's
    separation circle to the next target it stood in the corner where two met, every way ahead
    closing on one of them, until the mission's time ran out (#52 of seed 1: targets 13.0 m apart,
    rows of 8.0 and 7.3 m). The law drives the carrier straight at its target; reaching b c of
    each target past the others is the paper's assumption (b c < |e_tc(0)|) carried to several
    targets, not something a reactive barrier can plan round."""
    bc = cfg.law.params().separation_distance_m
    ground = float(cfg.scenario.carrier_start[2])
    margin = cfg.safety.margin_m
    legs = [np.asarray(t, dtype=float) for t in cfg.scenario.legs()]
    radius = [math.sqrt(max(bc * bc - (ground - float(t[2])) ** 2, 0.0)) + margin for t in legs]
    for i in range(len(legs)):
        for j in range(i + 1, len(legs)):
            if math.hypot(*(legs[i][:2] - legs[j][:2])) < radius[i] + radius[j]:
                return False
    return True


def scenarios(count: int, seed: int, base: dict[str, Any]) -> list[Scenario]:
    """``count`` scenarios from ``seed`` (the same list for the same arguments)."""
    rng = np.random.default_rng(seed)
    return [draw(i, rng, base) for i in range(count)]


def fly(sc: Scenario, estimate_error: float = 1.0) -> dict[str, Any]:
    """Fly scenario ``sc`` once and measure it (module docstring): one row."""
    w = TeamWorld(sc.cfg, estimate_error=estimate_error, seed=sc.seed, batteries=sc.batteries)
    n = len(w.members)
    D = sc.cfg.safety.passenger_separation_m
    span = sc.cfg.team.passenger_span_m
    kept = np.zeros((n, n))  # what the barrier keeps of each pair in its current window in the air [m]
    shortfall = np.zeros((n, n))
    worst: dict[str, Any] | None = None  # the pair and the moment of the largest shortfall (:func:`_worst`)
    least_air, least_any = math.inf, math.inf
    prev_u = [None] * n
    prev_q = [False] * n
    queue_step = 0.0
    queue_switches = 0
    docked_order: list[str] = []
    while not w.done:
        w.tick()
        x = [m.vehicle.true_position for m in w.members]
        for i in range(n):
            for j in range(i + 1, n):
                d = float(np.linalg.norm(x[i] - x[j]))
                least_any = min(least_any, d)
                if w.members[i].state.phase in AIR and w.members[j].state.phase in AIR:
                    least_air = min(least_air, d)
                    kept[i, j] = min(D, max(kept[i, j], d))
                    if kept[i, j] - d > shortfall.max() and kept[i, j] - d > 0.0:
                        worst = _worst(w, i, j, d, float(kept[i, j]))
                    shortfall[i, j] = max(shortfall[i, j], kept[i, j] - d)
                else:
                    kept[i, j] = 0.0
        for i, m in enumerate(w.members):
            rec = m.state.recovery
            queued = rec is not None and rec.queued_since_s is not None
            u = None if m.state.u_ref is None else np.asarray(m.state.u_ref, dtype=float)
            if queued != prev_q[i] and u is not None and prev_u[i] is not None:
                queue_step = max(queue_step, float(np.linalg.norm(u - prev_u[i])))
                queue_switches += 1
            prev_q[i], prev_u[i] = queued, u
            if m.state.phase is Phase.DOCKED and (not docked_order or docked_order[-1] != m.name):
                docked_order.append(m.name)
    report = w.report()
    legs, unsafe = [], []
    violation = float(shortfall.max()) > VIOLATION_M
    for i, m in enumerate(w.members):
        s = report["passengers"][m.name]
        flown = s.get("legs") or [s]
        done = {leg["leg"]: leg for leg in m.state.legs_done}
        for k, leg in enumerate(flown):
            if "p1" not in leg:
                continue
            rec = done.get(k)
            contact = rec.get("contact") if rec else None
            docked = bool(contact) and not str(rec.get("outcome", "")).startswith("fallback")
            attempts = contact.get("attempts") if contact else None
            row = {"passenger": m.name, "leg": k, "docked": docked, "attempts": attempts,
                   "within_2": docked and attempts is not None and attempts <= 2,
                   "p1": bool(leg.get("p1")), "p2": bool(leg.get("p2")), "p3": bool(leg.get("p3")),
                   "switch_jump_m_s": leg.get("max_phase_switch_jump_m_s"),
                   "switch_excess_m_s": leg.get("max_phase_switch_excess_m_s"),
                   "separation_jump_m_s": leg.get("input_jump_m_s"),
                   "relative_separation_jump_m_s": leg.get("relative_input_jump_m_s"),
                   "outcome": None if rec is None else rec.get("outcome")}
            legs.append(row)
            if not docked:
                safe = m.state.phase in SAFE_END and not violation
                row["safe"] = safe
                if not safe:
                    unsafe.append(f"{m.name} leg {k}: {m.state.phase.value}")
    battery_first = None
    if any(b is not None for b in sc.batteries):
        low = w.members[int(np.argmin([b if b is not None else 1e9 for b in sc.batteries]))].name
        battery_first = low
    return {"index": sc.index, "passengers": sc.n_passengers, "targets": sc.n_targets, "seed": sc.seed,
            "batteries": sc.batteries, "duration_s": report["duration_s"], "legs": legs,
            "pair_min_air_m": None if math.isinf(least_air) else round(least_air, 3),
            "pair_min_any_m": round(least_any, 3), "pair_shortfall_m": round(float(shortfall.max()), 4),
            "violation": violation, "worst_pair": worst, "touched": least_any < span,
            "queue_switches": queue_switches, "queue_step_m_s": round(queue_step, 4),
            "carrier_inside_keep_out": any(report["carrier"]["inside_keep_out"]),
            "carrier_closest_m": min(report["carrier"]["closest_m"]), "guard_radius_m": report["carrier"]["guard_radius_m"],
            "docked_order": docked_order, "low_battery": battery_first, "unsafe": unsafe,
            "phases": {m.name: m.state.phase.value for m in w.members}}


def _worst(w: TeamWorld, i: int, j: int, d_m: float, kept_m: float) -> dict[str, Any]:
    """The moment of a pair's shortfall in ``w`` (now): the two passengers and their phases, the
    time [s], the true distance ``d_m`` [m], what the count keeps ``kept_m`` [m], and the distance
    of the two positions their vehicles report [m] (what their barriers see): a pair whose reported
    distance held what the recovery keeps (``safety.passenger_separation_m + safety.margin_m``)
    came short in truth by their estimates' errors, not by their steps."""
    a, b = w.members[i], w.members[j]
    t = w.t[-1]
    reported = np.asarray(a.vehicle.report(t).position_ned_m, dtype=float) - np.asarray(b.vehicle.report(t).position_ned_m,
                                                                                      dtype=float)
    return {"t_s": round(t, 2), "pair": [a.name, b.name], "phases": [a.state.phase.value, b.state.phase.value],
            "true_m": round(d_m, 3), "kept_m": round(kept_m, 3), "reported_m": round(float(np.linalg.norm(reported)), 3)}


def table_violations(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each violating scenario of ``rows`` (:func:`fly`): its index and its worst pair's moment (:func:`_worst`)."""
    return [{"index": r["index"], **(r.get("worst_pair") or {})} for r in rows if r["violation"]]


def table(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The Monte-Carlo's figures over ``rows`` (:func:`fly`)."""
    legs = [leg for r in rows for leg in r["legs"]]
    within = sum(leg["within_2"] for leg in legs)
    not_docked = [leg for leg in legs if not leg["docked"]]
    jumps = [leg["switch_jump_m_s"] for leg in legs if leg["switch_jump_m_s"] is not None]
    air = [r["pair_min_air_m"] for r in rows if r["pair_min_air_m"] is not None]
    return {
        "scenarios": len(rows), "legs": len(legs),
        "legs_docked_within_2": within, "legs_docked_within_2_pct": round(100.0 * within / max(len(legs), 1), 2),
        "legs_docked_first_approach": sum(leg["docked"] and leg["attempts"] == 1 for leg in legs),
        "legs_not_docked": len(not_docked), "not_docked_safe": sum(bool(leg.get("safe")) for leg in not_docked),
        "p1_p3_all_legs": sum(leg["p1"] and leg["p2"] and leg["p3"] for leg in legs),
        "pairwise_violations": sum(r["violation"] for r in rows),
        "violations_at": table_violations(rows),
        "largest_shortfall_m": max((r["pair_shortfall_m"] for r in rows), default=0.0),
        "least_distance_in_air_m": min(air, default=None),
        "least_distance_any_m": min((r["pair_min_any_m"] for r in rows), default=None),
        "touched": sum(r["touched"] for r in rows),
        "largest_phase_switch_step_m_s": max(jumps, default=None),
        "largest_phase_switch_excess_m_s": max((leg["switch_excess_m_s"] for leg in legs
                                                if leg.get("switch_excess_m_s") is not None), default=None),
        "largest_separation_jump_m_s": max((leg["separation_jump_m_s"] for leg in legs
                                            if leg.get("separation_jump_m_s") is not None), default=None),
        "largest_relative_separation_jump_m_s": max((leg["relative_separation_jump_m_s"] for leg in legs
                                                     if leg.get("relative_separation_jump_m_s") is not None), default=None),
        "largest_queue_switch_step_m_s": max((r["queue_step_m_s"] for r in rows), default=0.0),
        "queue_switches": sum(r["queue_switches"] for r in rows),
        "carrier_inside_keep_out": sum(r["carrier_inside_keep_out"] for r in rows),
        "low_battery_scenarios": sum(r["low_battery"] is not None for r in rows),
    }
