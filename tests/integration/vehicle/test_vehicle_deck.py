"""The mock vehicle on the carrier's moving deck (sim/vehicle/physics/deck.py), over real UDP in
lockstep: a setpoint stream descending onto a deck that moves north at 1 m/s. Gentle: landed,
carried with the deck, PX4's land detector and auto-disarm; too fast down or across, or off the
deck's edge: a crash, with its reason. A deck faster than PX4's LNDMC_XY_VEL_MAX carries a vehicle
PX4 believes is flying."""
from __future__ import annotations

import contextlib
import itertools
import math
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

from mission.bus.bridge import CarrierPublisher
from mission.bus.wire import CarrierState
from mission.mavlink import px4, setpoints
from sim.testing.probe import Probe, SetpointStream, connect, start_offboard, vehicle_for, wait_flight
from sim.vehicle.mock import MockVehicle, VehicleSnapshot
from sim.robots.deck_follow import follow_carrier
from sim.vehicle.physics.deck import DeckMotion, DeckSpec
from tests.support.zenoh_util import peer_pair

pytestmark = pytest.mark.timeout(60)

HEIGHT_M = 0.3  # the deck's plane 0.3 m above the carrier's position (z = 0): NED d = -0.3
SPEC = DeckSpec(height_m=HEIGHT_M, radius_m=0.5, edge_m=0.25, max_vertical_m_s=1.0, max_horizontal_m_s=0.5)


def on_moving_deck(probe: Probe, speed_m_s: float = 1.0) -> MockVehicle:
    """A vehicle standing on the deck's centre; the deck moves north at ``speed_m_s`` from t = 0. Its
    estimate is exact: the touchdowns come at the speeds and places the tests set, to 0.05 m/s."""
    v = vehicle_for(probe, paced=True, speed=20.0, deck=SPEC, start_ned=(0.0, 0.0, -HEIGHT_M), estimate_error=0.0)
    motion = DeckMotion((0.0, 0.0, 0.0), (speed_m_s, 0.0, 0.0), 0.0)
    # known before the clock runs: learnt a step late, the deck stood one step (1 cm) ahead of the
    # vehicle standing on it for good (a loaded machine's wall-clock race)
    v.follow_deck(lambda: motion)
    v.start()
    return v


def deck_centre(t_s: float, speed_m_s: float = 1.0) -> np.ndarray:
    return np.array([speed_m_s * t_s, 0.0, -HEIGHT_M])


def over_the_deck(v: MockVehicle, stream: SetpointStream, until: Callable[[VehicleSnapshot], bool], what: str, *,
                  offset_m: tuple[float, float, float] = (0.0, 0.0, -1.0), relative_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
                  speed_m_s: float = 1.0, timeout_s: float = 15.0) -> VehicleSnapshot:
    """Stream position + velocity setpoints that move with the deck (at every step of the
    vehicle's simulated time): from ``offset_m`` [m] NED off its centre, moving ``relative_m_s``
    [m/s] relative to it, until ``until(snapshot)`` holds."""
    t0 = v.snapshot().t_s

    def goal(t_s: float) -> dict[str, Any]:
        at = deck_centre(t_s, speed_m_s) + np.asarray(offset_m) + np.asarray(relative_m_s) * max(t_s - t0, 0.0)
        return {"type_mask": setpoints.TYPE_MASK_POSITION_VELOCITY_ACCELERATION, "position_ned_m": tuple(at),
                "velocity_ned_m_s": (speed_m_s + relative_m_s[0], relative_m_s[1], relative_m_s[2]),
                "acceleration_ned_m_s2": (0.0, 0.0, 0.0)}
    stream.follow(goal)
    return wait_flight(v, until, timeout_s, what)


def lift_off_and_hover(v: MockVehicle, probe: Probe, above_m: float = 1.0, speed_m_s: float = 1.0,
                       offset_ne_m: tuple[float, float] = (0.0, 0.0)) -> SetpointStream:
    """Take off from the moving deck and fly with it ``above_m`` over its plane, ``offset_ne_m`` off
    its centre, settled."""
    stream = start_offboard(probe, (speed_m_s, 0.0, -1.0))
    wait_flight(v, lambda s: not s.on_deck and s.position_ned_m[2] < -HEIGHT_M - 0.2, 10.0, "off the deck")
    goal = (offset_ne_m[0], offset_ne_m[1], -above_m)

    def settled(s: VehicleSnapshot) -> bool:
        error = s.position_ned_m - deck_centre(s.t_s, speed_m_s) - np.asarray(goal)
        return bool(np.linalg.norm(error) < 0.05 and np.linalg.norm(s.velocity_ned_m_s - [speed_m_s, 0.0, 0.0]) < 0.05)
    over_the_deck(v, stream, settled, "settled over the deck", offset_m=goal, speed_m_s=speed_m_s)
    return stream


