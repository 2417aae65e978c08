"""A team's mission flown in-process: one carrier, N passengers on their slots (``[team]``,
docs/team.md), every one of them by the flight's own pure steps; the simulation adds only the
world (N vehicles' dynamics, the carrier robot, who hears what).

- each passenger: its own configuration (:func:`mission.config.passenger.passenger_config`), its
  own :class:`mission.passenger.step.PassengerStep`, its own mock dynamics
  (:class:`sim.batch.recovery.MockDynamics`, starting on the ground under its slot), ticked as
  :class:`sim.batch.recovery.World` ticks its one passenger; it reads the carrier's newest state
  and the target the carrier announces (:meth:`mission.carrier.team.TeamCarrier.heading_for_ned_m`:
  its latch waits for its turn);
- the carrier: the built-in holonomic robot driven by :class:`mission.carrier.team.TeamCarrier`
  (the single-passenger :class:`~mission.carrier.step.CarrierStepper` behind it) on every
  passenger's status of the tick before, with the configuration's recovery course;
- the neighbours: :meth:`TeamWorld.neighbours_of` gives each passenger the others' reported
  states (position, velocity, age), which its step passes to the pairwise separation barrier
  (``PassengerInputs.neighbours``; ``share_neighbours`` False: none, each flies as if alone).

The simulation has no deck (:func:`sim.batch.recovery.as_simulated`): a team that rides the deck
(``mission.ride = "deck"``) is flown riding hovering :data:`HOVER_RAISE_M` above its slots
(:func:`hovering`), and ``simulate`` says so.

Figures (:meth:`TeamWorld.report`): per passenger the flight log's summary (each leg's P1-P3,
separation, jump, contact; :func:`mission.record.figures.summary_of`), which target the carrier
stood nearest to at each separation, the least distance between two passengers (true positions)
over time, and the carrier's closest approach to every target against its P3 guard radius.
Frames: local NED [m], [m/s]; time [s] from the start of the mission.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from mission.carrier.modes import CarrierMode, PassengerView
from mission.carrier.team import TeamCarrier
from mission.carrier.tracking import Tracked
from mission.config.passenger import carrier_config, has_team, passenger_config
from mission.config.schema import Config, from_dict
from mission.core.safety import Neighbours
from mission.errors import ConfigError
from mission.model import mission_model
from mission.passenger.inputs import PassengerInputs
from mission.passenger.step import PassengerStep
from mission.phases import MissionState, Phase, finished
from mission.record.figures import summary_of
from mission.record.info import flown_info, mission_info
from sim.batch.recovery import KinematicCarrier, MockDynamics, _record, _Rows, configured, sim_backend
from sim.vehicle.mock import PHYSICS_DT_S

HOVER_RAISE_M = 1.0  # [m] a deck-riding team is simulated riding hovering this far above its slots


def hovering(cfg: Config) -> Config:
    """``cfg`` as this simulation flies it: itself unless it rides the deck; else riding hovering
    (``mission.ride = "hover"``) :data:`HOVER_RAISE_M` above each slot (the simulation has no deck)."""
    if cfg.mission.ride != "deck":
        return cfg
    data = {key: dict(value) if isinstance(value, dict) else value
            for key, value in cfg.model_dump(exclude_unset=True).items()}
    data["mission"]["ride"] = "hover"
    slots = [dict(slot) for slot in data["team"]["slots"]]
    for slot in slots:
        slot["offset_ned_m"] = [*slot["offset_ned_m"][:2], slot["offset_ned_m"][2] - HOVER_RAISE_M]
    data["team"] = {**data["team"], "slots": slots}
    return from_dict(data)


class TeamKinematicCarrier(KinematicCarrier):
    """The built-in holonomic robot driven by :class:`TeamCarrier` (what the simulation adds: every
    passenger's status it hears, the configuration's recovery course); it keeps its closest
    approach to every target [m] and the targets it served, in order."""

    def __init__(self, cfg: Config) -> None:
        own, _ = carrier_config(cfg)
        super().__init__(own, configured())  # its robot, period and feed; its stepper is the team's
        self.team = TeamCarrier(sim_backend(cfg), self.robot.brakes_itself)
        self.stepper = self.team.stepper
        self.targets = [np.asarray(t, dtype=float) for t in own.scenario.legs()]
        self.closest_m = [math.inf] * len(self.targets)
        self.served: list[tuple[float, int, str]] = []  # (t [s], target index, mode) at each change

    def step_team(self, views: list[PassengerView]) -> Tracked:
        """Step at :meth:`next_step_s` on every passenger's ``views`` (the statuses of the tick before)."""
        t_s = self.next_step_s()
        self.robot.advance(t_s - self.t_s)
        dt = t_s - self.t_s
        self.t_s = t_s
        self.done += 1
        x = self.position
        for k, target in enumerate(self.targets):
            self.closest_m[k] = min(self.closest_m[k], float(np.linalg.norm(target - x)))
        self.team.update_mode(views)
        if self.mode is CarrierMode.RECOVERING:
            self.course_begun = True
        now = (self.team.heading_for(), self.mode.value)
        if not self.served or self.served[-1][1:] != now:
            self.served.append((t_s, *now))
        cmd = self.team.decide(self.robot.state_at(t_s), dt, 0.0, t_s).tracked
        self.robot.command(cmd)
        return cmd


