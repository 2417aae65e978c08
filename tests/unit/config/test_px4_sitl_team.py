"""configs/px4_sitl_team.toml, the team on real PX4 SITL (docs/team.md, "On real PX4"): it copies
configs/px4_sitl_cycle.toml's PX4 tracking, rover and recovery settings (the configuration system
has no includes), so this holds the copy to its source, and its PX4 instances to their ports and
system ids (bench/px4_team.py: instance = system id - 1)."""
from __future__ import annotations

import pytest

from mission.config.passenger import passenger_config
from mission.config.schema import load_config
from tests.conftest import CONFIGS

# The fields the team states itself, or that differ for a team's reason: the rover is instance 2
# (its link and system id), the mission's duration (two legs and two recoveries), the dock
# tolerance (both quadrotors start at the rover's home, 0.9 m from their slots).
OWN = {"mission": {"dock_offset_ned_m", "max_duration_s", "dock_tolerance_m"}, "mavlink": {"target_system"}, "carrier": {"mavlink"},
       "scenario": {"targets", "target"}}


@pytest.fixture(scope="module")
def team():
    return load_config(CONFIGS / "px4_sitl_team.toml")


@pytest.fixture(scope="module")
def cycle():
    return load_config(CONFIGS / "px4_sitl_cycle.toml")


@pytest.mark.parametrize("section", ["law", "scenario", "safety", "mission", "mavlink", "zenoh", "carrier", "recovery"])
def test_every_field_but_the_teams_own_is_the_single_pairs(team, cycle, section):
    mine, theirs = getattr(team, section).model_dump(), getattr(cycle, section).model_dump()
    differ = {k for k in mine if mine[k] != theirs[k]}
    assert differ <= OWN.get(section, set()), f"{section}: {sorted(differ - OWN.get(section, set()))} drifted"


def test_the_rovers_link_is_the_third_instances_and_only_its_address_differs(team, cycle):
    mine, theirs = team.carrier.mavlink.model_dump(), cycle.carrier.mavlink.model_dump()
    assert {k for k in mine if mine[k] != theirs[k]} == {"url", "target_system"}
    assert (team.carrier.mavlink.url, team.carrier.mavlink.target_system) == ("udpin:127.0.0.1:14542", 3)
    assert team.carrier.backend == "mavlink"


def test_each_passenger_rides_the_pairs_dock_point_moved_to_its_side_on_its_own_instance(team, cycle):
    ids = set()
    for p, side in zip(team.team.passengers, (-0.9, 0.9)):
        own = passenger_config(team, p.name)
        ids.add(own.mavlink.target_system)
        expected = list(cycle.mission.dock_offset_ned_m)
        expected[1] += side
        assert own.mission.dock_offset_ned_m == pytest.approx(expected)
        assert own.mission.ride == "hover"  # an SIH quadrotor cannot sit on an SIH rover
    assert ids == {1, 2} and team.carrier.mavlink.target_system not in ids
    assert [p.targets for p in team.team.passengers] == [[0, 2], [1]]  # alpha, bravo, alpha: configs/team.toml's order
