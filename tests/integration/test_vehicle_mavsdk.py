"""MAVSDK, an independent client nobody here wrote, connects to the mock vehicle, arms it and
flies it offboard, as MAVSDK flies a real PX4 SITL."""
from __future__ import annotations

import socket
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from sim.vehicle import MockVehicle, VehicleOptions

mavsdk = pytest.importorskip("mavsdk")
from mavsdk import ComponentType, Configuration, ConnectionResult, Mavsdk  # noqa: E402
from mavsdk.plugins.action import Action  # noqa: E402
from mavsdk.plugins.offboard import Offboard, VelocityNedYaw  # noqa: E402
from mavsdk.plugins.telemetry import FlightMode, Telemetry  # noqa: E402

pytestmark = [pytest.mark.mavsdk, pytest.mark.timeout(60)]
SPEED = 4.0  # MAVSDK resends setpoints every 0.05 s wall = 0.2 s simulated < COM_OF_LOSS_T


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _until(condition: Callable[[], Any], timeout_s: float, what: str) -> Any:
    """Poll ``condition`` until it returns something truthy; fail with ``what`` at the deadline."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.02)
    pytest.fail(f"timed out after {timeout_s} s waiting for {what}")


@pytest.fixture
def sdk() -> Iterator[Mavsdk]:
    instance = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        yield instance
    finally:
        instance.destroy()  # releases systems, plugins, connections and MAVSDK's threads


def test_mavsdk_connects_arms_and_flies_offboard(sdk: Mavsdk) -> None:
    port = _free_udp_port()
    with MockVehicle(VehicleOptions(bind="127.0.0.1:0", target=f"127.0.0.1:{port}", speed=SPEED)) as vehicle:
        assert sdk.add_any_connection(f"udpin://127.0.0.1:{port}") == ConnectionResult.SUCCESS
        system = sdk.first_autopilot(10.0)
        assert system is not None
        telemetry, action, offboard = Telemetry(system), Action(system), Offboard(system)

        _until(lambda: telemetry.health().is_armable, 5.0, "health is_armable")
        assert telemetry.flight_mode() == FlightMode.HOLD
        action.arm()
        _until(telemetry.armed, 3.0, "armed")

        velocity = VelocityNedYaw(1.0, 0.5, -1.0, 0.0)
        offboard.set_velocity_ned(velocity)
        offboard.start()
        _until(lambda: telemetry.flight_mode() == FlightMode.OFFBOARD, 3.0, "flight mode Offboard")
        assert vehicle.snapshot().mode == "OFFBOARD"

        def following() -> bool:
            pv = telemetry.position_velocity_ned()
            v = pv.velocity
            return (abs(v.north_m_s - 1.0) < 0.05 and abs(v.east_m_s - 0.5) < 0.05 and abs(v.down_m_s + 1.0) < 0.05
                    and pv.position.down_m < -1.0 and pv.position.north_m > 0.5)

        _until(following, 5.0, "position_velocity_ned to follow the commanded velocity")
        snap = vehicle.snapshot()
        assert snap.counters["setpoints_accepted"] > 5 and snap.counters["rx_malformed"] == 0

        offboard.stop()
        _until(lambda: telemetry.flight_mode() == FlightMode.HOLD, 3.0, "flight mode Hold after offboard.stop()")
        hold = vehicle.wait_for(lambda s: abs(s.velocity_ned_m_s).max() < 0.01, 5.0)
        assert hold is not None and hold.mode == "AUTO.LOITER" and hold.armed and not hold.in_failsafe
