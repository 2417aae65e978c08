"""The team as its carrier hears it (mission.carrier.heard): a step's snapshot -> every pair's
distance at the carrier's clock -> the closest pair of the flight (carrier.json), and the same
steps through carrier.mcap's team topic, read back by mission.flightdata.read and drawn by
mission.plots.plot_team (no sockets)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from mission.carrier.controller import CarrierStep
from mission.carrier.heard import ClosestPair, Heard, hear
from mission.carrier.backends import OwnState
from mission.carrier.tracking import Tracked
from mission.flightdata.carrier_log import CarrierLog, team_metadata
from mission.flightdata.read import is_team_log, read_messages, read_team

MAX_AGE_S = 0.5


def _heard(name: str, phase: str | None, n: float, e: float, v_e: float = 0.0, age: float = 0.0) -> Heard:
    return Heard(name, phase, np.array([n, e, -1.0]), np.array([0.0, v_e, 0.0]), age)


def test_each_pair_is_measured_at_the_carriers_clock_and_counts_only_when_one_flies():
    """Positions moved on by velocity x age; a stale or unheard passenger gives no distance; two
    standing on the deck (neither flies) do not count, as a passenger's own figure does not."""
    team = hear([_heard("alpha", "RIDING", 0.0, 0.0, v_e=2.0, age=0.25),   # now at e = 0.5
                 _heard("bravo", "PREFLIGHT", 0.0, 3.0, v_e=-1.0, age=0.5),  # now at e = 2.5, fresh (at the limit)
                 _heard("charlie", "NAVIGATING", 4.0, 0.0, age=0.51),      # stale: left out
                 Heard("delta")], MAX_AGE_S)                               # never heard
    by = {(g.a, g.b): g for g in team.pairs}
    assert list(by) == [("alpha", "bravo"), ("alpha", "charlie"), ("alpha", "delta"), ("bravo", "charlie"),
                        ("bravo", "delta"), ("charlie", "delta")]
    assert by["alpha", "bravo"].distance_m == pytest.approx(2.0) and by["alpha", "bravo"].counted
    assert all(g.distance_m is None and not g.counted for k, g in by.items() if k != ("alpha", "bravo"))
    on_deck = hear([_heard("alpha", "ARMING", 0.0, 0.0), _heard("bravo", "PREFLIGHT", 0.0, 1.5)], MAX_AGE_S)
    assert on_deck.pairs[0].distance_m == pytest.approx(1.5) and not on_deck.pairs[0].counted
    assert on_deck.closest() is None


def test_the_closest_pair_is_the_least_counted_distance_with_its_time_names_and_phases():
    closest = ClosestPair()
    assert closest.summary() is None
    steps = [(1.0, [_heard("alpha", "ARMING", 0, 0), _heard("bravo", "PREFLIGHT", 0, 1.0)]),   # 1.0 m, not counted
             (2.0, [_heard("alpha", "RIDING", 0, 0), _heard("bravo", "RIDING", 0, 1.5)]),
             (3.0, [_heard("alpha", "SEPARATED", 0, 0), _heard("bravo", "RIDING", 0, 1.2)]),
             (4.0, [_heard("alpha", "NAVIGATING", 0, 0), _heard("bravo", "RIDING", 0, 1.3)])]
    for t, snapshot in steps:
        closest.update(t, hear(snapshot, MAX_AGE_S))
    assert closest.summary() == {"distance_m": 1.2, "t_s": 3.0, "names": ["alpha", "bravo"],
                                 "phases": ["SEPARATED", "RIDING"]}


