"""One carrier, several passengers at load (mission/config/team.py, mission/config/passenger.py):
a team's passenger flies exactly the single-passenger configuration that states its slot, system id
and targets; a file without [team] is what it was."""
from __future__ import annotations

import re

import pytest

from mission.cli.run import check_config
from mission.config.passenger import chosen_passenger, has_team, passenger_config, sole_passenger
from mission.config.schema import from_dict, load_config, with_overrides
from mission.config.team import as_team_error, dock_points, min_slot_spacing_m
from mission.errors import ConfigError
from tests.conftest import CONFIGS

TEAM_TOML = (CONFIGS / "team.toml").read_text()
TARGETS_LINE = "targets = [[24.0, 18.0, -5.0], [44.0, 4.0, -4.0], [20.0, -20.0, -4.0]]"


@pytest.fixture(scope="module")
def team():
    return load_config(CONFIGS / "team.toml")


def single_passenger_text(dock: str, system_id: int, targets_line: str) -> str:
    """configs/team.toml as a one-passenger file would say it: no [team], the dock offset, the
    system id and the targets stated where a file without a team states them; [team] keeps its
    scalars (the span, the queue: every passenger's), without slots or passengers."""
    text = TEAM_TOML[:TEAM_TOML.index("[team]")]
    text = re.sub(r"^targets = .*$", targets_line, text, count=1, flags=re.M)
    text = text.replace("[mission]\n", f"[mission]\ndock_offset_ned_m = {dock}\n", 1)
    text = text.replace("[mavlink]\n", f"[mavlink]\ntarget_system = {system_id}\n", 1)
    return text + TEAM_TOML[TEAM_TOML.index("[team]"):TEAM_TOML.index("[[team.slots]]")]


@pytest.mark.parametrize("name, dock, system_id, targets_line", [
    ("alpha", "[0.0, -0.75, -0.5]", 1, "targets = [[24.0, 18.0, -5.0], [20.0, -20.0, -4.0]]"),
    ("bravo", "[0.0, 0.75, -0.5]", 2, "target = [44.0, 4.0, -4.0]"),
])
def test_a_passenger_of_the_team_flies_the_equivalent_single_passenger_config(team, tmp_path, name, dock, system_id,
                                                                              targets_line):
    path = tmp_path / "single.toml"
    path.write_text(single_passenger_text(dock, system_id, targets_line))
    single = load_config(path)
    derived = passenger_config(team, name)
    assert not has_team(derived) and not has_team(single)
    assert derived.model_dump() == single.model_dump()  # every value, defaults included
    assert derived.model_dump(exclude_unset=True) == single.model_dump(exclude_unset=True)  # and what is stated
    assert derived.mission.dock_offset_ned_m == [0.0, -0.75 if name == "alpha" else 0.75, -0.5]
    assert derived.mavlink.target_system == system_id
    check_config(derived)  # what `marsupial run` checks before it opens anything: the mission model builds
    assert chosen_passenger(team, name).model_dump() == single.model_dump()  # `run --passenger NAME`


def test_overrides_reach_the_passenger(team):
    derived = chosen_passenger(with_overrides(team, {"mavlink.url": "udpin:127.0.0.1:14541"}), "bravo")
    assert derived.mavlink.url == "udpin:127.0.0.1:14541" and derived.mavlink.target_system == 2


TEAM_FILES = {"team.toml", "px4_sitl_team.toml", "px4_sitl_team_relnav.toml"}  # the shipped teams (the mock's, real PX4 SITL's, with a camera)


@pytest.mark.parametrize("path", sorted(p for p in CONFIGS.glob("*.toml") if p.name not in TEAM_FILES), ids=lambda p: p.name)
def test_a_file_without_a_team_is_as_before(path):
    cfg = load_config(path)
    assert not has_team(cfg) and cfg.team.passengers == [] and "team" not in cfg.model_dump(exclude_unset=True)
    assert chosen_passenger(cfg, None) is cfg and sole_passenger(cfg, "x") is cfg
    with pytest.raises(ConfigError) as info:  # --passenger means nothing without a team
        chosen_passenger(cfg, "alpha")
    assert info.value.field == "--passenger" and "no [team]" in info.value.rule


def test_each_target_leaves_from_its_passengers_slot(team):
    docks, leg_docks = dock_points(team.team, team.mission.dock_offset_ned_m, 3)
    port, starboard = [0.0, -0.75, -0.5], [0.0, 0.75, -0.5]
    assert docks == [("team.slots[0].offset_ned_m", port), ("team.slots[1].offset_ned_m", starboard)]
    assert leg_docks == [port, starboard, port]  # targets 0 and 2: alpha (port); 1: bravo (starboard)
    assert team.team.owners(3) == [0, 1, 0]
    single = from_dict({})
    assert dock_points(None, single.mission.dock_offset_ned_m, 2) == (
        [("mission.dock_offset_ned_m", [0.0, 0.0, -1.5])], [[0.0, 0.0, -1.5]] * 2)