@dataclass
class Member:
    """One passenger in the world: its configuration, step, vehicle, mission state and record."""

    name: str
    cfg: Config
    step: PassengerStep
    vehicle: MockDynamics
    state: MissionState = field(default_factory=MissionState)
    rows: _Rows = field(default_factory=_Rows)
    failed: dict[str, str] = field(default_factory=dict)
    events: list[tuple[float, str]] = field(default_factory=list)
    finished: bool = False
    separations: list[dict[str, Any]] = field(default_factory=list)  # where the carrier stood at each latch
    battery_pct: float | None = None  # [%] the battery its vehicle reports, steady (None: none reported)


class TeamWorld:
    """A team's mission in flight (module docstring); :meth:`tick` advances it one controller tick."""

    def __init__(self, cfg: Config, max_duration_s: float | None = None, estimate_error: float = 0.0,
                 seed: int = 0, share_neighbours: bool = True, batteries: list[float | None] | None = None) -> None:
        if not has_team(cfg):
            raise ConfigError("team.passengers", [], "the team simulation flies a file with a [team]")
        if cfg.mission.feeds:
            raise ConfigError("mission.feeds", list(cfg.mission.feeds), "the team simulation has no sensors yet")
        cfg = hovering(cfg)
        self.cfg = cfg
        self.carrier = TeamKinematicCarrier(cfg)
        self.law_bc_m = cfg.law.params().separation_distance_m
        self.members: list[Member] = []
        start = np.asarray(cfg.scenario.carrier_start, dtype=float)
        for i, p in enumerate(cfg.team.passengers):
            own = passenger_config(cfg, p.name)
            model = mission_model(own)
            slot = np.asarray(cfg.team.slots[cfg.team.slot_index(p.slot)].offset_ned_m, dtype=float)
            under = [float(start[0] + slot[0]), float(start[1] + slot[1]), float(start[2])]  # on the ground under its slot
            step = PassengerStep(model, own.mission.velocity_bias_tau_s, own.mission.near_deck_velocity_bias_tau_s)
            self.members.append(Member(p.name, own, step,
                                       MockDynamics(under, estimate_error, seed + i, gnss=own.world.passenger_gnss)))
        for m, pct in zip(self.members, batteries or []):
            m.battery_pct = pct
        self.dt_s = mission_model(self.members[0].cfg).dt_s
        self.steps_per_tick = int(round(self.dt_s / PHYSICS_DT_S))
        if abs(self.steps_per_tick * PHYSICS_DT_S - self.dt_s) > 1e-12:
            raise ConfigError("mission.rate_hz", cfg.mission.rate_hz,
                              f"must divide the mock's physics rate ({1 / PHYSICS_DT_S:g} Hz) to simulate the mission")
        self.limit_s = max_duration_s if max_duration_s is not None else cfg.mission.max_duration_s + 30.0
        self.views = [PassengerView(None) for _ in self.members]  # the statuses the carrier hears
        self.t: list[float] = []
        self.pair_min_m: list[float] = []  # the least true distance between two passengers at each tick [m]
        self.phases: list[tuple[Phase, ...]] = []  # every passenger's phase at each tick
        self.share_neighbours = share_neighbours  # each passenger's step hears the others (the pairwise barrier's rows)
        self.k = 0
        self.done = False

    def neighbours_of(self, i: int, t_s: float) -> list[tuple[list[float], list[float], float]]:
        """The other passengers' states as passenger ``i`` hears them at ``t_s`` [s]: (position
        [m], velocity [m/s] NED as its vehicle reports it, age [s]), each once: the pairwise
        separation barrier's input (``PassengerInputs.neighbours``, docs/team.md "Keeping
        passengers apart"). This world shares them with no delay (no bus carries them yet)."""
        out = []
        for j, m in enumerate(self.members):
            if j != i:
                r = m.vehicle.report(t_s)
                out.append((list(np.asarray(r.position_ned_m, dtype=float)), list(np.asarray(r.velocity_ned_m_s, dtype=float)),
                            0.0))
        return out

    def shared_of(self, i: int, t_s: float) -> Neighbours:
        """What passenger ``i`` hears of the others at ``t_s`` [s] (:meth:`neighbours_of`), with
        what the recovery queue reads (:mod:`mission.phases.queue`): each one's phase (of the tick
        before, as its status would carry it), how long its recovery has run [s], its battery [%],
        its system id and its leg's target [m]."""
        others = [m for j, m in enumerate(self.members) if j != i]
        nb = Neighbours.of(self.neighbours_of(i, t_s), 3)
        return replace(nb, phases=tuple(m.state.phase.value for m in others),
                       recovery_s=tuple(None if m.state.recovery is None else t_s - m.state.recovery.started_s
                                        for m in others),
                       battery_pct=tuple(m.battery_pct for m in others),
                       ids=tuple(m.cfg.mavlink.target_system or 0 for m in others),
                       targets_ned_m=np.array([m.cfg.scenario.legs()[min(m.state.leg, len(m.cfg.scenario.legs()) - 1)]
                                               for m in others], dtype=float).reshape(-1, 3))

    def tick(self) -> None:
        """One controller tick at ``k * dt``: the carrier's steps due, then every passenger's tick."""
        t = self.k * self.dt_s
        carrier = self.carrier
        while carrier.next_step_s() <= t + 1e-9:
            carrier.step_team(self.views)
        seen = carrier.observed(t)
        heading_for = carrier.team.heading_for_ned_m()
        views = []
        for m in self.members:  # every vehicle at the tick first: each passenger hears the others' states of now
            m.vehicle.advance_to_step(self.k * self.steps_per_tick)
        for i, m in enumerate(self.members):
            vehicle = m.vehicle
            if m.finished:
                views.append(PassengerView(m.state.phase, separated=m.state.phase.separated, leg=m.state.leg))
                continue
            before = m.state.phase
            neighbours = self.shared_of(i, t) if self.share_neighbours else None
            report = vehicle.report(t)
            if m.battery_pct is not None:
                report = replace(report, battery_pct=m.battery_pct)
            result = m.step(m.state, PassengerInputs(t, report, seen, dict(m.failed), neighbours=neighbours,
                                                     carrier_target_ned_m=heading_for))
            m.state, obs, dec = result.state, result.observation, result.decision
            vehicle.carry_out(t, dec, m.failed)
            m.events.extend((t, text) for text in dec.events)
            if m.state.phase is Phase.SEPARATED and before is not Phase.SEPARATED and m.state.anchor is not None:
                m.separations.append(self._separation(m, t))
            _record(m.rows, t, m.state, obs, dec, vehicle, carrier)
            m.finished = finished(m.state, dec)
            views.append(PassengerView(m.state.phase, separated=m.state.phase.separated, leg=m.state.leg))
        self.views = views
        x = [m.vehicle.true_position for m in self.members]
        self.t.append(t)
        self.phases.append(tuple(m.state.phase for m in self.members))
        self.pair_min_m.append(min((float(np.linalg.norm(x[i] - x[j])) for i in range(len(x))
                                    for j in range(i + 1, len(x))), default=math.inf))
        self.k += 1
        self.done = all(m.finished for m in self.members) or t >= self.limit_s

    def _separation(self, m: Member, t: float) -> dict[str, Any]:
        """Where the dock point (the latched anchor) stood at passenger ``m``'s latch: the nearest
        target, its distance to the leg's own target [m], and the target the carrier announced."""
        anchor = np.asarray(m.state.anchor, dtype=float)
        dist = [float(np.linalg.norm(tg - anchor)) for tg in self.carrier.targets]
        own = self.cfg.team.passengers[self.members.index(m)].targets[m.state.leg]
        return {"t_s": round(t, 3), "leg": m.state.leg, "own_target": own, "nearest_target": int(np.argmin(dist)),
                "dock_target_distance_m": round(dist[own], 3), "carrier_heading_for": self.carrier.team.heading_for()}

    def run(self) -> TeamWorld:
        """Tick until every passenger's mission ended (or the time limit)."""
        while not self.done:
            self.tick()
        return self

    def report(self) -> dict[str, Any]:
        """The team's figures (module docstring): ``passengers`` one summary per passenger (with
        ``legs`` for several targets), ``pair_min_distance_m`` and its time, ``carrier`` the
        closest approach to every target against the P3 guard radius, the targets served in order."""
        out: dict[str, Any] = {"simulated": "team", "passengers": {}}
        for m in self.members:
            record = m.rows.record({**mission_info(m.cfg), **flown_info(m.state)})
            s = summary_of(record)
            s.update(phase=m.state.phase.value, reason=None if m.state.reason is None else m.state.reason.value,
                     detail=m.state.detail, separations=m.separations,
                     last_event=m.events[-1][1] if m.events else None)
            out["passengers"][m.name] = s
        d = np.asarray(self.pair_min_m)
        worst = int(np.argmin(d)) if d.size else 0
        out["pair_min_distance_m"] = round(float(d[worst]), 3) if d.size else None
        out["pair_min_distance_t_s"] = round(self.t[worst], 3) if d.size else None
        out["pair_min_phases"] = [p.value for p in self.phases[worst]] if d.size else []
        out["duration_s"] = round(self.t[-1], 3) if self.t else 0.0
        guard = self.carrier.stepper.guard.radius_m
        out["carrier"] = {"guard_radius_m": round(guard, 3),
                          "closest_m": [round(c, 3) for c in self.carrier.closest_m],
                          "inside_keep_out": [c < guard for c in self.carrier.closest_m],
                          "served": [{"t_s": round(t, 2), "target": k, "mode": mode} for t, k, mode in self.carrier.served],
                          "hand_overs": [[self.members[a].name, self.members[b].name] for a, b in self.carrier.team.hand_overs],
                          "targets_done": sorted(self.carrier.team.done)}
        return out


