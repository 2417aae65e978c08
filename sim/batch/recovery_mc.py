"""The recovery's Monte-Carlo: random scenarios drawn, each flown by :func:`sim.batch.recovery.fly`
(the flights of a batch share the flight before the recovery), and the report of the targets.

Targets (docs/recovery.md): >= 99 % docked within 2 attempts, every other one fell back safely
(the fallback handed the vehicle to Hold or Land), none touched the deck outside the contact
conditions, and the carrier never inside any target's guard circle (``b c -
carrier.p3_margin_m``, its true position against every target, not only the leg's own). ``marsupial simulate CONFIG --monte-carlo N`` prints :func:`format_report`;
``python -m bench.recovery_mc`` adds the cost.
"""
from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from mission.config.schema import Config
from mission.phases import Phase
from sim.batch.recovery import Flight, Scenario, World, before_recovery, fly

SPEED_RANGE_M_S = (0.0, 2.0)  # [m/s] the carrier's speed on its recovery course
TURN_MAX_DEG = 45.0  # [deg] largest turn during the approach
TURN_RATE_RANGE_DEG_S = (5.0, 30.0)  # [deg/s] how fast it turns
TURN_START_RANGE_S = (0.0, 8.0)  # [s] after the first approach began


def random_scenarios(count: int, seed: int, estimate_error: float = 0.0) -> list[Scenario]:
    """``count`` scenarios drawn with ``seed``: speed uniform in :data:`SPEED_RANGE_M_S`, heading
    uniform over the circle, a turn uniform in +-:data:`TURN_MAX_DEG` at a rate uniform in
    :data:`TURN_RATE_RANGE_DEG_S` beginning uniformly in :data:`TURN_START_RANGE_S` after the
    first approach began."""
    rng = np.random.default_rng(seed)
    return [Scenario(speed_m_s=float(rng.uniform(*SPEED_RANGE_M_S)), heading_deg=float(rng.uniform(0.0, 360.0)),
                     turn_deg=float(rng.uniform(-TURN_MAX_DEG, TURN_MAX_DEG)),
                     turn_rate_deg_s=float(rng.uniform(*TURN_RATE_RANGE_DEG_S)),
                     turn_after_s=float(rng.uniform(*TURN_START_RANGE_S)), estimate_error=estimate_error,
                     seed=int(rng.integers(0, 2**31 - 1)), index=i) for i in range(count)]


