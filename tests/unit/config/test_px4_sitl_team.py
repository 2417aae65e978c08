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


# configs/px4_sitl_team_relnav.toml: the team above with configs/px4_sitl_relnav.toml's relative
# navigation. Each field comes from one of the two, and these say which: what relnav changed of
# the PX4 cycle's is relnav's, the rest the team's; its own is the seat's sigma (its quadrotors
# stand 0.9 m from their seats) and each slot's marker.
RELNAV_OWN = {"mission": {"feeds", "near_deck_velocity_bias_tau_s"}, "carrier": {"p3_margin_m", "p3_frame", "p3_unaligned_margin_m", "p3_bias_max_m",
                                                "align_on_deck_m", "acceleration_tau_s", "start_motion_tau_s",
                                                "separation_speed_m_s", "separation_decel_m_s2", "separation_room_m",
                                                "p3_bias_max_age_s"},
              "recovery": {"holdoff_distance_m", "glide_angle_deg", "final_descent_speed_m_s", "final_lineup_margin",
                           "final_descent_lag_m", "decision_height_m"},
              "vision": {"rate_hz", "layout", "hfov_deg"}, "relnav": {"enabled", "landing_target_rate_hz", "accel_noise_m_s2",
                                                                                 "gnss_velocity_sigma_m_s", "marker_model_sigma_m"},
              "world": {"carrier_gnss"}}


@pytest.fixture(scope="module")
def team_relnav():
    return load_config(CONFIGS / "px4_sitl_team_relnav.toml")


@pytest.fixture(scope="module")
def relnav():
    return load_config(CONFIGS / "px4_sitl_relnav.toml")


@pytest.mark.parametrize("section", ["law", "scenario", "safety", "mission", "mavlink", "zenoh", "carrier", "recovery", "team"])
def test_the_relnav_team_is_the_team_but_for_relnavs_fields(team_relnav, team, section):
    mine, theirs = getattr(team_relnav, section).model_dump(), getattr(team, section).model_dump()
    differ = {k for k in mine if mine[k] != theirs[k]}
    own = RELNAV_OWN.get(section, set()) | ({"slots"} if section == "team" else set())
    assert differ <= own, f"{section}: {sorted(differ - own)} drifted from px4_sitl_team.toml"


@pytest.mark.parametrize("section", ["carrier", "recovery", "vision", "relnav", "world"])
def test_relnavs_fields_are_px4_sitl_relnavs(team_relnav, relnav, section):
    mine, theirs = getattr(team_relnav, section).model_dump(), getattr(relnav, section).model_dump()
    fields = RELNAV_OWN[section] - {"carrier_gnss"}
    assert {k: mine[k] for k in fields} == {k: theirs[k] for k in fields}
    if section == "world":  # the seed is the bench's (--seed)
        assert {**mine["carrier_gnss"], "seed": 0} == {**theirs["carrier_gnss"], "seed": 0}
    if section == "relnav":  # all but the seat's sigma: its quadrotors stand 0.9 m from their seats
        assert {k for k in mine if mine[k] != theirs[k]} == {"seated_sigma_m"} and team_relnav.relnav.seated_sigma_m == 0.5
    if section == "vision":  # all but where the marker is: under each slot's dock point (its own)
        assert {k for k in mine if mine[k] != theirs[k]} == {"marker_offset_ned_m"}


def test_the_relnav_teams_slots_are_the_teams_with_a_marker_each_under_its_dock_point(team_relnav, team):
    for mine, theirs in zip(team_relnav.team.slots, team.team.slots):
        assert (mine.name, mine.offset_ned_m) == (theirs.name, theirs.offset_ned_m)
        assert mine.marker_offset_ned_m == [*mine.offset_ned_m[:2], 0.0]  # on the rover (the ground) under the dock point
    assert len({i for s in team_relnav.team.slots for i in (s.tag_id, s.small_tag_id)}) == 4
