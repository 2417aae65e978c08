"""The mock vehicle's side of lockstep simulated time (:mod:`mission.bus.lockstep` is the protocol).

The vehicle owns simulated time. At each barrier ``t`` it sends ``TIMESYNC(0, t)`` and waits for
the controller's answer (``tc1`` = the controller's next wake) before it integrates, step by
step, up to that wake, with the streams, faults and commands of every step. Each step's packets
go out as one datagram per link, ``SYSTEM_TIME`` first and the barrier last (a step is one
instant of simulated time). The clock messages bypass the link faults and the counters.

Before any controller answered, the vehicle says hello (HEARTBEAT + barrier, no faults) at
once and then every :data:`HELLO_WALL_S`; the streams of that first step (t = 0) go to no one
(their schedule moves on as if sent), so a controller bound before the vehicle's first datagram
and one bound after it start from the same first samples (a race on the wall clock otherwise:
with the estimate's errors the first position differs). Later, a barrier still unanswered after
:data:`RESEND_WALL_S` is sent again (UDP may lose it or its answer; the controller answers a
barrier it has done again with the same answer). A controller that leaves (``wake < 0``)
or stays silent for the watchdog (its "still working on the step", ``TIMESYNC(t, t)`` while it
waits for a slow carrier, is not silence) ends the lockstep: the vehicle goes on in real time (a killed controller is offboard loss, as
in PX4).
"""
from __future__ import annotations

import logging
import math
import time
from typing import TYPE_CHECKING, Any

from mission.mavlink.env import mavlink
from mission.time.clock import Silence
from sim.vehicle import telemetry as tel
from sim.vehicle.endpoints import VehicleLink

if TYPE_CHECKING:
    from sim.vehicle.mock import MockVehicle

log = logging.getLogger("sim.vehicle.mock")

HELLO_WALL_S = 0.05  # resend period of the first barrier until a controller answers [s, wall]
RESEND_WALL_S = 0.5  # resend period of a later barrier still unanswered (it or its answer lost) [s, wall]
POLL_WALL_S = 0.02  # longest socket wait while waiting for an answer [s, wall]; bounds the reaction to stop()


def is_timesync(data: bytes) -> bool:
    """Is this datagram a MAVLink 1 or 2 TIMESYNC (id 111)? (Read from the header, before the
    link faults decide its fate.)"""
    if len(data) >= 10 and data[0] == 0xFD:
        return data[7] | data[8] << 8 | data[9] << 16 == mavlink.MAVLINK_MSG_ID_TIMESYNC
    return len(data) >= 6 and data[0] == 0xFE and data[5] == mavlink.MAVLINK_MSG_ID_TIMESYNC


