"""The carrier controller on real robots' interfaces, over real sockets: a PX4-like Ackermann
rover (the mock vehicle's rover frame) through MAVLink, and a ROS-2-shaped robot through Zenoh
under both key forms. A scripted passenger talks to the carrier over Zenoh.

The rover flights run in lockstep: the test is the carrier clock's upstream (:class:`Stepper`,
what the mission's clock relay is in a flight) and the rover steps on the carrier's clock
(:class:`mission.mavlink.lockstep.MavlinkRelay`), so they do not depend on the machine's load. The ROS 2
robot runs in real time at 3x."""
from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
import zenoh

from mission.carrier.controller import CarrierController
from mission.carrier.modes import CarrierMode
from mission.carrier.backends.mavlink import MavlinkCarrier
from mission.carrier.backends.ros2 import AttachmentWriter, Ros2Carrier, rmw_sequence, robot_clock_keys, ros2_topics
from mission.bus.bridge import CarrierFeed, PassengerPublisher
from mission.time.clock import Clock, LockstepClock, ScaledClock
from mission.bus.lockstep import ZenohRelay, ZenohUpstream
from mission.mavlink.lockstep import MavlinkRelay
from mission.config.schema import Config, from_dict
from mission.bus.wire import PassengerStatus
from mission.phases.phase import Phase
from sim.robots.ros2 import Ros2RobotSim
from sim.vehicle.mock import MockVehicle, VehicleOptions
from tests.support.stepper import Stepper
from tests.support.zenoh_util import peer_pair, wait_for

pytestmark = pytest.mark.timeout(90)

SPEED = 3.0  # real-time processes on a shared 2-core machine: a gentle clock
TARGET = np.array([20.0, 15.0, -4.0])
START = np.array([2.0, 1.0, 0.0])
RADIUS = 8.0 - 0.5


def _cfg(backend: str, kinematics: str, mission: dict[str, Any] | None = None, **carrier: Any) -> Config:
    return from_dict({
        "zenoh": {"pair": "cb"},
        "mission": mission or {},
        "scenario": {"carrier_start": START.tolist(), "target": TARGET.tolist()},
        "safety": {"carrier_max_accel_m_s2": 1.0},
        "carrier": {"backend": backend, "kinematics": kinematics, "max_speed_m_s": 2.0, "passenger_timeout_s": 1.0,
                    "p3_margin_m": 0.5, **carrier},
    })


class ScriptedPassenger:
    """Publishes a phase at 20 Hz (clock) from its own thread: ``phase`` can be changed at any time.
    It begins with three JOIN statuses whatever ``phase`` says (the carrier binds a passenger that
    began on the deck) and says it is on the dock point ``at()`` [m] NED (``carrier_running`` sets
    it to the carrier's)."""

    def __init__(self, session: zenoh.Session, clock: Clock) -> None:
        self.pub = PassengerPublisher(session, "cb", zenoh.CongestionControl.BLOCK)  # the boarding goes out back to back
        self.clock, self.phase, self.seq = clock, "JOIN", 0
        self.at: Callable[[], Any] = lambda: None
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def start(self, at: Callable[[], Any]) -> None:
        """Stand on the deck (three JOIN statuses, at once), then publish from the thread."""
        self.at = at
        for _ in range(3):
            self._say("JOIN")
        self.thread.start()

    def _say(self, phase: str) -> None:
        self.seq += 1
        dock = self.at()
        at = [0.0, 0.0, -1.5] if dock is None else dock
        self.pub.publish(PassengerStatus(phase, self.clock.now(), self.seq, at, [0, 0, 0],
                                         Phase(phase).separated))

    def _run(self) -> None:
        while not self.stop.is_set():
            self.clock.sleep(0.05)  # first: in lockstep every status goes out in a step
            self._say(self.phase)

    def close(self) -> None:
        self.stop.set()
        if self.thread.is_alive():
            self.thread.join(5.0)
        self.pub.close()


