"""Several targets at load (mission/config/legs.py): every leg can start under the paper's
Assumption 1, or the file is refused naming the field."""
from __future__ import annotations

import math
import tomllib

import pytest

from mission.config.legs import covered_circle
from mission.config.schema import from_dict, load_config, with_overrides
from mission.errors import ConfigError
from tests.conftest import CONFIGS


@pytest.fixture(scope="module")
def cycle():
    return load_config(CONFIGS / "cycle.toml")


def test_a_circle_is_covered_only_when_no_point_of_it_is_free():
    c = [0.0, 0.0]
    assert covered_circle(c, 1.0, [([0.0, 0.0], 1.5)])  # inside one disc
    assert not covered_circle(c, 1.0, [([0.0, 0.0], 0.5)])  # a disc inside the circle covers none of it
    assert not covered_circle(c, 1.0, [([3.0, 0.0], 1.0)])  # apart
    ring = [([math.cos(a), math.sin(a)], 0.3) for a in [k * 2 * math.pi / 12 for k in range(12)]]
    assert covered_circle(c, 1.0, ring)  # 12 discs of half-angle ~17 deg round it
    assert not covered_circle(c, 1.0, ring[:-1])  # one missing: a gap across the angle +-pi's neighbour
    gap_at_pi = [d for d in ring if d[0][0] > -0.99]  # the disc at 180 deg (where the arcs wrap) left out
    assert not covered_circle(c, 1.0, gap_at_pi)


@pytest.mark.parametrize("overrides, field, words", [
    ({"scenario.targets": []}, "scenario.targets", "1 to 100"),
    ({"scenario.targets": [[24.0, 18.0, -5.0], [30.0, 18.0, -4.0]]}, "scenario.targets[1]",
     "inside the keep-out of scenario.targets[0] (6.00 m"),
    ({"scenario.targets": [[24.0, 18.0, -5.0], [3.0, 4.0, -4.0]]}, "scenario.carrier_start",
     "inside the keep-out of scenario.targets[1] (5.00 m"),
    ({"scenario.targets": [[24.0, 18.0, -5.0], [44.0, 4.0, -4.0]],
      "scenario.obstacles": [{"center": [44.0, 4.0, -4.0], "radius": 0.5}]}, "scenario.targets[1]", "inside scenario.obstacles[0]"),
    ({"scenario.targets": [[24.0, 18.0, -5.0], [44.0, 4.0, -4.0]], "recovery.fallback_point_ned_m": [40.0, 4.0, -3.0]},
     "recovery.fallback_point_ned_m", "inside the keep-out of scenario.targets[1]"),
    ({"mission.final_action": "land"}, "mission.final_action", "must be \"return\" with 2 scenario.targets"),
])
def test_targets_that_leave_a_leg_no_start_are_refused(cycle, overrides, field, words):
    with pytest.raises(ConfigError) as exc:
        with_overrides(cycle, overrides)
    assert exc.value.field == field and words in str(exc.value), str(exc.value)


@pytest.mark.parametrize("targets, field, words", [
    ([[24.0, 18.0, 5.0], [44.0, 4.0, -4.0]], "scenario.targets[0]", "below the ground"),
    ([[24.0, 18.0], [44.0, 4.0, -4.0]], "scenario.targets[0]", "3 components"),
    ([[24.0, 18.0, "x"], [44.0, 4.0, -4.0]], "scenario.targets[0][2]", "valid number"),
    ([[24.0, 18.0, -5.0], [44.0, 4.0, float("nan")]], "scenario.targets[1][2]", "finite"),
])
def test_a_bad_entry_of_targets_is_named_as_the_file_wrote_it(targets, field, words):
    """A file that gives only ``scenario.targets`` hears of its entries, not of ``scenario.target``
    (the copy of the first entry it never wrote)."""
    text = (CONFIGS / "cycle.toml").read_text()
    data = tomllib.loads(text)
    data["scenario"]["targets"] = targets
    with pytest.raises(ConfigError) as exc:
        from_dict(data)
    assert exc.value.field == field and words in str(exc.value), str(exc.value)