def _step(t_s: float, team=None) -> CarrierStep:
    state = OwnState(t_s, np.array([t_s, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), 0.0)
    return CarrierStep(t_s, "approaching", None, state, Tracked(0.0, 0.0, 0.0, np.zeros(2), np.zeros(2)),
                       np.zeros(2), 0, None, team)


META = team_metadata(["alpha", "bravo"], [[24.0, 18.0, -5.0], [44.0, 4.0, -4.0], [20.0, -20.0, -4.0]],
                     ["alpha", "bravo", "alpha"], 8.0, 3.0, MAX_AGE_S)


def _team_log(path, steps: int = 60) -> ClosestPair:
    """A team's carrier.mcap of ``steps`` steps at 10 Hz: alpha leaves bravo's side, flies past it
    and away; returns the closest pair the controller's account gives of the same snapshots."""
    log = CarrierLog(path, pair="pairX", target=[24.0, 18.0, -5.0], clock={"clock": "mission"}, team=META)
    closest = ClosestPair()
    for k in range(steps):
        t = 0.1 * k
        phase = "ARMING" if k < 10 else "RIDING" if k < 20 else "NAVIGATING"
        alpha = _heard("alpha", phase, t, -0.75 + math.sin(0.2 * k), v_e=0.4, age=0.02)
        team = hear([alpha, _heard("bravo", "RIDING" if k >= 10 else "PREFLIGHT", t, 0.75, age=0.03)], MAX_AGE_S)
        closest.update(t, team)
        log.step(_step(t, team))
    log.close()
    return closest


def test_carrier_mcap_names_every_passenger_and_its_distances_match_the_summary(tmp_path):
    """The team topic has each passenger by name and the pair's distance every step; its least
    counted distance is the summary's closest pair, at its time; the team metadata says the
    targets, b c and the separation; the team's figure is drawn from the file alone."""
    from mission.plots import plot_team

    closest = _team_log(tmp_path / "carrier.mcap").summary()
    content = read_messages(tmp_path / "carrier.mcap", {"/pairX/carrier/team"})
    messages = [json.loads(data) for _, schema, _, data in content.messages]
    assert len(messages) == 60 and {s for _, s, _, _ in content.messages} == {"marsupial.Team"}
    assert [p["name"] for p in messages[0]["passengers"]] == ["alpha", "bravo"]
    assert messages[-1]["passengers"][0]["phase"] == "NAVIGATING" and messages[0]["separation_m"] == 3.0
    rec = read_team(tmp_path / "carrier.mcap")
    assert rec.names == ["alpha", "bravo"] and rec.pairs == [("alpha", "bravo")] and rec.owners == ["alpha", "bravo", "alpha"]
    assert rec.positions.shape == (60, 2, 3) and rec.carrier.shape == (60, 3) and rec.bc_m == 8.0
    assert not rec.counted[:10, 0].any() and rec.counted[10:, 0].all()  # both on the deck: not counted
    d, t, pair = rec.closest()
    assert closest is not None and d == pytest.approx(closest["distance_m"], abs=1e-4) and t == pytest.approx(closest["t_s"])
    assert d > np.nanmin(rec.distances[:10, 0])  # the on-deck steps were closer still and did not count
    out = plot_team(rec, tmp_path / "team.png")
    assert out.stat().st_size > 20_000


def test_a_single_pairs_carrier_mcap_has_no_team(tmp_path):
    """No team channel and no team metadata (a single pair's file is as before); the reader says so."""
    from mission.errors import ConfigError

    log = CarrierLog(tmp_path / "carrier.mcap", pair="pairX", target=[24.0, 18.0, -5.0], clock={"clock": "mission"})
    log.step(_step(0.0))
    log.close()
    content = read_messages(tmp_path / "carrier.mcap")
    assert set(content.metadata) == {"clock"} and {t for t, _, _, _ in content.messages} == {
        "/pairX/carrier/tf", "/pairX/carrier/log", "/pairX/carrier/status"}
    assert not is_team_log(tmp_path / "carrier.mcap")
    with pytest.raises(ConfigError, match="not a team's carrier.mcap"):
        read_team(tmp_path / "carrier.mcap")


def test_marsupial_plot_draws_a_teams_figure_from_its_log_root_or_its_carrier_mcap(tmp_path):
    """`marsupial plot ROOT` with a team's carrier.mcap: team.png beside it (exit 0); the file itself
    with --out: there."""
    from click.testing import CliRunner

    from mission.cli.run import plot

    _team_log(tmp_path / "carrier.mcap", steps=20)
    result = CliRunner().invoke(plot, [str(tmp_path)])
    assert result.exit_code == 0 and (tmp_path / "team.png").stat().st_size > 20_000, result.output
    result = CliRunner().invoke(plot, [str(tmp_path / "carrier.mcap"), "--out", str(tmp_path / "other.png")])
    assert result.exit_code == 0 and (tmp_path / "other.png").is_file(), result.output


def test_carrier_status_measures_the_distance_to_the_target_served_at_each_step(tmp_path):
    """A carrier serving its second target reports that target and the distance to it, not to the
    first target the log was opened with; a step that names none falls back to the first."""
    import dataclasses

    log = CarrierLog(tmp_path / "carrier.mcap", pair="pairX", target=[24.0, 18.0, -5.0], clock={"clock": "mission"})
    log.step(_step(0.0))                                                       # x = (0, 0, 0), target 0
    log.step(dataclasses.replace(_step(1.0), target_ned_m=np.array([1.0, 4.0, 0.0])))  # x = (1, 0, 0), target 1
    log.close()
    content = read_messages(tmp_path / "carrier.mcap", {"/pairX/carrier/status"})
    first, second = (json.loads(data) for _, _, _, data in content.messages)
    assert first["target"] == {"n": 24.0, "e": 18.0, "d": -5.0}
    assert first["target_distance_m"] == pytest.approx(math.hypot(24.0, 18.0, 5.0), abs=1e-6)
    assert second["target"] == {"n": 1.0, "e": 4.0, "d": 0.0} and second["target_distance_m"] == pytest.approx(4.0)