@contextlib.contextmanager
def carrier_running(cfg: Config, clock: Clock, session: zenoh.Session, backend: Any, *,
                    stepper: Stepper | None = None, passenger: ScriptedPassenger | None = None) -> Iterator[CarrierController]:
    """The carrier controller in its own thread; with a ``stepper``, each step waits for the
    scripted ``passenger``'s last status to have reached the carrier (Zenoh delivers it on its
    own time; the mission's clock relay waits for it in a flight)."""
    ctl = CarrierController(cfg, clock, session, backend)
    if passenger is not None:
        wait_for(lambda: passenger.pub.matched, 10.0, "the carrier subscribed to the passenger")
        passenger.start(ctl.dock_point_ned_m)
    if stepper is not None and passenger is not None:
        def delivered() -> bool:
            rx = ctl.passenger.latest()
            return passenger.seq == 0 or (rx is not None and rx.status.seq >= passenger.seq)

        stepper.settle = lambda: wait_for(delivered, 10.0, "the passenger's status at the carrier")
    stop = threading.Event()
    thread = threading.Thread(target=ctl.run, args=(stop,), daemon=True)
    thread.start()
    try:
        yield ctl
    finally:
        stop.set()
        if isinstance(clock, LockstepClock):
            clock.close()  # its sleeps end now
        thread.join(5.0)
        assert not thread.is_alive()
        ctl.close()


def _distance(position: np.ndarray) -> float:
    return float(np.linalg.norm(TARGET - position))


@contextlib.contextmanager
def rover_carrier(mission: dict[str, Any] | None = None,
                  **carrier: Any) -> Iterator[tuple[Config, Stepper, zenoh.Session, zenoh.Session, MavlinkCarrier, MockVehicle]]:
    """The carrier's backend on a lockstep mock rover; the carrier's clock driven by a :class:`Stepper`."""
    cfg = _cfg("mavlink", "ackermann", mission, mavlink={"url": "udpin:127.0.0.1:0", "target_system": 2,
                                                         "offset_ned_m": START.tolist()}, **carrier)
    clock = LockstepClock(speed=SPEED, name="carrier", creator_runs=False)
    stepper = Stepper(clock)
    with peer_pair() as (sa, sb):
        backend = MavlinkCarrier(cfg, clock)
        try:
            clock.downstream = relay = MavlinkRelay(backend.link)
            opts = VehicleOptions(target=f"127.0.0.1:{backend.link.port}", speed=SPEED, sysid=2, frame="rover",
                                  lockstep=True)
            with MockVehicle(opts) as rover:
                yield cfg, stepper, sa, sb, backend, rover
                assert clock.fallback_reason in (None, "closed") and not relay.dropped, clock.fallback_reason  # lockstep to the end
        finally:
            clock.close()
            backend.close()


def _watch(rover: MockVehicle, stepper: Stepper, until: Any, timeout_s: float, what: str) -> list[float]:
    """Distances [m] of the rover's true position (shared frame), step by step until ``until()`` holds."""
    distances: list[float] = []

    def check() -> bool:
        distances.append(_distance(rover.snapshot().position_ned_m + START))
        return bool(until())

    stepper.until(check, timeout_s, what)
    return distances