@dataclass
class MonteCarloReport:
    """What a batch of recoveries gave: each flight's figures (``rows``) and the rates over them."""

    rows: list[dict[str, Any]]
    seed: int | None = None
    guard_m: float | None = None  # [m] the P3 guard circle's radius, b c - carrier.p3_margin_m (None: not judged)

    @property
    def count(self) -> int:
        return len(self.rows)

    def fraction(self, predicate: Callable[[dict[str, Any]], bool]) -> float:
        return sum(1 for r in self.rows if predicate(r)) / self.count if self.count else float("nan")

    @property
    def docked_within_1(self) -> float:
        return self.fraction(lambda r: r["docked"] and r["attempts"] <= 1)

    @property
    def docked_within_2(self) -> float:
        return self.fraction(lambda r: r["docked"] and r["attempts"] <= 2)

    @property
    def docked(self) -> float:
        return self.fraction(lambda r: r["docked"])

    @property
    def fallbacks(self) -> dict[str, int]:
        """{reason: count} of the flights that fell back (reasons with their numbers dropped)."""
        out: dict[str, int] = {}
        for r in self.rows:
            if not r["docked"]:
                key = _reason_kind(r["outcome"])
                out[key] = out.get(key, 0) + 1
        return out

    @property
    def go_around_reasons(self) -> dict[str, int]:
        """{why (numbers dropped): count} over every go-around of every flight."""
        out: dict[str, int] = {}
        for r in self.rows:
            for why in r["go_arounds"]:
                key = _reason_kind(why)
                out[key] = out.get(key, 0) + 1
        return out

    @property
    def legs_held(self) -> float | None:
        """The share of flights in which every leg held P1-P3 (None: one target per flight)."""
        if not any(r["legs"] for r in self.rows):
            return None
        return self.fraction(lambda r: bool(r["legs"]) and all(leg["p1"] and leg["p2"] and leg["p3"] for leg in r["legs"]))

    @property
    def max_separation_jump_m_s(self) -> float | None:
        """The largest jump of the relative command at a leg's separation [m/s] (None: one target per flight)."""
        jumps = [leg["relative_input_jump_m_s"] for r in self.rows for leg in r["legs"]
                 if leg.get("relative_input_jump_m_s") is not None]
        return max(jumps) if jumps else None

    @property
    def max_riding_offset_m(self) -> float | None:
        """The largest riding offset [m] of any leg (the vehicle's distance from the dock point while
        riding, P1's figure, :func:`leg_row`; None: one target per flight)."""
        offsets = [leg["max_offset_before_separation_m"] for r in self.rows for leg in r["legs"]
                   if leg.get("max_offset_before_separation_m") is not None]
        return max(offsets) if offsets else None

    def largest(self, key: str) -> float | None:
        """The largest of a row's figure ``key`` over every flight (None: in none)."""
        values = [r[key] for r in self.rows if r.get(key) is not None]
        return max(values) if values else None

    @property
    def closest_any_target_m(self) -> float | None:
        """The carrier's closest approach to any target [m] over every flight (its true position, 3D)."""
        values = [r["closest_any_target_m"] for r in self.rows if r.get("closest_any_target_m") is not None]
        return min(values) if values else None

    @property
    def inside_guard(self) -> list[dict[str, Any]]:
        """Flights whose carrier came inside a target's guard circle (:attr:`guard_m`, less
        :data:`GUARD_TOLERANCE_M`)."""
        if self.guard_m is None:
            return []
        return [r for r in self.rows if r.get("closest_any_target_m") is not None
                and r["closest_any_target_m"] < self.guard_m - GUARD_TOLERANCE_M]

    @property
    def unsafe(self) -> list[dict[str, Any]]:
        """Flights that did not end safely: the mission did not complete (DONE: docked and handed to
        Hold above the carrier, or fallen back to its point and handed to Hold or Land)."""
        return [r for r in self.rows if not r["safe_end"]]

    def contact_percentiles(self, key: str) -> dict[str, float | None]:
        """p50, p95 and max of a contact figure over every docking (every leg's, with several targets)."""
        contacts = [c for r in self.rows for c in ([leg["contact"] for leg in r["legs"]] if r["legs"] else [r["contact"]])]
        values = np.array([c[key] for c in contacts if c is not None], dtype=float)
        if not values.size:
            return {"p50": None, "p95": None, "max": None}
        return {"p50": float(np.percentile(values, 50)), "p95": float(np.percentile(values, 95)),
                "max": float(values.max())}

    def as_dict(self) -> dict[str, Any]:
        keys = ("horizontal_error_m", "horizontal_relative_speed_m_s", "vertical_relative_speed_m_s")
        return {
            "simulated": "mission", "scenarios": self.count, "seed": self.seed,
            "docked_within_1_attempt": self.docked_within_1, "docked_within_2_attempts": self.docked_within_2,
            "docked": self.docked, "fallbacks": self.fallbacks, "go_arounds": self.go_around_reasons,
            "unsafe_ends": len(self.unsafe),
            "contact": {k: self.contact_percentiles(k) for k in keys},
            "deck_violations": sum(r["deck_violations"] for r in self.rows),
            "true_deck_violations": sum(r["true_deck_violations"] for r in self.rows),
            "max_phase_switch_jump_m_s": max((r["max_phase_switch_jump_m_s"] or 0.0) for r in self.rows) if self.rows else None,
            "p3": all(r["p3"] for r in self.rows),
            "every_leg_p1_p3": self.legs_held, "max_separation_jump_m_s": self.max_separation_jump_m_s,
            "max_riding_offset_m": self.max_riding_offset_m, "max_ridden_offset_m": self.largest("ridden_offset_m"),
            "max_ridden_carrier_step_m_s": self.largest("ridden_carrier_step_m_s"),
            "closest_any_target_m": self.closest_any_target_m, "guard_m": self.guard_m,
            "inside_guard": [r["index"] for r in self.inside_guard],
            "rows": self.rows,
        }


def _reason_kind(why: str) -> str:
    """A reason with its numbers as ``x`` and its parentheses dropped, so that equal reasons count
    together ("2.10 m off the glide path (cone 0.91 m)" -> "x m off the glide path")."""
    text = re.sub(r"\s*\([^)]*\)", "", why.removeprefix("fallback: "))
    return re.sub(r"[-+]?\d+(\.\d+)?", "x", text).strip()


def closest_to_targets_m(f: Flight) -> list[float | None]:
    """The carrier's closest approach [m] to each target of the mission over the whole flight
    (its true position, 3D, against every target, whichever leg it served); None where the record
    has no carrier position."""
    x_c = f.record.vec("x_c_true")
    x_c = x_c[np.isfinite(x_c).all(axis=1)]
    targets = f.record.info.get("targets") or [f.record.info["target_ned_m"]]
    if not len(x_c):
        return [None for _ in targets]
    return [round(float(np.linalg.norm(x_c - np.asarray(t, dtype=float), axis=1).min()), 4) for t in targets]


