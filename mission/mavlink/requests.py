"""What the mission asks of the vehicle off its loop, so that the setpoint stream never stalls.

- :class:`CommandWorker` carries out the phases' requests (:class:`~mission.phases.phase.Request`:
  arm, OFFBOARD, Hold, Land, disarm) one at a time on a thread (the passenger's loop and the
  carrier's MAVLink backend);
- :class:`Px4Setup` asks PX4, once the mission's preflight checks passed, for the telemetry
  streams it reads (LOCAL_POSITION_NED at ``mission.telemetry_rate_hz``, EXTENDED_SYS_STATE at
  :data:`LANDED_STATE_RATE_HZ`, DISTANCE_SENSOR at :data:`RANGEFINDER_RATE_HZ` for the feed
  ``rangefinder``) and to stop those it never reads (:data:`UNUSED_STREAMS`); sets
  the failsafe parameters a recovery relies on, keeps them (:class:`~mission.mavlink.commander.ParamKeeper`)
  and puts them back at the end.
"""
from __future__ import annotations

import collections
import logging
import math
import threading
from typing import Any, Callable, Protocol

from mission.errors import CommandRejected, LinkError
from mission.flight_mode import FlightMode
from mission.mavlink.commander import KEPT_PARAMS, OFFBOARD_LOSS_RETURN, ParamKeeper
from mission.mavlink.env import mavlink
from mission.phases.phase import Request
from mission.time.clock import Clock, join_thread, start_thread

log = logging.getLogger(__name__)

LOCAL_POSITION_NED_ID = mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED
# PX4's onboard-profile streams the mission never reads (stopped with mission.unused_streams = "stop");
# ATTITUDE (100 Hz, the busiest) only gives the yaw, which the passenger's mission does not use
UNUSED_STREAMS = tuple(getattr(mavlink, f"MAVLINK_MSG_ID_{name}") for name in (
    "ATTITUDE", "ATTITUDE_QUATERNION", "GLOBAL_POSITION_INT", "HIGHRES_IMU", "ODOMETRY", "POSITION_TARGET_LOCAL_NED",
    "ATTITUDE_TARGET", "ALTITUDE", "VFR_HUD", "ESTIMATOR_STATUS"))
EXTENDED_SYS_STATE_ID = mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE
# EXTENDED_SYS_STATE (PX4's land detector) asked at this rate [Hz] (PX4 streams 5 Hz): a forced
# disarm in the air shows as ON_GROUND LNDMC_TRIG_TIME / 3 (0.33 s) after it, so at 10 Hz within
# about 0.43 s, where the 1 Hz HEARTBEAT can take a second (docs/flying-px4.md)
LANDED_STATE_RATE_HZ = 10.0
DISTANCE_SENSOR_ID = mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR
# DISTANCE_SENSOR asked at this rate [Hz] for the feed rangefinder: PX4's onboard profile streams it at 10 Hz (its
# normal profile 0.5 Hz; src/modules/mavlink/mavlink_main.cpp), and its stream sends a sample only when the sensor
# published a new one, so asked at or above the sensor's rate it delivers every reading once
# (src/modules/mavlink/streams/DISTANCE_SENSOR.hpp)
RANGEFINDER_RATE_HZ = 50.0


class Commandable(Protocol):
    """What :class:`CommandWorker` needs of a vehicle (a :class:`~mission.interfaces.Vehicle` has
    it): blocking commands that raise :class:`~mission.errors.CommandRejected` or
    :class:`~mission.errors.LinkError`."""

    def arm(self) -> None: ...

    def disarm(self) -> None: ...

    def set_mode(self, mode: str) -> None: ...

    def hold(self) -> None: ...

    def land(self) -> None: ...


#: How each request the phases make is carried out on the vehicle (blocking until confirmed).
COMMANDS: dict[Request, Callable[[Commandable], None]] = {
    Request.ARM: lambda vehicle: vehicle.arm(),
    Request.OFFBOARD: lambda vehicle: vehicle.set_mode(FlightMode.OFFBOARD),
    Request.HOLD: lambda vehicle: vehicle.hold(),
    Request.LAND: lambda vehicle: vehicle.land(),
    Request.DISARM: lambda vehicle: vehicle.disarm(),
}