def test_px4_rover_arms_when_the_passenger_rides_and_stops_outside_the_guard_after_separation() -> None:
    with rover_carrier() as (cfg, stepper, sa, sb, backend, rover):
        clock = stepper.clock
        passenger = ScriptedPassenger(sb, clock)
        try:
            with carrier_running(cfg, clock, sa, backend, stepper=stepper, passenger=passenger) as ctl, CarrierFeed(sb, "cb", clock) as feed:
                rx = stepper.until(feed.latest, 5, "carrier state")
                np.testing.assert_allclose(rx.state.position, START, atol=1e-6)  # offset into the shared frame
                assert rx.state.acceleration_ned_m_s2 is None  # carrier.acceleration_tau_s = 0: none sent
                assert not rover.snapshot().armed  # waiting for the passenger: not armed for nothing
                passenger.phase = "RIDING"
                stepper.until(lambda: rover.snapshot().mode == "OFFBOARD" and rover.snapshot().armed, 20, "armed in OFFBOARD")
                d = _watch(rover, stepper, lambda: _distance(rover.snapshot().position_ned_m + START) < 8.3, 30, "near 8 m")
                passenger.phase = "SEPARATED"
                stepper.until(lambda: ctl.mode is CarrierMode.SEPARATED, 5, "separated heard")
                d += _watch(rover, stepper, lambda: rover.snapshot().mode == "AUTO.LOITER"
                            and np.linalg.norm(rover.snapshot().velocity_ned_m_s) < 1e-3, 20, "stopped in Hold")
                summary = ctl.summary()
                assert (ctl.hold_reason or "").startswith("parked")
        finally:
            passenger.close()
        snap = rover.snapshot()
    assert min(d) >= RADIUS, min(d)
    assert summary["braking_distance_m"] is not None and 0.0 < summary["braking_distance_m"] < 3.0
    assert summary["stopped_target_distance_m"] >= RADIUS
    assert snap.mode == "AUTO.LOITER" and snap.armed  # the carrier parked the rover in Hold when it was done
    assert all(b <= a + 0.05 for a, b in zip(d, d[1:]))  # the Ackermann rover closed in without loops


def test_px4_rover_drives_its_recovery_course_parks_in_hold_and_drives_again_for_the_next_target() -> None:
    """mission.final_action = "return": after separation the rover stops but stays ours (OFFBOARD,
    not Hold: it must drive again); while the passenger comes home it drives its recovery course
    (away from the target at 1 m/s); once the passenger is home it parks in Hold, which Hold and
    DONE leave alone; the passenger riding again (the next target) takes it back into OFFBOARD."""
    with rover_carrier({"final_action": "return"}, recovery_speed_m_s=1.0) as (cfg, stepper, sa, sb, backend, rover):
        clock = stepper.clock
        passenger = ScriptedPassenger(sb, clock)
        try:
            with carrier_running(cfg, clock, sa, backend, stepper=stepper, passenger=passenger) as ctl:
                passenger.phase = "RIDING"
                stepper.until(lambda: rover.snapshot().mode == "OFFBOARD" and rover.snapshot().armed, 20, "armed in OFFBOARD")
                d = _watch(rover, stepper, lambda: _distance(rover.snapshot().position_ned_m + START) < 8.3, 30, "near 8 m")
                passenger.phase = "NAVIGATING"
                d += _watch(rover, stepper, lambda: np.linalg.norm(rover.snapshot().velocity_ned_m_s) < 0.05, 20, "stopped")
                stepper.run_for(1.0)
                assert rover.snapshot().mode == "OFFBOARD" and ctl.mode is CarrierMode.SEPARATED  # not parked: a recovery comes
                stood = rover.snapshot().position_ned_m + START
                passenger.phase = "RETURNING"
                d += _watch(rover, stepper, lambda: np.linalg.norm(rover.snapshot().velocity_ned_m_s) > 0.95, 20, "on course")
                passenger.phase = "APPROACH"
                d += _watch(rover, stepper, lambda: _distance(rover.snapshot().position_ned_m + START) > _distance(stood) + 3.0,
                            20, "3 m further away")
                snap = rover.snapshot()
                away = (stood - TARGET)[:2] / np.linalg.norm((stood - TARGET)[:2])
                assert float(np.dot(snap.velocity_ned_m_s[:2], away)) > 0.9  # ~1 m/s straight away from the target
                passenger.phase = "HOME"
                d += _watch(rover, stepper, lambda: rover.snapshot().mode == "AUTO.LOITER", 20, "parked in Hold")
                assert ctl.mode is CarrierMode.PARKED
                for phase in ("HOLD", "DONE"):
                    passenger.phase = phase
                    stepper.until(lambda: ctl.passenger.latest().status.phase == phase, 5, f"{phase} heard")
                    stepper.run_for(1.0)
                assert rover.snapshot().mode == "AUTO.LOITER" and ctl.mode is CarrierMode.PARKED
                passenger.phase = "RIDING"
                stepper.until(lambda: rover.snapshot().mode == "OFFBOARD", 20, "OFFBOARD again")
                d += _watch(rover, stepper, lambda: np.linalg.norm(rover.snapshot().velocity_ned_m_s) > 0.5, 20, "driving again")
                assert ctl.mode is CarrierMode.APPROACHING
        finally:
            passenger.close()
    assert min(d) >= RADIUS, min(d)