class LockstepStepper:
    """Runs a :class:`~sim.vehicle.mock.MockVehicle`'s loop in lockstep with the controller on its
    onboard link, advancing the vehicle's clock (a :class:`~mission.time.clock.ManualClock`)."""

    def __init__(self, vehicle: MockVehicle, watchdog_wall_s: float, step_s: float,
                 max_speed: float | None = None) -> None:
        self.v = vehicle
        self.max_speed = max_speed  # at most this many simulated seconds per wall second (None: no limit)
        self._step_ns = round(step_s * 1e9)  # the vehicle's physics step [ns]
        self.watchdog_wall_s = watchdog_wall_s
        self.batching = False  # a step's packets go out as one datagram per link
        self._barrier_ns = -1  # the step the vehicle waits at
        self._answer: int | None = None  # the controller's answer (its next wake [ns])
        self._working = 0  # the controller's "still working on this step" messages, counted
        self._marked_steps = -1  # last step announced by SYSTEM_TIME

    def run(self) -> None:
        """Step until the controller leaves or goes silent, or the vehicle stops (then the
        caller goes on in real time)."""
        self.batching = True
        try:
            self._step_until_left()
        finally:
            with self.v._lock:
                self.v._io.flush()
                self.batching = False

    def _step_until_left(self) -> None:
        v = self.v
        onboard, joined = v._links[0], False
        start: tuple[int, float] | None = None  # (t [ns], wall [s]) when the controller first answered
        while not v._stop_event.is_set():
            if start is not None and self.max_speed is not None:  # hold the barrier until the wall clock catches up
                ahead_s = (self.t_ns - start[0]) / 1e9 / self.max_speed - (time.monotonic() - start[1])
                if ahead_s > 0 and v._stop_event.wait(ahead_s):
                    return
            with v._lock:
                if joined:
                    v._service_step()
                else:  # nobody listens for sure before the first answer: step 0's streams go to no one
                    v._schedule.skip(v._links, v._t_s)
                self._barrier_ns, self._answer = self.t_ns, None
                if not joined:
                    self._hello(onboard)
                self.send_control(onboard, mavlink.MAVLink_timesync_message(0, self.t_ns))
                v._io.flush()
            answer = self._wait_answer(onboard, joined)
            if answer is None:
                return
            if answer < 0:
                log.info("lockstep: the controller left at t = %.3f s; going on in real time at speed %g",
                         v._t_s, v.options.speed)
                return
            joined = True
            start = start or (self.t_ns, time.monotonic())
            target = max(v._steps + 1, math.ceil(answer / self._step_ns - 1e-6))
            with v._lock:
                while v._steps < target - 1:
                    v._advance_steps(v._steps + 1)
                    v._service_step()
                    v._io.flush()
                v._advance_steps(target)

    def _wait_answer(self, onboard: VehicleLink, joined: bool) -> int | None:
        """The controller's answer to the barrier; None on stop() or when it went silent."""
        v = self.v
        called = time.monotonic()
        silence = Silence()  # the controller's, without the vehicle's own stalls (a stopped process)
        working = self._working
        while not v._stop_event.is_set():
            v._io.poll(POLL_WALL_S)
            if self._answer is not None:
                return self._answer
            if self._working != working:  # slow, not gone: it waits for its own carrier
                working = self._working
                silence.restart()
            now = time.monotonic()
            if not joined and now - called > HELLO_WALL_S:  # nobody answered yet: hello again
                with v._lock:  # (time has not started: no link faults yet, or latency would hold it forever)
                    self._hello(onboard)
                    self.send_control(onboard, mavlink.MAVLink_timesync_message(0, self.t_ns))
                    v._io.flush()
                called = now
            elif joined and silence.elapsed() > self.watchdog_wall_s:
                log.warning("lockstep: no answer for step t = %.3f s within %.1f s (wall); the controller is "
                            "gone, going on in real time at speed %g", v._t_s, self.watchdog_wall_s, v.options.speed)
                return None
            elif joined and now - called > RESEND_WALL_S:  # UDP: the barrier or its answer may be lost
                with v._lock:
                    self.send_control(onboard, mavlink.MAVLink_timesync_message(0, self._barrier_ns))
                    v._io.flush()
                called = now
        return None

    def _hello(self, onboard: VehicleLink) -> None:
        """A HEARTBEAT outside the streams and the faults on every link, so a controller that has
        not answered yet can adopt the vehicle and a ground station sees it from power-on, as PX4
        heartbeats before any offboard controller (the ground station's copy moves no clock)."""
        v = self.v
        heartbeat = tel.build("HEARTBEAT", v._telemetry_state(), v._geo, v._noise)
        self.send_control(onboard, heartbeat)
        for link in v._links:
            if link is not onboard:
                self.send_control(link, heartbeat)

    @property
    def barrier_ns(self) -> int:
        """The barrier the vehicle waits at, or last integrated past once answered [ns] (-1: none yet)."""
        return self._barrier_ns

    @property
    def t_ns(self) -> int:
        """The vehicle's time [ns] (its step count times the step, exactly)."""
        return self.v._steps * self._step_ns

    def on_answer(self, link: VehicleLink, msg: Any) -> None:
        """A TIMESYNC with ``tc1 != 0``: the controller's answer if it is for this barrier; with
        ``tc1 == ts1`` (a wake that is not after the step) it still works on it; ``tc1 < 0``: it
        left, at this step or an earlier one (it fell back to its wall clock while this barrier
        was lost on the way)."""
        if link is not self.v._links[0]:
            return
        if msg.tc1 < 0 and 0 <= msg.ts1 <= self._barrier_ns:  # it left, at this step or an earlier one
            self._answer = -1
        elif msg.ts1 == self._barrier_ns:
            if msg.tc1 == msg.ts1:
                self._working += 1
            else:
                self._answer = int(msg.tc1)  # the controller finished this step

    def clock_message(self, link: VehicleLink, data: bytes, address: tuple[str, int]) -> None:
        """A TIMESYNC datagram: the simulation's own clock, so no link faults and no counters."""
        messages, _ = link.parse(data)
        for msg in messages:
            if msg.get_type() == "TIMESYNC":
                link.latch(address)
                self.v._handlers.timesync(link, msg)

    def send_control(self, link: VehicleLink, msg: Any) -> None:
        """Send a clock message: never through the link faults, never counted."""
        if link.target is not None and self.batching:
            link.queue(link.pack(msg), counted=False)
        elif link.target is not None:
            link.sendto(link.pack(msg), link.target)

    def mark_time(self, link: VehicleLink) -> None:
        """Precede the first packet of a step on the onboard link with SYSTEM_TIME, so the
        controller stamps what follows with this step's time."""
        v = self.v
        if link is v._links[0] and self._marked_steps != v._steps:
            self._marked_steps = v._steps
            self.send_control(link, mavlink.MAVLink_system_time_message(0, self.t_ns // 1_000_000))