RIDDEN = (Phase.RIDING.value, Phase.TRANSIT.value)  # the phases in which the passenger rides the dock point


def ridden_figures(f: Flight) -> tuple[float | None, float | None]:
    """While the passenger rides the dock point (RIDING, and TRANSIT before a leg): its largest
    distance from it [m], and the largest change of the carrier's reported velocity between two
    ticks [m/s] (at most one of its steps when the carrier steps slower than the controller ticks),
    which is what the rider has to follow; None: never ridden."""
    r = f.record
    ridden = np.isin(r.phase, RIDDEN)
    if not ridden.any():
        return None, None
    offset = np.linalg.norm(r.vec("x_p")[ridden] - r.vec("dock")[ridden], axis=1)
    both = ridden[1:] & ridden[:-1]
    step = np.linalg.norm(np.diff(r.vec("v_c")[:, :2], axis=0), axis=1)[both]
    offset, step = offset[np.isfinite(offset)], step[np.isfinite(step)]
    return (round(float(offset.max()), 6) if offset.size else None, round(float(step.max()), 6) if step.size else None)


def flight_row(f: Flight) -> dict[str, Any]:
    """One flight's line of the Monte-Carlo report (``closest_to_targets_m``: the carrier's closest
    approach to each target, ``closest_any_target_m`` the least of them, :func:`closest_to_targets_m`;
    ``ridden_offset_m`` and ``ridden_carrier_step_m_s``: :func:`ridden_figures`)."""
    s = f.summary
    closest = closest_to_targets_m(f)
    ridden_offset, ridden_step = ridden_figures(f)
    known = [c for c in closest if c is not None]
    safe_end = f.state.phase is Phase.DONE
    return {**f.scenario.as_dict(), "docked": f.docked, "attempts": f.attempts, "outcome": s.get("recovery_outcome"),
            "contact": s.get("contact"), "deck_violations": int(s.get("deck_violations") or 0),
            "true_deck_violations": f.true_deck_violations, "safe_end": safe_end,
            "end_phase": f.state.phase.value, "abort": None if f.state.reason is None else f"{f.state.reason}: {f.state.detail}",
            "max_phase_switch_jump_m_s": s.get("max_phase_switch_jump_m_s"), "p3": bool(s.get("p3")),
            "go_arounds": f.go_arounds,
            "flight_time_s": round(float(f.record.t[-1]), 2) if len(f.record.t) else 0.0,
            "closest_to_targets_m": closest, "closest_any_target_m": min(known) if known else None,
            "ridden_offset_m": ridden_offset, "ridden_carrier_step_m_s": ridden_step,
            "legs": [leg_row(leg) for leg in s.get("legs") or []]}


def leg_row(leg: dict[str, Any]) -> dict[str, Any]:
    """One leg's figures in a flight's row (several targets): its outcome, P1-P3, its separation
    (time from its riding, carrier-target distance, the relative command's jump), contact, the
    carrier's closest approach to the leg's own target [m] (``min_carrier_target_distance_m``) and
    the riding offset [m] P1 is judged on (``max_offset_before_separation_m``: the vehicle's largest
    distance from the dock point while riding, against ``mission.dock_tolerance_m``)."""
    keys = ("leg", "outcome", "p1", "p2", "p3", "separation_time_s", "carrier_target_distance_at_separation_m",
            "relative_input_jump_m_s", "final_passenger_target_distance_m", "contact", "min_carrier_target_distance_m",
            "max_offset_before_separation_m")
    return {k: leg.get(k) for k in keys}


def badness(row: dict[str, Any]) -> tuple[int, int, float]:
    """How bad a flight of the report went, for picking the worst: missed a target (not docked
    within 2 attempts, an unsafe end, a deck violation, a leg that broke P1-P3; the carrier inside a
    target's guard circle is :meth:`MonteCarloReport.inside_guard`'s) first, then the
    attempts, then the contact's horizontal error."""
    missed = (not (row["docked"] and row["attempts"] <= 2)) or not row["safe_end"] or row["deck_violations"] > 0 \
        or not all(leg["p1"] and leg["p2"] and leg["p3"] for leg in row["legs"])
    error = row["contact"]["horizontal_error_m"] if row["contact"] else float("inf")
    return int(missed), row["attempts"], error