def test_px4_rover_publishes_its_velocity_along_its_heading_and_its_measured_acceleration() -> None:
    """carrier.acceleration_tau_s > 0: the state on Zenoh carries the acceleration the rover really
    makes (the law ramps it at safety.carrier_max_accel_m_s2 = 1 m/s^2 once it rolls); its velocity
    is along its heading."""
    with rover_carrier(acceleration_tau_s=0.1) as (cfg, stepper, sa, sb, backend, rover):
        clock = stepper.clock
        passenger = ScriptedPassenger(sb, clock)
        samples: list[Any] = []
        try:
            with carrier_running(cfg, clock, sa, backend, stepper=stepper, passenger=passenger), CarrierFeed(sb, "cb", clock) as feed:
                stepper.until(feed.latest, 5, "carrier state")
                passenger.phase = "RIDING"

                def rolling() -> bool:
                    rx = feed.latest()
                    if rx is not None and (not samples or rx.state.seq != samples[-1].seq):
                        samples.append(rx.state)
                    return rx is not None and float(np.linalg.norm(rx.state.velocity_ned_m_s)) > 1.5

                stepper.until(rolling, 30, "the rover at 1.5 m/s")
        finally:
            passenger.close()
    ramp = [st for st in samples if 0.3 < float(np.linalg.norm(st.velocity_ned_m_s)) < 1.4]
    assert len(ramp) >= 5, len(samples)
    along = []
    for st in ramp:
        assert st.acceleration_ned_m_s2 is not None and st.yaw_rad is not None
        heading = np.array([np.cos(st.yaw_rad), np.sin(st.yaw_rad), 0.0])
        v = st.velocity_ned_m_s
        assert abs(v[0] * heading[1] - v[1] * heading[0]) < 1e-9  # no sideways component
        along.append(float(np.dot(st.acceleration_ned_m_s2, heading)))
    assert 0.5 < float(np.median(along)) < 1.5, along


def test_px4_rover_under_a_passenger_that_never_separates_stops_at_the_guard() -> None:
    with rover_carrier() as (cfg, stepper, sa, sb, backend, rover):
        clock = stepper.clock
        passenger = ScriptedPassenger(sb, clock)
        passenger.phase = "RIDING"
        try:
            with carrier_running(cfg, clock, sa, backend, stepper=stepper, passenger=passenger) as ctl:
                stepper.until(lambda: rover.snapshot().armed, 20, "armed")
                d = _watch(rover, stepper, lambda: ctl.summary()["guard_active_ticks"] > 30
                           and np.linalg.norm(rover.snapshot().velocity_ned_m_s) < 1e-3, 60, "held at the guard")
                assert ctl.mode is CarrierMode.APPROACHING
                # at rest it is held where it came to rest (carrier.mavlink.stand = "position"), and stays
                assert backend.stand_at is not None
                rest, until_s = rover.snapshot().position_ned_m, clock.now() + 5.0
                d += _watch(rover, stepper, lambda: clock.now() >= until_s, 20, "5 s standing")
                assert np.linalg.norm(rover.snapshot().position_ned_m - rest) <= 0.05
        finally:
            passenger.close()
    assert min(d) >= RADIUS, min(d)
    assert d[-1] < RADIUS + 0.5