@pytest.mark.parametrize("overrides, field, words", [
    ({"recovery.settle_carrier_speed_m_s": 2.5}, "recovery.settle_carrier_speed_m_s", "top speed 2 m/s"),
    ({"recovery.settle_carrier_speed_m_s": 1.8}, "recovery.settle_carrier_speed_m_s", "above 1.5 m/s, the fastest"),
    ({"carrier.recovery_speed_m_s": 0.0, "recovery.settle_carrier_speed_m_s": 0.5}, "recovery.settle_carrier_speed_m_s",
     "never settle"),
    ({"safety.passenger_max_speed_m_s": 1.5}, "carrier.recovery_speed_m_s", "never catch"),
    ({"recovery.carrier_max_age_s": 0.05}, "recovery.carrier_max_age_s", "two carrier states"),
])
def test_a_recovery_that_cannot_finish_is_refused(cycle, overrides, field, words):
    with pytest.raises(ConfigError) as exc:
        with_overrides(cycle, overrides)
    assert exc.value.field == field and words in str(exc.value), str(exc.value)


def test_a_holdoff_may_wait_for_a_course_leg_faster_than_the_steady_course(cycle):
    faster_leg = {"recovery.settle_carrier_speed_m_s": 1.8, "carrier.recovery_course": [[90.0, 2.0, 30.0]]}
    assert with_overrides(cycle, faster_leg).recovery.settle_carrier_speed_m_s == 1.8


def test_a_leg_ringed_by_obstacles_has_no_place_to_start(cycle):
    """Obstacles (radius + safety.margin_m) round the second target wherever its leg could start
    (10.5 m from the dock point, 10.2 m horizontally: the dock point is 1.5 m below it): refused;
    with a gap of one obstacle the carrier can drive out there, and the file loads."""
    ring = [{"center": [44.0 + 10.2 * math.cos(a), 4.0 + 10.2 * math.sin(a), 0.0], "radius": 3.5}
            for a in [k * math.pi / 6 for k in range(12)]]
    with pytest.raises(ConfigError) as exc:
        with_overrides(cycle, {"scenario.obstacles": ring})
    assert exc.value.field == "scenario.targets[1]" and "no place to start its leg: every point 9.90 m" in str(exc.value)
    with_overrides(cycle, {"scenario.obstacles": ring[1:]})


def test_two_targets_ringing_a_third_leave_it_no_place_to_start(cycle):
    """Other targets' P3 circles (where the carrier is b c - carrier.p3_margin_m = 7.5 m from them,
    their height counted: 7.48 m across at 0.5 m up) count as the obstacles do: a target with two
    others and two obstacles 8.2 m round it has its start circle (10.50 m) covered; spaced 16 m
    apart they leave gaps, and the file loads."""
    def three(gap_m: float) -> dict:
        targets = [[40.0, 30.0 - gap_m, -0.5], [40.0, 30.0, -0.5], [40.0 - gap_m, 30.0, -0.5]]
        return {"scenario.carrier_start": [0.0, -40.0, 0.0], "scenario.targets": targets,
                "scenario.obstacles": [{"center": [40.0 + gap_m, 30.0, 0.0], "radius": 8.0},
                                       {"center": [40.0, 30.0 + gap_m, 0.0], "radius": 8.0}]}
    with pytest.raises(ConfigError) as exc:
        with_overrides(cycle, three(8.2))
    assert exc.value.field == "scenario.targets[1]" and "no place to start its leg: every point 10.50 m" in str(exc.value)
    with_overrides(cycle, three(16.0))


def test_the_shipped_cycle_loads(cycle):
    assert cycle.scenario.legs() == [[24.0, 18.0, -5.0], [44.0, 4.0, -4.0]]


def test_overriding_the_targets_moves_the_first_target_with_them(cycle):
    """``scenario.target`` is the first of ``scenario.targets``: an override of the list alone
    (``--set scenario.targets=...``, a Monte-Carlo's scenario) moves it too, where it used to be
    refused as differing from the old first target; both given and different is still refused."""
    new = [[30.0, 20.0, -5.0], [44.0, 4.0, -4.0]]
    moved = with_overrides(cycle, {"scenario.targets": new})
    assert moved.scenario.target == new[0] and moved.scenario.legs() == new
    with pytest.raises(ConfigError) as exc:
        with_overrides(cycle, {"scenario.targets": new, "scenario.target": [24.0, 18.0, -5.0]})
    assert exc.value.field == "scenario.target"
