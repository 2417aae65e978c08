"""MAVSDK, an independent client nobody here wrote, connects to the mock vehicle, arms it and
flies it offboard, as MAVSDK flies a real PX4 SITL."""
from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest

from sim.net import free_port, wait_for
from sim.vehicle.mock import MockVehicle, VehicleOptions

mavsdk = pytest.importorskip("mavsdk")
from mavsdk import ComponentType, Configuration, ConnectionResult, Mavsdk  # noqa: E402
from mavsdk.plugins.action import Action  # noqa: E402
from mavsdk.plugins.offboard import Offboard, VelocityNedYaw  # noqa: E402
from mavsdk.plugins.telemetry import FlightMode, Telemetry  # noqa: E402

pytestmark = [pytest.mark.mavsdk, pytest.mark.timeout(60)]
SPEED = 4.0  # MAVSDK resends setpoints every 0.05 s wall = 0.2 s simulated < COM_OF_LOSS_T


@pytest.fixture
def sdk() -> Iterator[Mavsdk]:
    instance = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        yield instance
    finally:
        instance.destroy()  # releases systems, plugins, connections and MAVSDK's threads


def test_mavsdk_connects_arms_and_flies_offboard(sdk: Mavsdk) -> None:
    port = free_port(socket.SOCK_DGRAM)
    # exact estimate: the checks wait for the vehicle at rest, which PX4's estimate never quite reports
    with MockVehicle(VehicleOptions(bind="127.0.0.1:0", target=f"127.0.0.1:{port}", speed=SPEED, estimate_error=0.0)) as vehicle:
        assert sdk.add_any_connection(f"udpin://127.0.0.1:{port}") == ConnectionResult.SUCCESS
        system = sdk.first_autopilot(10.0)
        assert system is not None
        telemetry, action, offboard = Telemetry(system), Action(system), Offboard(system)

        wait_for(lambda: telemetry.health().is_armable, 5.0, "health is_armable")
        assert telemetry.flight_mode() == FlightMode.HOLD
        action.arm()
        wait_for(telemetry.armed, 3.0, "armed")

        velocity = VelocityNedYaw(1.0, 0.5, -1.0, 0.0)
        offboard.set_velocity_ned(velocity)
        offboard.start()
        wait_for(lambda: telemetry.flight_mode() == FlightMode.OFFBOARD, 3.0, "flight mode Offboard")
        assert vehicle.snapshot().mode == "OFFBOARD"

        def following() -> bool:
            pv = telemetry.position_velocity_ned()
            v = pv.velocity
            return (abs(v.north_m_s - 1.0) < 0.05 and abs(v.east_m_s - 0.5) < 0.05 and abs(v.down_m_s + 1.0) < 0.05
                    and pv.position.down_m < -1.0 and pv.position.north_m > 0.5)

        wait_for(following, 5.0, "position_velocity_ned to follow the commanded velocity")
        snap = vehicle.snapshot()
        assert snap.counters["setpoints_accepted"] > 5 and snap.counters["rx_malformed"] == 0

        offboard.stop()
        wait_for(lambda: telemetry.flight_mode() == FlightMode.HOLD, 3.0, "flight mode Hold after offboard.stop()")
        hold = wait_for(vehicle.when(lambda s: abs(s.velocity_ned_m_s).max() < 0.01), 5.0, "the vehicle at rest")
        assert hold is not None and hold.mode == "AUTO.LOITER" and hold.armed and not hold.in_failsafe
