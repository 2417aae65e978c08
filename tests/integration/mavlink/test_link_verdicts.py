"""No single sample decides that the vehicle is disarmed or landed: forged EXTENDED_SYS_STATE and
HEARTBEAT packets arriving on the vehicle's own address (a forwarding autopilot, a spoofed
source) against VehicleLink over real loopback sockets, read as the mission reads them
(the link's report, :func:`mission.mavlink.telemetry.vehicle_report`, observed by the passenger's
step, :func:`mission.passenger.step.observe_vehicle`). docs/security.md, "Attacks tried"."""
from __future__ import annotations

from mission.mavlink import px4
from mission.mavlink.env import mavlink
from mission.mavlink.link import VehicleLink
from mission.mavlink.telemetry import VehicleState, vehicle_report
from mission.passenger.step import observe_vehicle
from mission.phases import VehicleObs
from mission.time.clock import ManualClock
from sim.testing.fake_px4 import FakePx4 as Px4Peer
from tests.integration.mavlink.conftest import ANY_PORT


def _vehicle_obs(state: VehicleState) -> VehicleObs | None:
    return observe_vehicle(vehicle_report(state))


def _landed(state: int) -> object:
    return mavlink.MAVLink_extended_sys_state_message(0, state)


def _mark(peer: Px4Peer, link: VehicleLink, text: str) -> None:
    """Everything the peer sent before is applied once its STATUSTEXT ``text`` shows."""
    peer.statustext(text, severity=6)
    link.wait_until(lambda s: s.last_statustext == text, 5.0)


def test_one_forged_on_ground_in_flight_decides_nothing_two_sources_or_time_do() -> None:
    clock = ManualClock(5.0)
    with VehicleLink(ANY_PORT, clock) as link, Px4Peer(link.port, position_ned_m=(3.0, 1.0, -4.6)) as peer:
        peer.armed, peer.custom_mode = True, px4.custom_mode_of("OFFBOARD")
        link.wait_vehicle(timeout_s=5.0)
        peer.send(_landed(px4.LANDED_IN_AIR))
        link.wait_until(lambda s: s.armed and s.landed_state == px4.LANDED_IN_AIR, 5.0)
        peer.send(_landed(px4.LANDED_ON_GROUND))  # the forgery: one packet, HEARTBEAT armed, 4.6 m up
        _mark(peer, link, "forged")
        obs = _vehicle_obs(link.state)
        assert link.state.landed_state == px4.LANDED_ON_GROUND  # the raw sample is there ...
        assert obs is not None and obs.armed and not obs.on_ground  # ... but decides nothing (on main: landed)
        peer.send(_landed(px4.LANDED_IN_AIR))  # the vehicle's own next sample
        clock.advance(0.1)
        peer.send(_landed(px4.LANDED_ON_GROUND))  # a second forgery later: the run started afresh
        _mark(peer, link, "forged again")
        obs = _vehicle_obs(link.state)
        assert obs is not None and not obs.on_ground
        clock.advance(0.1)  # ON_GROUND for 0.1 s, nothing else between: PX4's land detector, believed
        peer.send(_landed(px4.LANDED_ON_GROUND))
        _mark(peer, link, "still on the ground")
        obs = _vehicle_obs(link.state)
        assert obs is not None and obs.on_ground and obs.armed  # landed, armed: pressing on a deck
        # a forced disarm: HEARTBEAT disarmed and ON_GROUND agree at once
        peer.send(_landed(px4.LANDED_IN_AIR))
        _mark(peer, link, "up again")
        peer.armed = False
        link.wait_until(lambda s: not s.armed, 5.0)
        obs = _vehicle_obs(link.state)
        assert obs is not None and obs.armed  # one source alone: HEARTBEAT disarmed, in the air
        peer.send(_landed(px4.LANDED_ON_GROUND))
        _mark(peer, link, "disarmed and down")
        obs = _vehicle_obs(link.state)
        assert obs is not None and not obs.armed and obs.on_ground


def test_one_forged_disarmed_heartbeat_in_flight_decides_nothing() -> None:
    clock = ManualClock(5.0)
    with VehicleLink(ANY_PORT, clock, target_system=1) as link, Px4Peer(link.port, heartbeat_hz=0.0) as peer:
        peer.armed, peer.custom_mode = True, px4.custom_mode_of("OFFBOARD")
        peer.heartbeat()
        link.wait_until(lambda s: s.armed, 5.0)
        peer.send(_landed(px4.LANDED_IN_AIR))
        peer.armed = False
        peer.heartbeat()  # the forgery: disarmed, while the vehicle flies and says IN_AIR
        link.wait_until(lambda s: not s.armed, 5.0)
        obs = _vehicle_obs(link.state)
        assert obs is not None and obs.armed  # on main: disarmed, the mission aborts vehicle_disarmed
        clock.advance(0.3)
        peer.heartbeat()  # a second one 0.3 s later: not yet DISARMED_AGREE_S
        _mark(peer, link, "second")
        assert _vehicle_obs(link.state).armed  # type: ignore[union-attr]
        clock.advance(0.3)
        peer.heartbeat()  # disarmed for 0.6 s, no armed HEARTBEAT between: believed
        _mark(peer, link, "third")
        assert not _vehicle_obs(link.state).armed  # type: ignore[union-attr]


def test_signed_link_each_sample_decides() -> None:
    key = bytes(range(32))
    clock = ManualClock(5.0)
    with VehicleLink(ANY_PORT, clock, signing_key=key) as link, Px4Peer(link.port, signing_key=key) as peer:
        peer.armed, peer.custom_mode = True, px4.custom_mode_of("OFFBOARD")
        link.wait_vehicle(timeout_s=5.0)
        peer.send(_landed(px4.LANDED_IN_AIR))
        link.wait_until(lambda s: s.armed and s.landed_state == px4.LANDED_IN_AIR, 5.0)
        peer.send(_landed(px4.LANDED_ON_GROUND))  # signed with the key: the vehicle's own word
        link.wait_until(lambda s: s.landed_state == px4.LANDED_ON_GROUND, 5.0)
        assert _vehicle_obs(link.state).on_ground  # type: ignore[union-attr]