class CommandWorker:
    """Runs vehicle commands (:class:`Request`) one at a time off the loop.

    A request is retried up to ``retries`` times (each try is the vehicle's own ACK/retry cycle);
    then ``failed[request]`` holds the vehicle's reason and the phases decide. Hold and Land may
    be asked again after ``repeat_s`` if the vehicle still does not show the mode. With
    ``threaded=False`` a request runs inside :meth:`submit` (deterministic unit tests on a
    manual clock); the flight always uses the thread, so commands never stall the setpoints.
    """

    def __init__(self, vehicle: Commandable, clock: Clock, retries: int = 3, repeat_s: float = 2.0,
                 threaded: bool = True) -> None:
        self.link, self.clock, self.retries, self.repeat_s = vehicle, clock, retries, repeat_s
        self.failed: dict[str, str] = {}
        self._requests: collections.deque[Request | None] = collections.deque()
        self._cond = threading.Condition()
        self._busy = threading.Event()
        self._last: dict[Request, float] = {}
        self._thread: threading.Thread | None = None
        if threaded:
            self._thread = threading.Thread(target=self._run, name="mission-commands", daemon=True)
            self._thread.start()

    def submit(self, request: str) -> None:
        req = Request(request)
        if self._busy.is_set() or req in self.failed:
            return
        last = self._last.get(req)
        if last is not None and self.clock.now() - last < self.repeat_s:
            return
        self._last[req] = self.clock.now()
        self._busy.set()
        if self._thread is None:
            self._handle(req)
        else:
            self._put(req)

    def _put(self, request: Request | None) -> None:
        with self._cond:
            self._requests.append(request)
            self.clock.notify(self._cond)

    def _next(self) -> Request | None:
        """The next request; waits on the clock (so a lockstep clock runs this thread in turn)."""
        with self._cond:
            while not self._requests:
                self.clock.wait(self._cond, math.inf)
            return self._requests.popleft()

    def _run(self) -> None:
        while True:
            request = self._next()
            if request is None:
                return
            self._handle(request)

    def _handle(self, request: Request) -> None:
        reason = ""
        for attempt in range(1, self.retries + 1):
            try:
                COMMANDS[request](self.link)
                log.info("vehicle accepted %s", request)
                reason = ""
                break
            except CommandRejected as exc:
                reason = exc.reason or f"MAV_RESULT {exc.result}"
            except LinkError as exc:
                reason = str(exc)
            log.warning("%s refused (try %d/%d): %s", request, attempt, self.retries, reason)
            self.clock.sleep(0.5)
        if reason and request in (Request.ARM, Request.OFFBOARD):
            self.failed[request.value] = reason
        self._last[request] = self.clock.now()
        self._busy.clear()

    def close(self) -> None:
        if self._thread is not None:
            self._put(None)
            join_thread(self.clock, self._thread, 5.0)


class Configurable(Protocol):
    """What :class:`Px4Setup` needs of a vehicle (a :class:`~mission.interfaces.Vehicle` has it)."""

    def set_message_interval(self, message_id: int, rate_hz: float) -> None: ...

    def get_param(self, name: str) -> float: ...

    def set_param(self, name: str, value: float) -> float: ...


RTL_PRECLAND_OPPORTUNISTIC = 1  # RTL_PLD_MD: precision landing if the target is seen, else a normal one