def fly_team(cfg: Config, max_duration_s: float | None = None, estimate_error: float = 0.0, seed: int = 0) -> TeamWorld:
    """Fly ``cfg``'s team once, as configured (:class:`TeamWorld`), passenger ``i``'s vehicle
    estimate erring ``estimate_error`` times PX4 SITL's, drawn from ``seed + i`` (as the demo's pairs)."""
    return TeamWorld(cfg, max_duration_s, estimate_error, seed).run()


def team_ok(report: dict[str, Any]) -> bool:
    """Every passenger's every flown leg held P1-P3, each separated at its own target, and the carrier
    stayed out of every keep-out."""
    for s in report["passengers"].values():
        legs = s.get("legs") or [s]
        if not all(leg.get("p1") and leg.get("p2") and leg.get("p3") for leg in legs if "p1" in leg):
            return False
        if any(sep["nearest_target"] != sep["own_target"] for sep in s["separations"]):
            return False
    return not any(report["carrier"]["inside_keep_out"])


def team_ok_report(world: TeamWorld) -> dict[str, Any]:
    """:meth:`TeamWorld.report` with ``ok``: :func:`team_ok` and every passenger's mission completed (DONE)."""
    report = world.report()
    report["ok"] = team_ok(report) and all(s["phase"] == Phase.DONE.value for s in report["passengers"].values())
    return report


