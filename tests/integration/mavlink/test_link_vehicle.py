"""VehicleLink flying the PX4-like mock vehicle (sim/vehicle/mock.py) over real loopback UDP.

Both ends share the speed factor, so times below are simulated seconds of the link clock.
Setpoints are streamed from a thread of the test, as the controller's loop would, while the
blocking mode and arming calls wait for their HEARTBEAT confirmation.
"""
from __future__ import annotations

import threading
from collections.abc import Iterator

import numpy as np
import pytest

from mission.core.setpoint import Setpoint
from mission.mavlink import px4
from mission.time.clock import Periodic, ScaledClock
from mission.errors import CommandRejected, LinkTimeout
from mission.mavlink.link import VehicleLink
from sim.vehicle.mock import MockVehicle, VehicleOptions
from sim.net import wait_for as eventually

SPEED = 10.0
KEY = bytes(range(7, 39))


class Streamer:
    """Sends ``velocity`` at ``rate_hz`` of the link clock from its own thread until stopped."""

    def __init__(self, link: VehicleLink, rate_hz: float = 20.0) -> None:
        self.link, self.period_s = link, 1.0 / rate_hz
        self.velocity = np.zeros(3)
        self.sent = 0
        self.last_sent_s = -1.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="test-streamer", daemon=True)

    def __enter__(self) -> Streamer:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)

    def _run(self) -> None:
        tick = Periodic(self.link.clock, self.period_s)
        while not self._stop.is_set():
            self.link.send(Setpoint.velocity_only(self.velocity))
            self.sent += 1
            self.last_sent_s = self.link.clock.now()
            tick.wait()


def _threads() -> set[threading.Thread]:
    return {t for t in threading.enumerate() if t.name.startswith(("marsupial-link", "mock-vehicle", "test-streamer"))}


@pytest.fixture(autouse=True)
def no_leaked_threads() -> Iterator[None]:
    before = _threads()
    yield
    leaked = _threads() - before
    assert not leaked, f"threads left running: {[t.name for t in leaked]}"


@pytest.fixture
def link() -> Iterator[VehicleLink]:
    with VehicleLink("udpin:127.0.0.1:0", ScaledClock(SPEED)) as lk:
        yield lk


def _vehicle(link: VehicleLink, **options: object) -> MockVehicle:
    return MockVehicle(VehicleOptions(bind="127.0.0.1:0", target=f"127.0.0.1:{link.port}", speed=SPEED, **options))  # type: ignore[arg-type]


def test_offboard_flight_follow_velocity_hold_and_land(link: VehicleLink) -> None:
    with _vehicle(link, estimate_error=0.0) as vehicle:  # exact: at rest to 0.2 m/s
        link.wait_vehicle(20.0)
        # EXTENDED_SYS_STATE comes on its own stream: wait for it too, or a loaded machine asserts
        # on a landed state not yet heard (None)
        s = link.wait_until(lambda s: s.position_valid and s.origin is not None and s.landed_state is not None, 20.0)
        assert s.mode == "AUTO.LOITER" and not s.armed and s.landed_state == px4.LANDED_ON_GROUND
        assert s.origin == pytest.approx(vehicle.options.home, abs=1e-6)
        with Streamer(link) as stream:
            eventually(lambda: stream.sent >= 20, what="1 s of setpoints before the switch")
            link.set_mode("OFFBOARD")
            link.arm()
            truth = vehicle.snapshot()
            assert truth.armed and truth.mode == "OFFBOARD"
            stream.velocity = np.array([0.0, 0.0, -1.5])  # climb
            link.wait_until(lambda s: s.position_ned_m[2] < -3.0, 30.0)
            stream.velocity = np.array([2.0, 0.0, 0.0])  # north
            s = link.wait_until(lambda s: s.position_ned_m[0] > 4.0 and s.velocity_ned_m_s[0] > 1.8, 30.0)
            assert abs(s.velocity_ned_m_s[1]) < 0.2 and abs(s.velocity_ned_m_s[2]) < 0.3
            truth = vehicle.snapshot()
            assert np.linalg.norm(truth.position_ned_m - s.position_ned_m) < 1.0  # telemetry follows truth
            link.hold()
        assert vehicle.snapshot().mode == "AUTO.LOITER"
        s = link.wait_until(lambda s: np.linalg.norm(s.velocity_ned_m_s) < 0.2, 30.0)
        assert s.mode == "AUTO.LOITER" and s.armed and s.position_ned_m[2] < -2.5
        link.land()
        s = link.wait_until(lambda s: s.landed_state == px4.LANDED_ON_GROUND and not s.armed, 60.0)
        assert abs(s.position_ned_m[2]) < 0.2
        assert link.counters.rx_bad == 0 and link.counters.rejected_foreign == 0