class Px4Setup:
    """PX4's streams and failsafe parameters for one mission, each asked once, off the loop.

    ``telemetry_rate_hz`` [Hz]: LOCAL_POSITION_NED's rate to ask for (None: as it streams);
    ``rangefinder``: ask for DISTANCE_SENSOR at :data:`RANGEFINDER_RATE_HZ` (the feed ``rangefinder``);
    ``stop_unused``: stop :data:`UNUSED_STREAMS`; ``recovery``: the mission comes home
    (``final_action = "return"``), with ``battery_reserve_pct`` [%] its recall and
    ``offboard_loss_return``: set PX4's offboard-loss action to Return, and with ``precland``
    (the mission streams the deck as LANDING_TARGET) RTL's precision landing to opportunistic
    (RTL_PLD_MD 1, docs/px4-precland.md) if it is off; ``keeper``: keeps
    :data:`~mission.mavlink.commander.KEPT_PARAMS` as found. ``params``: what was read, set and
    restored (for the summary). docs/recovery.md, "PX4's home".
    """

    def __init__(self, vehicle: Configurable, clock: Clock, *, telemetry_rate_hz: float | None, stop_unused: bool,
                 recovery: bool, battery_reserve_pct: float, offboard_loss_return: bool,
                 keeper: ParamKeeper | None = None, params: dict[str, Any] | None = None, precland: bool = False,
                 rangefinder: bool = False) -> None:
        self.vehicle, self.clock, self.precland, self.rangefinder = vehicle, clock, precland, rangefinder
        self.telemetry_rate_hz, self.stop_unused = telemetry_rate_hz, stop_unused
        self.recovery, self.battery_reserve_pct, self.offboard_loss_return = recovery, battery_reserve_pct, offboard_loss_return
        self.keeper = keeper
        self.params: dict[str, Any] = {} if params is None else params
        self._started = False

    def start(self) -> None:
        """Once the preflight checks passed (a refused start sends the vehicle nothing): ask for
        the streams and set the parameters, on threads; later calls do nothing."""
        if self._started:
            return
        self._started = True
        start_thread(self.clock, self._ask_streams, "mission-telemetry-rate")
        start_thread(self.clock, self._configure, "mission-px4-params")

    def _ask_streams(self) -> None:
        """LOCAL_POSITION_NED at ``telemetry_rate_hz`` (PX4 streams 30 Hz to a 50 Hz loop by
        default): a refusal is logged and the mission flies at the rate that comes (the summary's
        ``position_rate_hz`` says which). Then EXTENDED_SYS_STATE at :data:`LANDED_STATE_RATE_HZ`,
        DISTANCE_SENSOR at :data:`RANGEFINDER_RATE_HZ` with ``rangefinder``,
        and with ``stop_unused`` the streams the mission never reads stopped."""
        rate, link = self.telemetry_rate_hz, self.vehicle
        try:
            if rate is not None:
                link.set_message_interval(LOCAL_POSITION_NED_ID, rate)
                log.info("asked the vehicle for LOCAL_POSITION_NED at %g Hz", rate)
        except (CommandRejected, LinkError) as exc:
            log.warning("vehicle did not take LOCAL_POSITION_NED at %g Hz (%s); flying at the rate it streams", rate, exc)
        try:
            link.set_message_interval(EXTENDED_SYS_STATE_ID, LANDED_STATE_RATE_HZ)
        except (CommandRejected, LinkError) as exc:
            log.warning("vehicle did not take EXTENDED_SYS_STATE at %g Hz (%s): a disarm in the air may take up "
                        "to its HEARTBEAT period to notice", LANDED_STATE_RATE_HZ, exc)
        if self.rangefinder:
            try:
                link.set_message_interval(DISTANCE_SENSOR_ID, RANGEFINDER_RATE_HZ)
                log.info("asked the vehicle for DISTANCE_SENSOR at %g Hz (the rangefinder feed)", RANGEFINDER_RATE_HZ)
            except (CommandRejected, LinkError) as exc:
                log.warning("vehicle did not take DISTANCE_SENSOR at %g Hz (%s): the rangefinder feed reads what it "
                            "streams", RANGEFINDER_RATE_HZ, exc)
        if self.stop_unused:
            stopped = 0
            for msg_id in UNUSED_STREAMS:
                try:
                    link.set_message_interval(msg_id, 0.0)
                    stopped += 1
                except (CommandRejected, LinkError) as exc:  # it streams what it streams
                    log.debug("vehicle did not stop message %d: %s", msg_id, exc)
            log.info("asked the vehicle to stop %d of %d streams the mission does not read", stopped,
                     len(UNUSED_STREAMS))

    def _configure(self) -> None:
        """For a recovery: PX4's offboard-loss action to Return (so that a controller that dies
        leaves the passenger flying to the home kept at the carrier), and a warning if PX4's own
        battery failsafe (BAT_CRIT_THR) would act before our recall. For every mission: the
        failsafe parameters of :data:`KEPT_PARAMS`, as set or found, are kept."""
        link, params = self.vehicle, self.params
        try:
            if self.recovery:
                critical = link.get_param("BAT_CRIT_THR")
                params["BAT_CRIT_THR"] = critical
                if self.battery_reserve_pct <= 100.0 * critical:
                    log.warning("recovery.battery_reserve_pct %g %% is at or below PX4's BAT_CRIT_THR (%g %%): PX4's "
                                "own low-battery failsafe may act before the recall", self.battery_reserve_pct,
                                100.0 * critical)
            if self.recovery and self.offboard_loss_return:
                was = link.get_param("COM_OBL_RC_ACT")
                params["COM_OBL_RC_ACT"] = {"was": was, "set": was}
                if was != OFFBOARD_LOSS_RETURN:
                    params["COM_OBL_RC_ACT"]["set"] = link.set_param("COM_OBL_RC_ACT", OFFBOARD_LOSS_RETURN)
                    log.info("PX4's offboard-loss action COM_OBL_RC_ACT set to Return (was %g) for the recovery", was)
            if self.recovery and self.offboard_loss_return and self.precland:
                was = link.get_param("RTL_PLD_MD")
                params["RTL_PLD_MD"] = {"was": was, "set": was}
                if was == 0:
                    params["RTL_PLD_MD"]["set"] = link.set_param("RTL_PLD_MD", RTL_PRECLAND_OPPORTUNISTIC)
                    log.info("PX4's RTL_PLD_MD set to opportunistic: its Return lands on the deck streamed as LANDING_TARGET")
        except LinkError as exc:
            log.warning("PX4's parameters for the recovery not read or set: %s", exc)
        if self.keeper is None:
            return
        for name in KEPT_PARAMS:
            try:
                self.keeper.keep(name, link.get_param(name))
            except LinkError as exc:
                log.warning("PX4's %s not read: it is not kept (%s)", name, exc)

    def restore(self) -> None:
        """Put back the parameters :meth:`start` changed (the offboard-loss action, RTL's precision landing)."""
        for name in ("COM_OBL_RC_ACT", "RTL_PLD_MD"):
            entry = self.params.get(name)
            if entry is None or entry["set"] == entry["was"]:
                continue
            try:
                entry["restored"] = self.vehicle.set_param(name, entry["was"])
            except LinkError as exc:
                log.warning("PX4's %s left at %g: %s", name, entry["set"], exc)