def draw_team(world: TeamWorld, path: str | Path, title: str) -> Path:
    """The team's figure at ``path``: north-east tracks (carrier, each passenger, the targets
    with their P3 guard circles where they cut the carrier's plane) and the least distance
    between two passengers over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 5.5))
    guard = world.carrier.stepper.guard.radius_m
    plane = float(world.cfg.scenario.carrier_start[2])
    for k, tg in enumerate(world.carrier.targets):
        ax.plot(tg[1], tg[0], "k*", ms=12)
        cut = math.sqrt(max(guard * guard - (float(tg[2]) - plane) ** 2, 0.0))  # the sphere in the carrier's plane
        ax.add_patch(matplotlib.patches.Circle((tg[1], tg[0]), cut, fill=False, ls="--", color="grey"))
        ax.annotate(f"target {k}", (tg[1], tg[0]), textcoords="offset points", xytext=(6, 6))
    rows0 = world.members[0].rows
    xc = np.asarray(rows0.vecs["x_c_true"])
    ax.plot(xc[:, 1], xc[:, 0], "k-", lw=2, label="carrier")
    for m in world.members:
        xp = np.asarray(m.rows.vecs["x_true"])
        ax.plot(xp[:, 1], xp[:, 0], lw=1, label=m.name)
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_aspect("equal")
    ax.legend()
    ax.set_title(title)
    bx.plot(world.t, world.pair_min_m)
    bx.set_xlabel("t [s]")
    bx.set_ylabel("least distance between two passengers [m]")
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out