def test_stale_own_state_stops_the_carrier_and_its_publishing() -> None:
    """A blackout of the rover's link: no LOCAL_POSITION_NED. The carrier stops commanding motion
    and publishes nothing (a stale carrier state must never look fresh to the passenger)."""
    with rover_carrier() as (cfg, stepper, sa, sb, backend, rover):
        clock = stepper.clock
        passenger = ScriptedPassenger(sb, clock)
        passenger.phase = "RIDING"
        try:
            with carrier_running(cfg, clock, sa, backend, stepper=stepper, passenger=passenger) as ctl, CarrierFeed(sb, "cb", clock) as feed:
                stepper.until(lambda: np.linalg.norm(rover.snapshot().velocity_ned_m_s) > 0.5, 30, "moving")
                t0 = rover.snapshot().t_s
                rover.set_faults(blackouts=((t0, 3.0),))
                stepper.until(lambda: (ctl.hold_reason or "").startswith("own state"), 10, "stale own state seen")
                stepper.run_for(0.1)  # the last state published before it went stale has arrived
                seq_stale = feed.latest().state.seq
                stepper.run_for(1.0)
                assert feed.latest().state.seq == seq_stale  # nothing published while stale
                assert ctl.summary()["stale_ticks"] > 0
                stepper.until(lambda: ctl.hold_reason is None, 20, "back in control after the blackout")
        finally:
            passenger.close()


@pytest.mark.parametrize(("key_form", "kinematics"), [("rmw_zenoh", "diff_drive"), ("ros2dds", "holonomic")])
def test_ros2_robot_follows_the_law_and_stops_outside_the_guard(key_form: str, kinematics: str) -> None:
    """rmw_zenoh: the robot steps on the carrier's clock (lockstep; rmw_zenoh's sequence numbers
    order the steps). zenoh-bridge-ros2dds keys carry none: real time at 3x."""
    cfg = _cfg("ros2", kinematics, ros2={"key_form": key_form, "namespace": "robot1", "offset_ned_m": START.tolist()})
    topics = ros2_topics(cfg.carrier.ros2)
    lockstep = key_form == "rmw_zenoh"
    clock: Clock
    if lockstep:
        clock = LockstepClock(speed=SPEED, name="carrier", creator_runs=False)
        robot_clock: Clock = LockstepClock(speed=SPEED, name="robot", creator_runs=False)
        stepper: Stepper | None = Stepper(clock)
        wait: Any = stepper.until
    else:
        clock = robot_clock = ScaledClock(SPEED)
        stepper, wait = None, wait_for
    with peer_pair() as (sa, sb), contextlib.ExitStack() as stack:
        robot = Ros2RobotSim(sb, topics, robot_clock, holonomic=kinematics == "holonomic", yaw_rad=-1.0)
        stack.callback(robot.close)
        if isinstance(clock, LockstepClock) and isinstance(robot_clock, LockstepClock):
            keys = robot_clock_keys(cfg.carrier.ros2)
            stack.callback(ZenohUpstream(robot_clock, sb, keys, robot, published=lambda: robot.published_seq).close)
        stop_robot = threading.Event()
        robot_thread = threading.Thread(target=robot.run, args=(stop_robot,), daemon=True)
        robot_thread.start()
        stack.callback(robot_thread.join, 5.0)
        stack.callback(robot_clock.close)  # (every clock has close; a lockstep sleep ends on it)
        stack.callback(stop_robot.set)
        backend = Ros2Carrier(cfg, clock, sa)
        stack.callback(backend.close)
        relay = None
        if isinstance(clock, LockstepClock):
            clock.downstream = relay = ZenohRelay(sa, robot_clock_keys(cfg.carrier.ros2), backend, backend, name="robot")
            stack.callback(relay.close)
        passenger = ScriptedPassenger(sb, clock)
        stack.callback(passenger.close)
        with carrier_running(cfg, clock, sa, backend, stepper=stepper, passenger=passenger) as ctl:
            wait(lambda: ctl.hold_reason is None, 10, "odometry received")
            state = backend.own_state()
            np.testing.assert_allclose(state.position_ned_m, START, atol=1e-9)  # odom origin + offset
            assert state.yaw_rad == pytest.approx(-1.0)  # ENU quaternion back to the NED heading
            passenger.phase = "RIDING"
            d: list[float] = []

            def near() -> bool:
                d.append(_distance(robot.position_m + START))
                return d[-1] < 8.3

            wait(near, 40, "near 8 m")
            passenger.phase = "SEPARATED"

            def stopped() -> bool:
                d.append(_distance(robot.position_m + START))
                return ctl.mode is CarrierMode.SEPARATED and np.linalg.norm(robot.body_velocity) < 1e-6

            wait(stopped, 20, "stopped")
            assert robot.commands > 30 and backend.dropped == {}
            assert relay is None or not relay.dropped  # in lockstep to the end
    assert min(d) >= RADIUS, min(d)