def test_standing_on_the_deck_it_is_carried_and_px4_sees_it_landed(probe: Probe):
    with on_moving_deck(probe) as v:
        connect(probe)
        s = wait_flight(v, lambda s: s.t_s > 3.0, 10.0, "3 s on the deck")
        assert s.on_deck and s.crash is None and s.landed_state == px4.LANDED_ON_GROUND
        assert np.allclose(s.position_ned_m, deck_centre(s.t_s), atol=1e-6)
        assert s.velocity_ned_m_s == pytest.approx([1.0, 0.0, 0.0])


def test_gentle_descent_lands_on_the_deck_rides_with_it_and_auto_disarms(probe: Probe):
    with on_moving_deck(probe) as v:
        connect(probe)
        stream = lift_off_and_hover(v, probe)
        landed = over_the_deck(v, stream, lambda s: s.on_deck, "touchdown", relative_m_s=(0.0, 0.0, 0.4))
        later = wait_flight(v, lambda s: s.t_s > landed.t_s + 1.0, 5.0, "a second on the deck")
        stream.stop()
        assert landed.crash is None and later.crash is None
        touch = landed.touchdowns[-1]
        assert touch.crash is None and touch.vertical_speed_m_s == pytest.approx(0.4, abs=0.05)
        assert touch.horizontal_speed_m_s < 0.05 and touch.horizontal_error_m < 0.1
        # carried: where it touched down, relative to the moving deck
        offset = landed.position_ned_m - deck_centre(landed.t_s)
        assert np.allclose(later.position_ned_m - deck_centre(later.t_s), offset, atol=1e-6)
        assert later.landed_state == px4.LANDED_ON_GROUND
        disarmed = wait_flight(v, lambda s: not s.armed, 10.0, "the auto-disarm")
        t_landed, t_disarmed = v.event_time("Landing detected"), v.event_time("Disarmed by landing")
        assert t_landed is not None and t_disarmed is not None
        assert t_disarmed - t_landed == pytest.approx(2.0, abs=0.02)  # COM_DISARM_LAND
        assert np.allclose(disarmed.position_ned_m - deck_centre(disarmed.t_s), offset, atol=1e-6)


def test_descending_too_fast_is_a_crash_with_its_reason(probe: Probe):
    with on_moving_deck(probe) as v:
        connect(probe)
        stream = lift_off_and_hover(v, probe, above_m=2.0)
        crashed = over_the_deck(v, stream, lambda s: s.crash is not None, "the crash", offset_m=(0.0, 0.0, -2.0),
                                relative_m_s=(0.0, 0.0, 3.0))  # PX4 limits the descent to MPC_Z_VEL_MAX_DN 1.5 m/s
        stream.stop()
        assert crashed.crash.startswith("hit the deck at 1.") and "vertically (limit 1 m/s)" in crashed.crash
        wreck = wait_flight(v, lambda s: s.t_s > crashed.t_s + 1.0, 5.0, "a second later")
        assert wreck.on_deck and np.allclose(wreck.position_ned_m - deck_centre(wreck.t_s),
                                             crashed.position_ned_m - deck_centre(crashed.t_s), atol=1e-6)
        assert "CRASHED" in v.status_line()


def test_landing_across_the_deck_too_fast_is_a_crash(probe: Probe):
    with on_moving_deck(probe) as v:
        connect(probe)
        stream = lift_off_and_hover(v, probe, above_m=0.4, offset_ne_m=(0.45, 0.0))
        crashed = over_the_deck(v, stream, lambda s: s.crash is not None, "the crash", offset_m=(0.45, 0.0, -0.4),
                                relative_m_s=(-1.2, 0.0, 0.8))  # 1.2 m/s back across the deck, coming down
        stream.stop()
        assert "across it (limit 0.5 m/s)" in crashed.crash, crashed.touchdowns


def test_touching_down_off_the_edge_is_a_crash(probe: Probe):
    with on_moving_deck(probe) as v:
        connect(probe)
        stream = lift_off_and_hover(v, probe, offset_ne_m=(0.0, 0.6))
        crashed = over_the_deck(v, stream, lambda s: s.crash is not None, "the crash", offset_m=(0.0, 0.6, -1.0),
                                relative_m_s=(0.0, 0.0, 0.3))
        stream.stop()
        assert crashed.crash.startswith("off the deck's edge: 0.6"), crashed.crash


def test_descending_beside_the_deck_touches_nothing_but_the_ground(probe: Probe):
    with on_moving_deck(probe) as v:
        connect(probe)
        stream = lift_off_and_hover(v, probe, offset_ne_m=(0.0, 1.0))
        ground = over_the_deck(v, stream, lambda s: s.landed_state == px4.LANDED_ON_GROUND, "the ground",
                               offset_m=(0.0, 1.0, -1.0), relative_m_s=(0.0, 0.0, 0.3))
        stream.stop()
        assert ground.crash is None and not ground.on_deck and ground.position_ned_m[2] == pytest.approx(0.0)
        assert len(ground.touchdowns) == 1  # only the start on the deck


