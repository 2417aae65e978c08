"""``carrier.mcap``: the carrier controller's own flight data (a
:class:`~mission.carrier.controller.StepSink`).

Each :class:`~mission.carrier.controller.CarrierStep` becomes, at its clock time: the transform
``map_ned -> <pair>/carrier_own/base_link_frd`` (the carrier's own state as it used it, rotated
by its heading; the mission's log has ``<pair>/carrier/base_link_frd``, the state the passenger
received), its ``status`` (mode, why it holds, the
law's command, what it sent, the P3 guard, the distance to the target: JSON) and a
``foxglove.Log`` line when the mode or the hold reason changes; once a second, the passenger
feed's counters. A team's carrier (``team`` given) also logs, every step, its passengers as
heard and each pair's distance (``carrier/team``, ``marsupial.Team``: the step's
:class:`~mission.carrier.heard.TeamHeard`) and writes a ``team`` metadata record (the names, the
targets, b c, the passengers' separation); a single pair's file has neither. Topics:
:data:`mission.flightdata.topics.CARRIER_CHANNELS`.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Callable

import numpy as np

from mission.carrier.controller import CarrierStep
from mission.carrier.heard import TeamHeard
from mission.flightdata.mission_log import clean, vector, yaw_quaternion
from mission.flightdata.topics import CARRIER_CHANNELS, TEAM_ONLY, WORLD_FRAME, frame, topics
from mission.flightdata.writer import DataLog, LiveAddress, timestamp


def _pad3(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return np.concatenate([v, np.zeros(3 - v.shape[0])]) if v.shape[0] < 3 else v


class CarrierLog(DataLog):
    """``carrier.mcap`` of pair ``pair``: ``target`` [m] NED the first target (a step that names
    the target it serves is measured against that one); ``clock``: the ``clock`` metadata;
    ``team``: a team's carrier only (None: a single pair), its ``team`` metadata record (values
    JSON-encoded, :func:`team_metadata`), and the file gets the team channel."""

    def __init__(self, path: str | Path, *, pair: str, target: Any, clock: dict[str, str],
                 live: LiveAddress | None = None, team: dict[str, Any] | None = None) -> None:
        metadata = {"clock": clock} | ({} if team is None else {"team": {k: json.dumps(v) for k, v in team.items()}})
        super().__init__(path, name=f"{pair}-carrier", metadata=metadata, live=live)
        self.pair = pair
        self.target = _pad3(np.asarray(target, dtype=float))
        self.separation_m = None if team is None else team.get("separation_m")
        self.topics = topics(pair, CARRIER_CHANNELS)
        self.ch = {key: self.channel(self.topics[key], schema) for key, _, schema in CARRIER_CHANNELS
                   if team is not None or key not in TEAM_ONLY}
        self._counters: Callable[[], dict[str, Any]] | None = None
        self._said: tuple[str, str | None] | None = None
        self._next_counters_s: float | None = None
        self._guard_ticks = 0

    def set_counters(self, counters: Callable[[], dict[str, Any]]) -> None:
        """How to read the passenger feed's counters (logged once a second, off the loop)."""
        self._counters = counters

    def step(self, step: CarrierStep) -> None:
        self.submit(step.t_s, step)

    def close(self) -> None:
        """Finish the file (idempotent)."""
        self.finish()

    def handle(self, t_s: float, step: CarrierStep) -> None:
        from foxglove.messages import FrameTransform, Log, LogLevel, Quaternion, Vector3

        t = self.log_ns(t_s)
        stamp = timestamp(t)
        st = step.state
        if st is not None:
            p = _pad3(st.position_ned_m)
            qx, qy, qz, qw = yaw_quaternion(st.yaw_rad)
            self.ch["tf"].log(FrameTransform(timestamp=stamp, parent_frame_id=WORLD_FRAME,
                                             child_frame_id=frame(self.pair, "carrier_own"),
                                             translation=Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                                             rotation=Quaternion(x=qx, y=qy, z=qz, w=qw)), log_time=t)
        said = (step.mode, step.hold_reason)
        if said != self._said:
            text = f"mode {step.mode}" + ("" if step.hold_reason is None else f" (holding: {step.hold_reason})")
            level = LogLevel.Info if step.hold_reason is None else LogLevel.Warning
            self.ch["log"].log(Log(timestamp=stamp, level=level, message=text, name=f"{self.pair}/carrier"), log_time=t)
            self._said = said
        cmd = step.command
        target = self.target if step.target_ned_m is None else _pad3(np.asarray(step.target_ned_m, dtype=float))
        self.ch["status"].log({
            "mode": step.mode, "hold_reason": step.hold_reason, "published": step.published is not None,
            "position": None if st is None else vector(_pad3(st.position_ned_m)),
            "velocity": None if st is None else vector(_pad3(st.velocity_ned_m_s)),
            "yaw_rad": None if st is None or st.yaw_rad is None else clean(float(st.yaw_rad)),
            "law_velocity": vector(_pad3(step.law_velocity_m_s)), "setpoint": vector(_pad3(cmd.setpoint_ned_m_s)),
            "speed_m_s": clean(float(cmd.speed_m_s)), "yaw_rate_rad_s": clean(float(cmd.yaw_rate_rad_s)),
            "guard_active": step.guard_active_ticks > self._guard_ticks, "guard_active_ticks": step.guard_active_ticks,
            "target": vector(target), "target_distance_m": None if st is None else clean(
                float(np.linalg.norm(target - _pad3(st.position_ned_m))))},
            log_time=t)
        self._guard_ticks = step.guard_active_ticks
        if step.team is not None and "team" in self.ch:
            self.ch["team"].log(self.team_message(step.team), log_time=t)
        if self._counters is not None and (self._next_counters_s is None or t_s >= self._next_counters_s):
            self.ch["passenger_feed"].log(self._counters(), log_time=t)
            self._next_counters_s = t_s + 1.0

    def team_message(self, team: TeamHeard) -> dict[str, Any]:
        """The ``marsupial.Team`` message of a step's snapshot."""
        closest = team.closest()
        return {
            "passengers": [{"name": h.name, "phase": h.phase,
                            "position": None if h.position_ned_m is None else vector(_pad3(h.position_ned_m)),
                            "velocity": None if h.velocity_ned_m_s is None else vector(_pad3(h.velocity_ned_m_s)),
                            "age_s": None if h.age_s is None else clean(float(h.age_s))} for h in team.passengers],
            "pairs": [{"a": g.a, "b": g.b, "distance_m": None if g.distance_m is None else clean(g.distance_m),
                       "counted": g.counted} for g in team.pairs],
            "closest_m": None if closest is None else clean(closest.distance_m),
            "closest": None if closest is None else [closest.a, closest.b],
            "separation_m": self.separation_m}


def team_metadata(names: list[str], targets: list[list[float]], owners: list[str], bc_m: float, separation_m: float,
                  max_age_s: float) -> dict[str, Any]:
    """What a team's ``carrier.mcap`` says of its team (its ``team`` metadata record, each value
    JSON): the passengers' ``names`` (the team's order), the ``targets`` [m] NED in the mission's
    order and each one's passenger (``owners``), ``bc_m`` [m] b c (the keep-out round each),
    ``separation_m`` [m] ``safety.passenger_separation_m``, ``max_age_s`` [s]
    ``safety.passenger_separation_max_age_s`` (a status older is left out of the distances)."""
    return {"names": names, "targets": [[float(v) for v in t] for t in targets], "owners": owners, "bc_m": bc_m,
            "separation_m": separation_m, "max_age_s": max_age_s}