def monte_carlo(cfg: Config, scenarios: Sequence[Scenario],
                progress: Callable[[Flight], None] | None = None) -> tuple[MonteCarloReport, Flight | None]:
    """Fly every scenario (``progress(flight)`` after each); the report and the worst flight
    (:func:`badness`). Scenarios with an exact estimate share the flight up to the recovery
    (:func:`before_recovery`: the same flight as :func:`fly` gives, tick for tick)."""
    rows: list[dict[str, Any]] = []
    shared: World | None = None
    worst: tuple[tuple[int, int, float], Flight] | None = None
    for sc in scenarios:
        if sc.estimate_error > 0:  # each estimate errs its own way from the start
            f = fly(cfg, sc)
        else:
            shared = shared or before_recovery(cfg)
            f = shared.copy().with_scenario(sc).run().flight()
        row = flight_row(f)
        if worst is None or badness(row) > worst[0]:
            worst = (badness(row), f)
        rows.append(row)
        if progress is not None:
            progress(f)
    guard_m = cfg.law.b * cfg.law.c - cfg.carrier.p3_margin_m
    return MonteCarloReport(rows, guard_m=guard_m), None if worst is None else worst[1]


DOCKED_WITHIN_2_TARGET = 0.99  # the share of scenarios docked within 2 attempts
GUARD_TOLERANCE_M = 0.01  # [m] how far inside the guard circle a carrier may come before it counts as inside


def report_ok(report: MonteCarloReport) -> bool:
    """The targets: >= :data:`DOCKED_WITHIN_2_TARGET` docked within 2 attempts, every other one
    fell back safely, no deck violation, the carrier never inside a target's guard circle
    (:attr:`MonteCarloReport.inside_guard`); with several targets also every leg's P1-P3 in every
    flight."""
    d = report.as_dict()
    return (report.docked_within_2 >= DOCKED_WITHIN_2_TARGET and not report.unsafe
            and d["deck_violations"] == 0 and d["true_deck_violations"] == 0
            and report.legs_held in (None, 1.0) and not report.inside_guard)


def format_report(report: MonteCarloReport) -> str:
    """The Monte-Carlo table (what ``marsupial simulate CONFIG --monte-carlo N`` prints)."""
    d = report.as_dict()
    n = report.count

    def pct(x: float) -> str:
        return f"{x:.1%} ({round(x * n)}/{n})"

    def spread(key: str, unit: str) -> str:
        c = d["contact"][key]
        return "-" if c["p50"] is None else f"p50 {c['p50']:.3f}  p95 {c['p95']:.3f}  max {c['max']:.3f} {unit}"

    fallbacks = "; ".join(f"{k} x{v}" for k, v in sorted(d["fallbacks"].items())) or "none"
    go_arounds = "; ".join(f"{k} x{v}" for k, v in sorted(d["go_arounds"].items(), key=lambda kv: -kv[1])) or "none"
    rows = [
        ("docked at the first attempt", pct(report.docked_within_1)),
        ("docked within 2 attempts", f"{pct(report.docked_within_2)}   target >= {DOCKED_WITHIN_2_TARGET:.0%}"),
        ("docked at all", pct(report.docked)),
        ("fell back (reasons)", f"{n - round(report.docked * n)}: {fallbacks}"),
        ("went around (reasons)", f"{sum(d['go_arounds'].values())}: {go_arounds}"),
        ("ended unsafely (not DONE)", f"{len(report.unsafe)}   target 0"),
        ("contact: horizontal error", spread("horizontal_error_m", "m")),
        ("contact: horizontal relative speed", spread("horizontal_relative_speed_m_s", "m/s")),
        ("contact: vertical relative speed", spread("vertical_relative_speed_m_s", "m/s")),
        ("deck violations (reported / true position)", f"{d['deck_violations']} / {d['true_deck_violations']}   target 0"),
        ("largest command jump at a phase switch", f"{d['max_phase_switch_jump_m_s']:.3f} m/s"),
        ("P3 (the carrier never at the target)", "held" if d["p3"] else "BROKEN"),
    ]
    closest = report.closest_any_target_m
    if closest is not None:
        guard = "" if report.guard_m is None else (f"   guard circle {report.guard_m:.3f} m, inside it: "
                                                   f"{', '.join(f'#{i}' for i in d['inside_guard']) or 'none'}")
        rows.append(("carrier's closest approach to any target", f"{closest:.3f} m{guard}"))
    if report.legs_held is not None:  # several targets: each flight flies every leg
        jump, offset = report.max_separation_jump_m_s, report.max_riding_offset_m
        ridden, step = d["max_ridden_offset_m"], d["max_ridden_carrier_step_m_s"]
        rows[0:0] = [("every leg held P1-P3", pct(report.legs_held)),
                     ("largest riding offset (P1's figure)", "-" if offset is None else f"{offset:.3f} m"),
                     ("ridden (riding or transit): offset, carrier's step", "-" if ridden is None or step is None
                      else f"{ridden:.3f} m, {step:.3f} m/s a tick"),
                     ("largest relative jump at a leg's separation", "-" if jump is None else f"{jump:.3f} m/s")]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)
