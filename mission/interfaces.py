"""What the mission loop needs from the world, as narrow interfaces.

:class:`mission.controller.MissionController` talks to three things and knows each only by the
Protocol below, so a MAVLink link to PX4, the mock vehicle or a test's in-process fake are
interchangeable (as are a Zenoh feed and a scripted one):

* a :class:`Vehicle`: its newest telemetry snapshot, one setpoint at a time
  (:class:`mission.core.setpoint.Setpoint`), the position stream's rate (asked and seen), four commands
  (arm, set mode, hold, land), PX4's home and its parameters, each blocking until the vehicle
  confirmed it or raising :class:`mission.errors.CommandRejected` / :class:`mission.errors.LinkError`;
* a :class:`CarrierSource`: the newest carrier state with its receive time and age, the
  carrier's liveliness, and the EKF origin for geodetic carrier states;
* a :class:`StatusSink`: where the passenger's phase and state go (the carrier listens);
* any number of :class:`MeasurementSource`: the measurement feeds (a camera that sees the deck's
  marker, a relative estimator's sensors), each polled once a tick, their readings handed to the
  passenger's step as they are.

Implementations: :class:`mission.mavlink.link.VehicleLink`, :class:`mission.bus.bridge.CarrierFeed`,
:class:`mission.bus.bridge.PassengerPublisher`; ``tests/support/fake_vehicle.py`` fakes all
three without sockets.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:
    from collections.abc import Sequence

    from mission.phases.measurements import Measurement
    from mission.core.setpoint import Setpoint
    from mission.bus.bridge import ReceivedCarrierState
    from mission.passenger.target import LandingTarget
    from mission.mavlink.session import LinkCounters
    from mission.mavlink.link import VehicleState
    from mission.bus.wire import GeoOrigin, PassengerStatus
    from mission.vision.camera import SeenFrame


class Vehicle(Protocol):
    """The passenger UAV as the mission loop sees it."""

    @property
    def state(self) -> VehicleState:
        """Newest telemetry snapshot (never blocks)."""
        ...

    def send(self, setpoint: Setpoint) -> None:
        """Send one setpoint as it is (velocity only or full, yaw or not: the setpoint says which).
        ValueError for a non-finite one, before anything is sent."""
        ...

    def send_landing_target(self, target: LandingTarget) -> None:
        """Send the deck's landing point for the vehicle's own precision landing (PX4's
        LANDING_TARGET; docs/px4-precland.md). ValueError for an unsendable one."""
        ...

    def set_message_interval(self, message_id: int, rate_hz: float) -> None:
        """Ask the vehicle to stream ``message_id`` at ``rate_hz`` [Hz] (may raise CommandRejected)."""
        ...

    def message_rate_hz(self) -> float:
        """Rate [Hz] at which LOCAL_POSITION_NED arrived over the last second."""
        ...

    def arm(self) -> None: ...

    def set_mode(self, mode: str) -> None:
        """Switch to PX4 mode ``mode`` (a name of :data:`mission.mavlink.px4.MODES`)."""
        ...

    def hold(self) -> None: ...

    def disarm(self) -> None:
        """Disarm (not forced: PX4 refuses unless it has landed)."""
        ...

    def land(self) -> None: ...

    def set_home(self, home_ned_m: Any) -> int:
        """Move PX4's home to ``home_ned_m`` [m] NED (one attempt; LinkError without an EKF origin)."""
        ...

    def get_param(self, name: str) -> float:
        """The vehicle's parameter ``name`` (LinkTimeout if it has none)."""
        ...

    def set_param(self, name: str, value: float) -> float:
        """Set the vehicle's parameter ``name``; returns the value it kept."""
        ...

    def signing_problem(self) -> str | None:
        """Why no vehicle is identified although a PX4 was heard (it signs with another key), or None."""
        ...

    def identity_problem(self) -> str | None:
        """Why the identified vehicle is ambiguous (a second PX4 autopilot heard with
        ``mavlink.target_system`` unset), or None."""
        ...

    @property
    def counters(self) -> LinkCounters:
        """What the link received, sent and refused (for the summary)."""
        ...


class CarrierSource(Protocol):
    """The carrier's state as received (newest only, with its age on the mission clock)."""

    def latest(self) -> ReceivedCarrierState | None: ...

    @property
    def alive(self) -> bool | None:
        """Carrier liveliness (True, False, or None when not known yet)."""
        ...

    def alive_over_interval(self) -> bool | None:
        """Liveliness since the previous call: False if it went at any moment in between."""
        ...

    def set_origin(self, origin: GeoOrigin | None) -> None:
        """The vehicle's EKF origin, so geodetic carrier states map to local NED."""
        ...

    @property
    def counters(self) -> dict[str, Any]:
        """Samples received, accepted and dropped per reason (for the summary)."""
        ...


class StatusSink(Protocol):
    """Where the passenger's status goes each tick."""

    def publish(self, status: PassengerStatus) -> None: ...


class MeasurementSource(Protocol):
    """A measurement feed: what a sensor measured, for the passenger's step. In flight an I/O-side
    module opened by ``marsupial run`` for a name of ``mission.feeds`` (entry-point group
    ``marsupial.feeds``); in the in-process simulation the world's sensor of the same name
    (``marsupial.sensors``, :mod:`sim.batch.sensors`)."""

    def poll(self, t_s: float) -> Sequence[Measurement]:
        """The readings that arrived since the last poll, as of ``t_s`` [s] on the mission clock,
        each stamped at capture on that clock (:class:`mission.phases.measurements.Measurement`);
        empty when none. Never blocks; a reading is returned once."""
        ...

    def close(self) -> None:
        """Release what the feed holds (subscriptions, devices); the loop polls it no more."""
        ...


@runtime_checkable
class CameraSink(Protocol):
    """Where a camera's frames go as a feed saw them (the flight log, :mod:`mission.flightdata`)."""

    def camera(self, t_s: float, seen: SeenFrame) -> None:
        """Take a frame that reached the mission at ``t_s`` [s, mission clock]; returns at once."""
        ...


@runtime_checkable
class CountsReadings(Protocol):
    """A measurement feed that keeps counters of what it read, refused and used, for
    ``summary.json``'s ``feeds`` (the marker feed: frames received, refused, detected)."""

    @property
    def counters(self) -> dict[str, Any]:
        """The counters so far (a copy: the caller may keep it)."""
        ...


@runtime_checkable
class ShowsFrames(Protocol):
    """A measurement feed whose frames can be shown to :class:`CameraSink` s (the marker feed)."""

    def show_frames_to(self, sink: CameraSink) -> None:
        """Hand every frame the feed reads, as it saw it, to ``sink`` too (its rate is the feed's own)."""
        ...
