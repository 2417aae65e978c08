"""What bench/px4_team.py counts as a leg that met the team's PX4 target: docked (and stayed
docked) within 2 approaches, its contact within 0.2 m, P1-P3."""
from __future__ import annotations

from bench.px4_team import leg_meets

LEG = {"docked": True, "outcome": "done", "attempts": 1, "error_m": 0.07, "true_error_m": 0.066,
       "true_error_shifted_m": None, "p1": True, "p2": True, "p3": True}


def test_a_docked_leg_within_the_target_meets_it_on_the_truth_with_no_timing_check():
    assert leg_meets(LEG, "true") and leg_meets(LEG)


def test_a_leg_that_touched_then_fell_back_does_not_meet_it():
    assert not leg_meets({**LEG, "outcome": "fallback: 3 approaches without docking"}, "true")


def test_a_third_approach_or_a_wide_true_contact_does_not_meet_it():
    assert not leg_meets({**LEG, "attempts": 3}, "true")
    assert not leg_meets({**LEG, "true_error_m": 0.21}, "true") and leg_meets({**LEG, "true_error_m": 0.21})
    assert not leg_meets({**LEG, "true_error_shifted_m": 0.25}, "true")  # the rover's other timing, when checked