def test_slots_overlap_below_the_span_plus_twice_the_contact_radius(team):
    assert min_slot_spacing_m(team.team, team.recovery.contact_radius_m) == pytest.approx(0.8 + 2 * 0.15)
    data = team.model_dump(exclude_unset=True)
    for east, ok in ((0.55, True), (0.549, False)):  # port at -0.55: 1.10 m apart, then 1.099 m
        data["team"]["slots"][0]["offset_ned_m"] = [0.0, -east, -0.5]
        data["team"]["slots"][1]["offset_ned_m"] = [0.0, east, -0.5]
        if ok:
            from_dict(data)
            continue
        with pytest.raises(ConfigError) as info:
            from_dict(data)
        assert info.value.field == "team.slots[1].offset_ned_m" and "1.10 m from it horizontally" in info.value.rule
    data["team"]["slots"][1]["offset_ned_m"] = [0.0, -0.549, -3.0]  # above the other: overlapping all the same
    with pytest.raises(ConfigError, match=r"team.slots\[1\].offset_ned_m"):
        from_dict(data)


def test_a_derived_passengers_refusal_names_the_team_files_field(team):
    t = team.team
    err = as_team_error(ConfigError("mission.dock_offset_ned_m", [0, 0, 1], "underground"), t, 1, "scenario.targets")
    assert err.field == "team.slots[1].offset_ned_m"
    assert as_team_error(ConfigError("scenario.targets[1][2]", 1.0, "x"), t, 0, "scenario.targets").field == \
        "scenario.targets[2][2]"  # alpha's second target is the mission's third
    assert as_team_error(ConfigError("scenario.target", [1], "x"), t, 1, "scenario.targets").field == "scenario.targets[1]"
    assert as_team_error(ConfigError("mavlink.target_system", 3, "x"), t, 1, "scenario.targets").field == \
        "team.passengers[1].system_id"
    other = as_team_error(ConfigError("scenario.eta", 40.0, "too far"), t, 1, "scenario.targets")
    assert other.field == "scenario.eta" and "team.passengers[1] 'bravo'" in other.rule


def test_a_team_whose_passenger_could_not_fly_alone_is_refused(team):
    """Assumption 1's eta holds for the mission's first target, 44.2 m away, but not for bravo's
    first, 30.4 m away: bravo's own configuration would be refused, so the team is."""
    data = team.model_dump(exclude_unset=True)
    data["scenario"] = {**data["scenario"], "eta": 40.0, "targets": [[44.0, 4.0, -4.0], [24.0, 18.0, -5.0], [20.0, -20.0, -4.0]]}
    data["scenario"].pop("target")
    with pytest.raises(ConfigError) as info:
        from_dict(data)
    assert info.value.field == "scenario.carrier_start" and ">= eta = 40 m" in info.value.rule
    assert "as team.passengers[1] 'bravo' flies it" in info.value.rule
    data["scenario"]["eta"] = 30.0  # within both
    assert passenger_config(from_dict(data), "bravo").scenario.eta == 30.0


def test_a_team_of_one_is_its_passenger_and_a_team_of_two_is_refused_where_not_flown(team):
    data = team.model_dump(exclude_unset=True)
    data["team"]["passengers"] = [{**data["team"]["passengers"][0], "targets": [0, 1, 2]}]
    one = from_dict(data)
    assert chosen_passenger(one, None).model_dump() == passenger_config(one, "alpha").model_dump()
    assert sole_passenger(one, "x").scenario.legs() == one.scenario.legs()
    with pytest.raises(ConfigError, match="a team of 1 passenger is not flown by demo yet"):
        sole_passenger(one, "flown by demo", team_of_one=False)
    with pytest.raises(ConfigError, match="a team of 2 passengers is not flown by demo yet"):
        sole_passenger(team, "flown by demo")
    with pytest.raises(ConfigError) as info:
        chosen_passenger(team, None)
    assert info.value.field == "--passenger" and "alpha, bravo" in info.value.rule
    with pytest.raises(ConfigError, match=r"^team.passengers"):  # the team as a whole has no one mission model
        check_config(team)


def test_a_dump_of_a_one_passenger_configuration_loads_back_as_one_passenger():
    """A dump writes every field, the empty team's lists too: that is no team (an empty ``[team]``
    is one passenger, as without it), not a team that states the single-passenger fields again."""
    from mission.config.passenger import has_team
    from mission.config.schema import from_dict

    cfg = load_config(CONFIGS / "cycle.toml")
    again = from_dict(cfg.model_dump())
    assert not has_team(again) and again.mission.dock_offset_ned_m == cfg.mission.dock_offset_ned_m
