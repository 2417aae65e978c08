"""The carrier of a team on the bus (thin I/O around the pure :class:`mission.carrier.team.TeamCarrier`).

A file with a ``[team]`` of several passengers: one carrier process serves them all. Each
passenger is bound separately, as the single pair binds its passenger: its own
:class:`~mission.bus.feeds.PassengerFeed` on its own keys (``marsupial/<pair>/passenger/<name>/...``,
:func:`mission.bus.session.keys`), which binds only to a source that began on the deck. Every step
turns each feed into a :class:`~mission.carrier.modes.PassengerView` against that passenger's slot
and hands them to the :class:`TeamCarrier`, whose stepper the controller drives. The target the
carrier heads for goes out on every state it publishes (``CarrierState.target_ned_m``, signed with
the state), so a passenger separates only on its own turn (:func:`mission.phases.types.my_turn`).

Signing: one Ed25519 key per robot, every robot's public key in ``zenoh.public_keys_dir``
(:func:`mission.bus.auth.team_bus_auth`): each passenger's feed verifies only that passenger's own
key; else the pair's key (``zenoh.signing_key_file``) signs and verifies every robot of the team. A
single peer's key (``zenoh.peer_public_key_file``) names one peer, and a team of several is refused
with it.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import zenoh

from mission.bus.auth import CARRIER, BusAuth, check_team_auth, team_bus_auth
from mission.bus.feeds import PassengerFeed
from mission.carrier.heard import Heard
from mission.carrier.modes import BEFORE_RIDING, BIND_STATUSES, PassengerView
from mission.carrier.team import TeamCarrier
from mission.config.passenger import carrier_config, has_team
from mission.config.schema import Config
from mission.time.clock import Clock


def team_names(cfg: Config) -> list[str] | None:
    """The names of ``cfg``'s team's passengers, in the team's order (None: no team)."""
    return [p.name for p in cfg.team.passengers] if has_team(cfg) else None


class TeamBus:
    """The team of ``cfg`` (a ``[team]``) as its carrier hears it: the pure :attr:`carrier`, one
    passenger feed per passenger (:attr:`feeds`, the team's order) and each one's slot offset [m]
    NED (:attr:`offsets_ned_m`). ``own``: the carrier's own configuration
    (:func:`mission.config.passenger.carrier_config`); :attr:`auth`: the carrier's keys on the team's
    bus (:func:`mission.bus.auth.team_bus_auth`; None: unsigned)."""

    def __init__(self, cfg: Config, session: zenoh.Session, pair: str, clock: Clock, brakes_itself: bool) -> None:
        check_team_auth(cfg.zenoh, len(cfg.team.passengers))
        self.own, _ = carrier_config(cfg)
        self.names = team_names(cfg) or []
        self.auth: BusAuth | None = team_bus_auth(cfg.zenoh, self.names, CARRIER, pair)
        auth = self.auth
        team = cfg.team
        self.offsets_ned_m = [np.asarray(team.slots[team.slot_index(p.slot)].offset_ned_m, dtype=float)
                              for p in team.passengers]
        self.carrier = TeamCarrier(cfg, brakes_itself)
        self.max_age_s = cfg.safety.passenger_separation_max_age_s  # [s] a status older than this is left out of distances
        self.feeds: list[PassengerFeed] = []
        try:
            for name in self.names:
                self.feeds.append(PassengerFeed(session, pair, clock, max_age_s=cfg.carrier.passenger_timeout_s,
                                                auth=None if auth is None else auth.for_peer(name),
                                                bind_phases=BEFORE_RIDING, bind_samples=BIND_STATUSES,
                                                passenger=name))
        except Exception:
            self.close()
            raise

    def target_ned_m(self) -> np.ndarray:
        """[m] NED (3,) the target the carrier heads for: what it announces."""
        aim = np.zeros(3)
        target = self.carrier.heading_for_ned_m()
        aim[:target.shape[0]] = target
        return aim

    def heard(self) -> tuple[Heard, ...]:
        """Each passenger's newest status on its feed now, the team's order
        (:class:`~mission.carrier.heard.Heard`: phase, reported position and velocity, its receive
        age [s] on the carrier's clock; only the name while nothing was heard)."""
        out = []
        for name, feed in zip(self.names, self.feeds):
            rx = feed.latest()
            out.append(Heard(name) if rx is None else Heard(name, rx.status.phase.value, rx.status.position_ned_m,
                                                            rx.status.velocity_ned_m_s, rx.age_s))
        return tuple(out)

    def counters(self) -> dict[str, Any]:
        """Each passenger's feed's counters, by name, and the carrier's hand-overs."""
        return {"passenger_feeds": {n: f.counters for n, f in zip(self.names, self.feeds)},
                "heading_for": self.carrier.heading_for(),
                "hand_overs": [[self.names[a], self.names[b]] for a, b in self.carrier.hand_overs]}

    def close(self) -> None:
        for feed in self.feeds:
            feed.close()


def views(bus: TeamBus, own_position_ned_m: np.ndarray | None, tolerance_m: float, dim: int,
          view_of: Any) -> list[PassengerView]:
    """Each passenger's view (``view_of``: :func:`mission.carrier.controller.passenger_view`),
    judged on its own slot's dock point (``own_position_ned_m`` [m] NED (3,) plus its offset;
    None: no own state)."""
    return [view_of(feed, None if own_position_ned_m is None else own_position_ned_m + offset, tolerance_m, dim)
            for feed, offset in zip(bus.feeds, bus.offsets_ned_m)]
