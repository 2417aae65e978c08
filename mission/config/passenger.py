"""One passenger's configuration out of a team's (``[team]``, :mod:`mission.config.team`): what one
passenger process flies (``marsupial run --passenger NAME``), and what the commands that drive one
passenger take of a team file. docs/team.md.
"""
from __future__ import annotations

from dataclasses import dataclass

from mission.config.schema import Config, from_dict
from mission.config.team import check_hover_slots, dock_points, passenger_data
from mission.errors import ConfigError


def has_team(cfg: Config) -> bool:
    """Whether ``cfg`` came from a file that declares a team (:attr:`TeamSection.given`; validated:
    then it has passengers)."""
    return cfg.team.given


def passenger_config(cfg: Config, name: str) -> Config:
    """The single-passenger configuration passenger ``name`` of ``cfg``'s team flies: ``cfg`` without
    ``[team]``, ``mission.dock_offset_ned_m`` its slot's offset, ``mavlink.target_system`` its
    system id, ``scenario.target(s)`` its own targets (:func:`mission.config.team.passenger_data`);
    equal to the configuration a file stating just that would give. :class:`ConfigError` naming
    ``--passenger`` for a file without a team or a name not in it."""
    if not has_team(cfg):
        raise ConfigError("--passenger", name, "the file has no [team] section: it describes one passenger, which "
                          "flies without --passenger")
    names = [p.name for p in cfg.team.passengers]
    if name not in names:
        raise ConfigError("--passenger", name, f"no such passenger in team.passengers ({', '.join(names)})")
    return from_dict(passenger_data(cfg.model_dump(exclude_unset=True), cfg.team, cfg.scenario.legs(), names.index(name)))


def check_team_flight(cfg: Config) -> None:
    """What a command that flies ``cfg``'s team checks beyond the file's own rules, before anything
    opens: a team riding hovering keeps its riders apart (:func:`mission.config.team.check_hover_slots`;
    :class:`ConfigError` naming the slot). Nothing without a team."""
    if has_team(cfg):
        check_hover_slots(cfg.team, cfg.mission.ride, cfg.safety.margin_m)


def chosen_passenger(cfg: Config, name: str | None) -> Config:
    """What ``marsupial run`` flies of ``cfg``: ``cfg`` itself without a team; passenger ``name``'s
    configuration (:func:`passenger_config`), or the only passenger's when ``name`` is None; a team
    of several without ``name``, or ``name`` without a team: :class:`ConfigError` naming ``--passenger``."""
    if name is None and has_team(cfg):
        names = [p.name for p in cfg.team.passengers]
        if len(names) > 1:
            raise ConfigError("--passenger", None, f"the file's [team] has {len(names)} passengers: say which this "
                              f"process flies ({', '.join(names)})")
        name = names[0]
    return cfg if name is None else passenger_config(cfg, name)


@dataclass(frozen=True)
class TeamLink:
    """One passenger of a team of several on the bus: its ``name`` and every passenger's ``names``
    (the team's order, its own among them), with each one's MAVLink system id (``ids``) and the
    targets [m] NED of its legs in its order (``legs``), as the team's file gives them."""

    name: str
    names: tuple[str, ...]
    ids: tuple[int, ...] = ()
    legs: tuple[tuple[tuple[float, float, float], ...], ...] = ()


def team_link(cfg: Config, name: str | None) -> TeamLink | None:
    """Passenger ``name`` of ``cfg``'s team of several (None: no team, or a team of one, which flies
    on the pair's keys as one passenger; an unknown name is :func:`chosen_passenger`'s to refuse)."""
    names = tuple(p.name for p in cfg.team.passengers) if has_team(cfg) else ()
    if not (len(names) > 1 and name in names):
        return None
    each = [passenger_config(cfg, n) for n in names]
    return TeamLink(name, names, tuple(int(c.mavlink.target_system or 0) for c in each),
                    tuple(tuple((float(t[0]), float(t[1]), float(t[2]) if len(t) > 2 else 0.0) for t in c.scenario.legs())
                          for c in each))


def sole_passenger(cfg: Config, not_yet: str, *, team_of_one: bool = True) -> Config:
    """``cfg`` for a command that drives one passenger: itself without a team, a team of one's
    passenger's configuration; a team of several (or of one, with ``team_of_one`` False: a command
    whose processes read the file's single-passenger fields themselves) is refused,
    :class:`ConfigError` naming ``team.passengers``: "a team of N passengers is not ``not_yet`` yet"."""
    if not has_team(cfg):
        return cfg
    names = [p.name for p in cfg.team.passengers]
    if len(names) > 1 or not team_of_one:
        raise ConfigError("team.passengers", names, f"a team of {len(names)} passenger{'s' * (len(names) != 1)} is not "
                          f"{not_yet} yet (one of them flies with `marsupial run --passenger NAME`; docs/team.md)")
    return passenger_config(cfg, names[0])


def carrier_config(cfg: Config) -> tuple[Config, list[list[float]]]:
    """What the carrier of ``cfg`` drives (:class:`mission.carrier.team.TeamCarrier`), and the dock
    point [m] NED (from its reported position) each of the mission's targets is left from. Without
    a team: ``cfg`` itself, its one dock point for every target. With one: the team's file without
    ``[team]``, every target of the mission in its order, ``mission.dock_offset_ned_m`` the slot of
    the first target's passenger, and each target's dock point its passenger's slot
    (:func:`mission.config.team.dock_points`)."""
    targets = cfg.scenario.legs()
    if not has_team(cfg):
        return cfg, [list(cfg.mission.dock_offset_ned_m)] * len(targets)
    _, docks = dock_points(cfg.team, list(cfg.mission.dock_offset_ned_m), len(targets))
    data = {key: dict(value) if isinstance(value, dict) else value
            for key, value in cfg.model_dump(exclude_unset=True).items() if key != "team"}
    data.setdefault("mission", {})["dock_offset_ned_m"] = list(docks[0])
    return from_dict(data), docks