def test_stopped_stream_lets_the_offboard_failsafe_fire(link: VehicleLink) -> None:
    """No background resend: when the (test's) control loop stops, PX4's failsafe takes over."""
    with _vehicle(link) as vehicle:
        link.wait_vehicle(20.0)
        link.wait_until(lambda s: s.position_valid, 20.0)
        with Streamer(link) as stream:
            eventually(lambda: stream.sent >= 20, what="setpoints before the switch")
            link.set_mode("OFFBOARD")
            link.arm()
            stream.velocity = np.array([0.0, 0.0, -1.0])
            link.wait_until(lambda s: s.position_ned_m[2] < -1.5, 30.0)
        t_last = stream.last_sent_s
        accepted = vehicle.snapshot().counters["setpoints_accepted"]
        s = link.wait_until(lambda s: s.mode != "OFFBOARD", 10.0)
        assert s.heartbeat_rx_s - t_last >= 1.0 - 0.15  # COM_OF_LOSS_T, minus one physics/heartbeat slack
        assert s.mode == px4.OFFBOARD_LOSS_ACTION_MODE[0] and s.system_status == px4.MAV_STATE_CRITICAL
        assert vehicle.snapshot().counters["setpoints_accepted"] == accepted
        assert link.counters.tx_setpoints == stream.sent
        assert any("Failsafe" in text for _, _, text in link.statustexts)


def test_refused_arming_carries_the_vehicle_reason(link: VehicleLink) -> None:
    reason = "Arming denied: Resolve system health failures first"
    with _vehicle(link) as vehicle:
        vehicle.refuse_arming(reason)
        link.wait_vehicle(20.0)
        with pytest.raises(CommandRejected) as info:
            link.arm(retries=0)
        assert info.value.result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        assert info.value.command == px4.MAV_CMD_COMPONENT_ARM_DISARM
        assert info.value.reason == reason
        assert not vehicle.snapshot().armed


def test_offboard_without_a_stream_is_refused(link: VehicleLink) -> None:
    with _vehicle(link) as vehicle:
        link.wait_vehicle(20.0)
        link.wait_until(lambda s: s.position_valid, 20.0)
        with pytest.raises(CommandRejected) as info:
            link.set_mode("OFFBOARD", retries=0)
        assert info.value.result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        assert "no offboard signal" in info.value.reason
        assert vehicle.snapshot().mode == "AUTO.LOITER"


def test_takeoff_to_altitude_then_land(link: VehicleLink) -> None:
    with _vehicle(link, estimate_error=0.0) as vehicle:  # exact: the height reached, to 0.3 m
        link.wait_vehicle(20.0)
        link.wait_until(lambda s: s.position_valid and s.origin is not None, 20.0)
        link.arm()
        assert link.takeoff(3.0) == px4.MAV_RESULT_ACCEPTED
        s = link.wait_until(lambda s: s.position_ned_m[2] < -2.8 and abs(s.velocity_ned_m_s[2]) < 0.1, 60.0)
        assert s.position_ned_m[2] > -3.3
        link.land()
        link.wait_until(lambda s: s.landed_state == px4.LANDED_ON_GROUND and not s.armed, 60.0)
        assert not vehicle.snapshot().armed


def test_signed_link_flies_a_signed_vehicle() -> None:
    with VehicleLink("udpin:127.0.0.1:0", ScaledClock(SPEED), signing_key=KEY) as signed, \
            _vehicle(signed, signing_key=KEY) as vehicle:
        signed.wait_vehicle(20.0)
        signed.wait_until(lambda s: s.position_valid, 20.0)
        signed.arm()
        assert vehicle.snapshot().armed
        signed.disarm()
        assert not vehicle.snapshot().armed
        assert signed.counters.rx_bad_signature == 0
        assert vehicle.counters["rx_unsigned_rejected"] == 0


def test_home_placed_through_the_ekf_origin_and_read_back(link: VehicleLink) -> None:
    """DO_SET_HOME as COMMAND_INT lands within a centimetre of the NED point; HOME_POSITION brings
    it back."""
    with _vehicle(link, home=(47.1, 8.2, 410.0)) as vehicle:
        link.wait_vehicle(20.0)
        link.wait_until(lambda s: s.origin is not None, 20.0)
        assert link.set_home(np.array([-12.5, 30.25, 0.5])) == px4.MAV_RESULT_ACCEPTED
        assert vehicle.snapshot().home_ned_m == pytest.approx([-12.5, 30.25, 0.5], abs=0.015)
        s = link.wait_until(lambda s: s.home_ned_m is not None and s.home_ned_m[0] < -12.0, 10.0)
        assert s.home_ned_m == pytest.approx([-12.5, 30.25, 0.5], abs=0.015)
        assert link.counters.tx_commands == 1


def test_parameters_read_and_written_int_and_float(link: VehicleLink) -> None:
    with _vehicle(link) as vehicle:
        link.wait_vehicle(20.0)
        assert link.get_param("COM_OBL_RC_ACT") == 0.0  # an INT32, bit-packed on the wire
        assert link.set_param("COM_OBL_RC_ACT", 3) == 3.0
        assert vehicle.params.get("COM_OBL_RC_ACT") == 3.0
        assert link.set_param("COM_OF_LOSS_T", 1.5) == 1.5  # a REAL32
        assert vehicle.params.get("COM_OF_LOSS_T") == 1.5
        with pytest.raises(LinkTimeout, match="NO_SUCH_PARAM"):
            link.get_param("NO_SUCH_PARAM", timeout_s=0.2, retries=1)  # PX4 does not answer for it