def test_on_a_deck_faster_than_px4s_land_detector_px4_believes_it_flies(probe: Probe):
    with on_moving_deck(probe, speed_m_s=2.0) as v:
        connect(probe)
        stream = lift_off_and_hover(v, probe, speed_m_s=2.0)
        landed = over_the_deck(v, stream, lambda s: s.on_deck, "touchdown", relative_m_s=(0.0, 0.0, 0.4), speed_m_s=2.0)
        later = wait_flight(v, lambda s: s.t_s > landed.t_s + 4.0, 10.0, "4 s on the deck")
        stream.stop()
        assert landed.crash is None and later.on_deck and later.armed  # no auto-disarm
        assert later.landed_state == px4.LANDED_IN_AIR
        assert math.isclose(later.velocity_ned_m_s[0], 2.0)


@contextlib.contextmanager
def every_50_ms(publish: Callable[[float, int], None]) -> Iterator[None]:
    """Call ``publish(t, seq)`` on a thread every 0.05 s of wall time (``t`` [s] since it began,
    ``seq`` 0, 1, ...) until the block ends; the thread is joined before it returns."""
    stop = threading.Event()

    def run() -> None:
        t0 = time.monotonic()
        for seq in itertools.count():
            publish(time.monotonic() - t0, seq)
            if stop.wait(0.05):
                return
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(5.0)


def test_the_deck_moves_as_the_carriers_zenoh_state_says(probe: Probe):
    """``mock-vehicle --deck PAIR``'s feed (sim.robots.deck_follow.follow_carrier): the carrier's state
    published on Zenoh (loopback) at 20 Hz, moving north at 1 m/s, carries the vehicle standing on
    its deck (both on wall time here: the publisher has no simulated clock)."""
    with peer_pair() as (carrier_side, vehicle_side):
        publisher = CarrierPublisher(carrier_side, "deck0")
        with vehicle_for(probe, speed=1.0, deck=SPEC, start_ned=(0.0, 0.0, -HEIGHT_M)) as v:
            feed = follow_carrier(v, vehicle_side, "deck0")
            published: list[float] = []

            def publish(t: float, seq: int) -> None:
                publisher.publish(CarrierState(stamp_s=t, seq=seq, frame="local_ned", position=(t, 0.0, 0.0),
                                               velocity_ned_m_s=(1.0, 0.0, 0.0)))
                published.append(t)
            at_check: list[float] = []  # the newest publication when each snapshot was judged

            def carried_north(s: Any) -> bool:
                at_check.append(published[-1] if published else math.nan)
                return bool(s.position_ned_m[0] > 1.5)

            try:
                with every_50_ms(publish):
                    carried = wait_flight(v, carried_north, 10.0, "carried 1.5 m north")
                    # read with the snapshot, not after it: on a loaded machine the publisher had gone
                    # on 0.33 s before the test read its list (carried 1.50 m against 1.83 m)
                    now = at_check[-1]
            finally:
                feed.close()
                publisher.close()
    assert carried.on_deck and carried.crash is None and carried.velocity_ned_m_s == pytest.approx([1.0, 0.0, 0.0])
    assert carried.position_ned_m[0] == pytest.approx(now, abs=0.2)  # where the carrier is, within 0.2 s of it
    assert carried.position_ned_m[1:] == pytest.approx([0.0, -HEIGHT_M])


def test_with_deck_truth_the_deck_follows_the_carriers_truth_not_its_erring_state(probe: Probe):
    """``mock-vehicle --deck PAIR --deck-truth``: the carrier publishes its erring state (here 3 m
    east of the truth, a GNSS bias) and its truth on the sim-only key (sim.robots.truth); the deck
    carries the vehicle along the truth, and the truth track samples both (10 Hz)."""
    from mission.carrier.backends import OwnState
    from mission.time.clock import ManualClock
    from sim.robots.truth import TruthPublisher, TruthTrack

    with peer_pair() as (carrier_side, vehicle_side):
        publisher = CarrierPublisher(carrier_side, "deck1")
        truth = TruthPublisher(carrier_side, "deck1", ManualClock())
        track = TruthTrack()
        with vehicle_for(probe, speed=1.0, deck=SPEC, start_ned=(0.0, 0.0, -HEIGHT_M)) as v:
            feed = follow_carrier(v, vehicle_side, "deck1", truth=True, track=track)

            def publish(t: float, seq: int) -> None:
                publisher.publish(CarrierState(stamp_s=t, seq=seq, frame="local_ned", position=(t, 3.0, 0.0),
                                               velocity_ned_m_s=(1.0, 0.0, 0.0)))
                truth(OwnState(t, np.array([t, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]), 0.0))
            try:
                with every_50_ms(publish):
                    carried = wait_flight(v, lambda s: s.position_ned_m[0] > 1.5, 10.0, "carried 1.5 m north")
            finally:
                feed.close()
                truth.close()
                publisher.close()
    assert carried.on_deck and carried.crash is None
    assert carried.position_ned_m[1:] == pytest.approx([0.0, -HEIGHT_M])  # on the truth, not 3 m east
    got = track.as_dict()
    assert len(got["t_s"]) >= 10 and all(abs(c[1]) < 1e-9 for c in got["carrier_ned_m"])