def test_ros2_keys_of_both_forms() -> None:
    from mission.config.schema import CarrierRos2Section

    dds = ros2_topics(CarrierRos2Section(namespace="/robot1/"))
    assert (dds.odom_sub, dds.cmd_vel_pub) == ("robot1/odom", "robot1/cmd_vel")
    rmw = ros2_topics(CarrierRos2Section(key_form="rmw_zenoh", domain_id=3))
    assert rmw.odom_sub == "3/odom/nav_msgs::msg::dds_::Odometry_/*"
    assert rmw.cmd_vel_pub == ("3/cmd_vel/geometry_msgs::msg::dds_::Twist_/"
                               "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a")
    assert zenoh.KeyExpr(rmw.cmd_vel_sub).intersects(zenoh.KeyExpr(rmw.cmd_vel_pub))
    assert zenoh.KeyExpr(rmw.odom_sub).intersects(zenoh.KeyExpr(rmw.odom_pub))
    # lockstep (simulation): the robot's clock keys, and rmw_zenoh's sequence numbers that order its steps
    assert robot_clock_keys(CarrierRos2Section(namespace="/robot1/", domain_id=3)) == (
        "marsupial/robot_clock/3/robot1/time", "marsupial/robot_clock/3/robot1/ready")
    attachment = AttachmentWriter()
    assert [rmw_sequence(zenoh.ZBytes(attachment.next())) for _ in range(3)] == [1, 2, 3]
    assert rmw_sequence(None) is None and rmw_sequence(zenoh.ZBytes(b"\x00foreign")) is None


def test_px4_carrier_in_the_shared_frame_through_its_ekf_origin() -> None:
    """carrier.mavlink.shared_origin: the rover's EKF origin lies 10 m north and 5 m east of the
    shared frame's origin, so its LOCAL_POSITION_NED (0, 0) is (10, 5) in the shared frame."""
    from mission.bus.wire import GeoOrigin, ned_to_geodetic

    shared = (47.397742, 8.545594, 488.0)
    home = ned_to_geodetic(np.array([10.0, 5.0, 0.0]), GeoOrigin(*shared))
    cfg = _cfg("mavlink", "ackermann", mavlink={"url": "udpin:127.0.0.1:0", "target_system": 2,
                                                "shared_origin": list(shared)})
    clock = ScaledClock(SPEED)
    backend = MavlinkCarrier(cfg, clock)
    try:
        with MockVehicle(VehicleOptions(target=f"127.0.0.1:{backend.link.port}", speed=SPEED, sysid=2, frame="rover",
                                        home=home)):
            state = wait_for(backend.own_state, 20, "the rover's state in the shared frame")
            np.testing.assert_allclose(state.position_ned_m[:2], [10.0, 5.0], atol=0.01)
            assert backend.control_fault() == "waiting for the passenger (not armed)"  # origin known
    finally:
        backend.close()
