"""The carrier's side of the recovery, pure: its modes while the passenger comes home (one case per
line of the transition table in mission/carrier/modes.py) and the recovery course."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.carrier.course import Leg, RecoveryCourse, away_heading_deg
from mission.carrier.modes import CarrierMode, PassengerView, next_mode
from mission.phases.phase import Duty, Phase

M = CarrierMode
RECOVER = [p for p in Phase if p.duty is Duty.RECOVER]


@pytest.mark.parametrize(("mode", "view", "expected"), [
    # the passenger starts home: a separated (or paused) carrier takes its recovery course
    *[(M.SEPARATED, PassengerView(p, True), M.RECOVERING) for p in RECOVER],
    (M.PAUSED, PassengerView(Phase.RETURNING, True), M.RECOVERING),
    # ... but not while it cannot hear the passenger
    (M.SEPARATED, PassengerView(Phase.RETURNING, True, "stale"), M.SEPARATED),
    (M.PAUSED, PassengerView(Phase.RETURNING, True, "stale"), M.PAUSED),
    # it keeps the course through every recovery phase, go-arounds included
    *[(M.RECOVERING, PassengerView(p, True), M.RECOVERING) for p in RECOVER],
    # the passenger lost meanwhile: stop until it is heard again
    (M.RECOVERING, PassengerView(Phase.APPROACH, True, "its liveliness token is gone"), M.PAUSED),
    (M.RECOVERING, PassengerView(None, False, "no status received"), M.PAUSED),
    # the recovery fell back (FALLBACK, then HOLD or LAND): separated again
    (M.RECOVERING, PassengerView(Phase.FALLBACK, True), M.SEPARATED),
    (M.RECOVERING, PassengerView(Phase.HOLD, True), M.SEPARATED),
    (M.PAUSED, PassengerView(Phase.FALLBACK, True, "stale"), M.SEPARATED),
    # the passenger aborted during the recovery: stop for good
    (M.RECOVERING, PassengerView(Phase.ABORT), M.STOPPED),
    # the passenger is home: park, whatever the mode (stopped excepted)
    *[(mode, PassengerView(Phase.HOME, True), M.PARKED)
      for mode in (M.WAITING, M.APPROACHING, M.PAUSED, M.SEPARATED, M.RECOVERING, M.PARKED)],
    (M.STOPPED, PassengerView(Phase.HOME, True), M.STOPPED),
    # parked is latched: Hold, done, an abort, silence, even a recovery phase never unpark it
    *[(M.PARKED, PassengerView(p, p.separated), M.PARKED) for p in Phase if p.duty is not Duty.CARRY],
    (M.PARKED, PassengerView(Phase.DONE, True, "its liveliness token is gone"), M.PARKED),
    # ... only the passenger riding again (the next target) does
    (M.PARKED, PassengerView(Phase.RIDING), M.APPROACHING),
    (M.PARKED, PassengerView(Phase.RIDING, lost="stale"), M.PARKED),
    # several targets: after a dock the passenger rides on (TRANSIT: the carrier drives out to the
    # next leg's start; then RIDING under the law)
    (M.RECOVERING, PassengerView(Phase.TRANSIT, leg=1), M.REPOSITIONING),
    (M.PAUSED, PassengerView(Phase.TRANSIT, leg=1), M.REPOSITIONING),
    (M.PAUSED, PassengerView(Phase.TRANSIT, lost="stale", leg=1), M.PAUSED),
    (M.REPOSITIONING, PassengerView(Phase.TRANSIT, leg=1), M.REPOSITIONING),
    (M.REPOSITIONING, PassengerView(Phase.RIDING, leg=1), M.APPROACHING),
    (M.REPOSITIONING, PassengerView(Phase.TRANSIT, lost="stale", leg=1), M.PAUSED),
    (M.REPOSITIONING, PassengerView(Phase.ABORT, leg=1), M.STOPPED),
    (M.REPOSITIONING, PassengerView(Phase.HOME, True, leg=1), M.PARKED),
    (M.RECOVERING, PassengerView(Phase.RIDING), M.APPROACHING),
    # the deploy's transitions stand
    (M.SEPARATED, PassengerView(Phase.RIDING), M.SEPARATED),
    (M.SEPARATED, PassengerView(Phase.ABORT), M.SEPARATED),
    (M.STOPPED, PassengerView(Phase.RETURNING, True), M.STOPPED),
    (M.APPROACHING, PassengerView(Phase.RETURNING, True), M.SEPARATED),
    (M.WAITING, PassengerView(Phase.RETURNING, True), M.SEPARATED),
])
def test_recovery_transitions(mode: CarrierMode, view: PassengerView, expected: CarrierMode) -> None:
    new, why = next_mode(mode, view)
    assert new is expected
    assert bool(why) == (new is not mode)


def test_a_whole_recovery_from_the_carriers_side() -> None:
    """Deploy, come home, dock, park, hold, done: the modes the carrier goes through."""
    path = [Phase.JOIN, Phase.RIDING, Phase.SEPARATED, Phase.NAVIGATING, Phase.ARRIVED, Phase.RETURNING,
            Phase.HOLDOFF, Phase.APPROACH, Phase.GO_AROUND, Phase.HOLDOFF, Phase.APPROACH, Phase.DOCKED, Phase.HOME,
            Phase.HOLD, Phase.DONE]
    mode, seen = M.WAITING, [M.WAITING]
    for phase in path:
        mode, _ = next_mode(mode, PassengerView(phase, phase.separated))
        if mode is not seen[-1]:
            seen.append(mode)
    assert seen == [M.WAITING, M.APPROACHING, M.SEPARATED, M.RECOVERING, M.PARKED]


def test_the_course_drives_its_legs_then_the_steady_course() -> None:
    course = RecoveryCourse((Leg(90.0, 1.0, 2.0), Leg(180.0, 2.0, 3.0)), heading_deg=None, speed_m_s=1.5)
    assert course.velocity_ned_m_s(0.0, 10.0) == pytest.approx([0.0, 1.0])
    assert course.velocity_ned_m_s(1.999, 10.0) == pytest.approx([0.0, 1.0])
    assert course.velocity_ned_m_s(2.0, 10.0) == pytest.approx([-2.0, 0.0])
    steady = course.velocity_ned_m_s(5.0, 10.0)  # after the legs: away (10 deg) at 1.5 m/s
    assert steady == pytest.approx([1.5 * math.cos(math.radians(10.0)), 1.5 * math.sin(math.radians(10.0))])
    assert course.velocity_ned_m_s(1e6, 10.0) == pytest.approx(steady)
    fixed = RecoveryCourse.from_lists([], heading_deg=-90.0, speed_m_s=1.0)
    assert fixed.velocity_ned_m_s(3.0, 10.0) == pytest.approx([0.0, -1.0])
    assert not RecoveryCourse().velocity_ned_m_s(3.0, 10.0).any()  # the default: stop and wait


def test_away_from_the_target_is_the_bearing_from_the_target_to_the_carrier() -> None:
    target = np.array([24.0, 18.0, -5.0])
    carrier = target - 7.5 * np.array([0.8, 0.6, 0.0])
    heading = away_heading_deg(np.array([carrier[0], carrier[1], 0.0]), target)
    assert heading == pytest.approx(math.degrees(math.atan2(-0.6, -0.8)))
    v = RecoveryCourse(speed_m_s=1.0).velocity_ned_m_s(0.0, heading)
    assert np.dot(v, carrier[:2] - target[:2]) == pytest.approx(7.5)  # straight away, at 1 m/s
    assert away_heading_deg(target, target) == 0.0
