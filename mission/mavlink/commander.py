"""Blocking vehicle commands and parameters over a link: the executor of
:mod:`mission.mavlink.commands`, and :class:`ParamClient` (PARAM_REQUEST_READ and PARAM_SET, each
answered by the PARAM_VALUE PX4 sends back, integers bit-packed as :mod:`mission.mavlink.px4` says).

One command at a time (thread-safe). Each call sends through the link, waits on the session's
clock for what the state machines need, and turns their verdicts into our errors:
:class:`~mission.errors.CommandRejected` (with the vehicle's STATUSTEXT reason),
:class:`~mission.errors.LinkTimeout`, :class:`~mission.errors.LinkError`.
"""
from __future__ import annotations

import contextlib
import logging
import math
import threading
from collections.abc import Iterator
from typing import Any, Callable

from mission.core import geodesy
from mission.flight_mode import FlightMode
from mission.mavlink import px4
from mission.errors import CommandRejected, LinkError, LinkTimeout
from mission.mavlink.commands import CommandExchange, Confirmed, HeartbeatConfirmation, Step, refusal_reason
from mission.mavlink.session import LinkSession, ParamValue
from mission.mavlink.telemetry import VehicleState
from mission.mavlink.env import mavlink

log = logging.getLogger("mission.mavlink.link")


class CommandClient:
    """COMMAND_LONG with ACK, retry and HEARTBEAT confirmation on ``session``.

    ``send(msg, counter)`` sends a message (False: no peer yet); ``require_vehicle()`` returns
    the identified (system, component) or raises; ``reason_grace_s``: after a refusal, how long
    to wait for the vehicle's STATUSTEXT reason if it has not come yet [s].
    """

    def __init__(self, session: LinkSession, send: Callable[[Any, str], bool],
                 require_vehicle: Callable[[], tuple[int, int]], reason_grace_s: float) -> None:
        self.session, self.send, self.require_vehicle = session, send, require_vehicle
        self.reason_grace_s = reason_grace_s
        # One command at a time. Waiting for our turn goes through the clock, as every wait does: a
        # thread blocked on a plain lock held by another thread parked on a lockstep clock would
        # hold the whole simulation (the holder only runs at the next barrier, which waits for it).
        self._turn = threading.Condition()
        self._busy = False

    @contextlib.contextmanager
    def _one_at_a_time(self) -> Iterator[None]:
        clock = self.session.clock
        with self._turn:
            while self._busy:
                clock.wait(self._turn, math.inf)
            self._busy = True
        try:
            yield
        finally:
            with self._turn:
                self._busy = False
                clock.notify(self._turn)

    def command_long(self, command: int, *params: float, timeout_s: float = 0.5, retries: int = 3) -> int:
        """Send COMMAND_LONG and wait for its final COMMAND_ACK (:class:`CommandExchange`).

        ``params`` are param1..param7 (missing ones are 0). Each attempt waits ``timeout_s``
        [s of clock]; up to ``retries`` resends follow (``confirmation`` counts them); IN_PROGRESS
        extends the wait. Returns MAV_RESULT_ACCEPTED (0); raises CommandRejected for any other
        result, LinkTimeout when no ACK came, LinkError if the link is not ready.
        """
        if len(params) > 7:
            raise ValueError(f"COMMAND_LONG has 7 params, got {len(params)}")
        padded = [float(p) for p in params] + [0.0] * (7 - len(params))
        return self._exchange(command, lambda target, confirmation: mavlink.MAVLink_command_long_message(
            target[0], target[1], int(command), confirmation, *padded), timeout_s, retries)

    def command_int(self, command: int, frame: int, params: tuple[float, float, float, float], x: int, y: int,
                    z: float, timeout_s: float = 0.5, retries: int = 3) -> int:
        """Send COMMAND_INT (``x``, ``y``: latitude and longitude in degrees x 1e7 in a global
        ``frame``, exact where COMMAND_LONG's float32 params lose decimetres) and wait for its ACK,
        as :meth:`command_long` does."""
        return self._exchange(command, lambda target, confirmation: mavlink.MAVLink_command_int_message(
            target[0], target[1], int(frame), int(command), 0, 0, *(float(p) for p in params), int(x), int(y), float(z)),
            timeout_s, retries)

    def _exchange(self, command: int, message: Callable[[tuple[int, int], int], Any], timeout_s: float,
                  retries: int) -> int:
        """One command's ACK cycle; ``message(target, confirmation)`` builds each attempt."""
        if retries < 0 or not timeout_s > 0:
            raise ValueError("retries must be >= 0 and timeout_s > 0")
        target = self.require_vehicle()
        s = self.session
        with self._one_at_a_time():
            t_start = s.clock.now()
            with s.lock:
                exchange = CommandExchange(int(command), timeout_s, retries, s.acks.seq)
            while True:
                with s.changed:
                    step = exchange.step(s.clock.now(), s.acks)
                    if step is Step.WAIT:
                        s.wait_locked(exchange.deadline_s)
                        continue
                if step is not Step.SEND:
                    break
                if exchange.sent > 1:
                    s.count("command_retries")
                    log.debug("no ACK for command %d (attempt %d of %d)", command, exchange.sent - 1, retries + 1)
                self.send(message(target, exchange.confirmation), "tx_commands")
            ack = exchange.final
            if ack is None:
                s.count("command_timeouts")
                raise LinkTimeout(f"no COMMAND_ACK for command {command} after {retries + 1} attempts of {timeout_s:g} s")
            if ack.result == mavlink.MAV_RESULT_ACCEPTED:
                return ack.result
            s.count("command_rejections")
            reason = self.reason_since(t_start)
            log.warning("command %d rejected with MAV_RESULT %d: %s", command, ack.result, reason or "(no reason)")
            raise CommandRejected(int(command), ack.result, reason)

    def set_home(self, home_ned_m: Any, origin: tuple[float, float, float] | None, timeout_s: float = 0.5,
                 retries: int = 0) -> int:
        """MAV_CMD_DO_SET_HOME at ``home_ned_m`` [m] NED: latitude and longitude through the EKF
        ``origin`` (PX4's projection), altitude AMSL (param1 = 0: not here), as COMMAND_INT in
        MAV_FRAME_GLOBAL (degrees x 1e7: about a centimetre). Without an ``origin`` it is asked for
        first (REQUEST_MESSAGE). One attempt by default: the caller sends a newer home soon. Raises
        like :meth:`command_long`."""
        north, east, down = (float(c) for c in home_ned_m)
        if not all(math.isfinite(c) for c in (north, east, down)):
            raise ValueError(f"home must be finite, got {(north, east, down)}")
        if origin is None:  # PX4 sends GPS_GLOBAL_ORIGIN when its origin is set, not periodically: ask
            self.command_long(mavlink.MAV_CMD_REQUEST_MESSAGE, float(mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN),
                              timeout_s=timeout_s, retries=retries)
            origin = self.session.wait_until(lambda s: s.origin is not None, timeout_s, "GPS_GLOBAL_ORIGIN").origin
            assert origin is not None
        lat_deg, lon_deg = geodesy.reproject(north, east, origin[0], origin[1])
        alt_m = origin[2] - down
        return self.command_int(mavlink.MAV_CMD_DO_SET_HOME, mavlink.MAV_FRAME_GLOBAL, (0.0, 0.0, 0.0, math.nan),
                                round(lat_deg * 1e7), round(lon_deg * 1e7), alt_m, timeout_s=timeout_s, retries=retries)

    def arm(self, timeout_s: float = 0.5, retries: int = 3, confirm_timeout_s: float = 2.5) -> None:
        """Arm (MAV_CMD_COMPONENT_ARM_DISARM 1) and confirm it by HEARTBEAT."""
        self.confirmed("arm", lambda s: s.armed, confirm_timeout_s, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1.0,
                       timeout_s=timeout_s, retries=retries)

    def disarm(self, force: bool = False, timeout_s: float = 0.5, retries: int = 3,
               confirm_timeout_s: float = 2.5) -> None:
        """Disarm and confirm by HEARTBEAT; ``force`` adds 21196 (disarms even in the air)."""
        self.confirmed("disarm", lambda s: not s.armed, confirm_timeout_s, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0.0,
                       float(px4.ARM_FORCE_MAGIC) if force else 0.0, timeout_s=timeout_s, retries=retries)

    def set_mode(self, mode: str, timeout_s: float = 0.5, retries: int = 3, confirm_timeout_s: float = 2.5) -> None:
        """Switch the PX4 mode (name as in :data:`mission.mavlink.px4.MODES`) and confirm it by HEARTBEAT.

        Sends MAV_CMD_DO_SET_MODE(CUSTOM_MODE_ENABLED, main, sub). A first ACCEPTED ACK is not
        trusted: a later non-ACCEPTED ACK of the same command (PX4's double ACK) raises
        CommandRejected, and only a HEARTBEAT received after the command and showing the mode
        confirms it (LinkTimeout after ``confirm_timeout_s`` [s]).
        """
        if mode not in px4.MODES:
            raise ValueError(f"unknown PX4 mode {mode!r}; known: {sorted(px4.MODES)}")
        main, sub = px4.MODES[FlightMode(mode)]
        self.confirmed(f"mode {mode}", lambda s: s.mode == mode, confirm_timeout_s, mavlink.MAV_CMD_DO_SET_MODE,
                       float(mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(main), float(sub),
                       timeout_s=timeout_s, retries=retries)

    def set_message_interval(self, message_id: int, rate_hz: float, timeout_s: float = 0.5, retries: int = 2) -> None:
        """Ask the vehicle to stream ``message_id`` at ``rate_hz`` [Hz], 0: not at all (interval -1)
        (MAV_CMD_SET_MESSAGE_INTERVAL); raises CommandRejected or LinkTimeout like :meth:`command_long`."""
        if not rate_hz >= 0:
            raise ValueError(f"rate_hz must be >= 0, got {rate_hz!r}")
        self.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, float(message_id), 1e6 / rate_hz if rate_hz > 0 else -1.0,
                          timeout_s=timeout_s, retries=retries)

    def takeoff(self, alt_m: float | None, origin: tuple[float, float, float] | None, timeout_s: float = 0.5,
                retries: int = 3) -> int:
        """MAV_CMD_NAV_TAKEOFF to ``alt_m`` [m] above the EKF ``origin`` (None: the vehicle's default).

        PX4 reads param7 as altitude AMSL, so the origin altitude from GPS_GLOBAL_ORIGIN is added;
        without a known origin a numeric ``alt_m`` raises LinkError. Acknowledged only (the
        vehicle must already be armed; PX4 shows AUTO.TAKEOFF next).
        """
        nan = math.nan
        if alt_m is None:
            param7 = nan
        else:
            if not math.isfinite(alt_m):
                raise ValueError(f"takeoff altitude must be finite, got {alt_m!r}")
            if origin is None:
                raise LinkError("takeoff altitude needs the EKF origin (no GPS_GLOBAL_ORIGIN received)")
            param7 = origin[2] + float(alt_m)
        return self.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, 0.0, 0.0, 0.0, nan, nan, nan, param7,
                                 timeout_s=timeout_s, retries=retries)

    def confirmed(self, what: str, confirmed: Callable[[VehicleState], bool], confirm_timeout_s: float,
                  command: int, *params: float, timeout_s: float, retries: int) -> None:
        """Send a command, then wait for a HEARTBEAT after it that satisfies ``confirmed``
        (:class:`HeartbeatConfirmation`). A later non-ACCEPTED ACK of the same command raises
        CommandRejected; a lost ACK is forgiven if the HEARTBEAT confirms."""
        s = self.session
        t_sent = s.clock.now()
        with s.lock:
            confirmation = HeartbeatConfirmation(command, t_sent, s.acks.seq, confirmed, confirm_timeout_s)
        ack_lost: LinkTimeout | None = None
        try:
            self.command_long(command, *params, timeout_s=timeout_s, retries=retries)
        except LinkTimeout as exc:
            ack_lost = exc
        confirmation.start(s.clock.now())
        with s.changed:
            while True:
                verdict = confirmation.step(s.clock.now(), s.acks, s.snapshot_locked())
                if verdict is Confirmed.CONFIRMED:
                    log.info("%s confirmed by HEARTBEAT", what)
                    return
                if verdict is Confirmed.REJECTED:
                    break
                if verdict is Confirmed.TIMED_OUT or not s.wait_locked(confirmation.deadline_s):
                    if ack_lost is not None:
                        raise ack_lost
                    raise LinkTimeout(f"{what}: ACCEPTED but not confirmed by HEARTBEAT within {confirm_timeout_s:g} s")
        rejection = confirmation.rejection
        assert rejection is not None
        s.count("command_rejections")
        reason = self.reason_since(t_sent)
        log.warning("%s: late ACK rejected it with MAV_RESULT %d: %s", what, rejection.result, reason or "(no reason)")
        raise CommandRejected(command, rejection.result, reason)

    def reason_since(self, t_from_s: float) -> str:
        """The vehicle's reason for a refusal (:func:`refusal_reason`): waits up to
        ``reason_grace_s`` for a STATUSTEXT of severity WARNING or worse since ``t_from_s`` (PX4
        may send it just after the ACK); else the latest text of any severity, or ``""``."""
        s = self.session
        deadline = s.clock.now() + self.reason_grace_s
        with s.changed:
            while True:
                serious, latest = refusal_reason(s.statustexts, t_from_s)
                if serious is not None:
                    return serious
                if s.closed or not s.wait_locked(deadline):
                    return latest


def received_param(msg: Any, t_rx: float) -> ParamValue:
    """The :class:`ParamValue` of a PARAM_VALUE received at ``t_rx`` [s]."""
    return ParamValue(str(msg.param_id), px4.decode_param(float(msg.param_value), int(msg.param_type)), int(msg.param_type), t_rx)


class ParamClient:
    """Reads and writes one parameter at a time on ``session`` (which keeps every PARAM_VALUE
    from the vehicle in ``session.params``); ``send(msg, counter)`` sends, ``require_vehicle()``
    returns the identified (system, component) or raises LinkError."""

    def __init__(self, session: LinkSession, send: Callable[[Any, str | None], bool],
                 require_vehicle: Callable[[], tuple[int, int]]) -> None:
        self.session, self.send, self.require_vehicle = session, send, require_vehicle

    def get(self, name: str, timeout_s: float = 0.5, retries: int = 3) -> ParamValue:
        """The vehicle's ``name`` (PARAM_REQUEST_READ); LinkTimeout if it never answers (PX4 does not
        answer for a name it does not have)."""
        target = self.require_vehicle()
        request = mavlink.MAVLink_param_request_read_message(target[0], target[1], name.encode("ascii"), -1)
        return self._exchange(name, request, lambda pv: True, timeout_s, retries)

    def set(self, name: str, value: float, timeout_s: float = 0.5, retries: int = 3) -> ParamValue:
        """Set ``name`` to ``value`` (its type read first if not yet known) and confirm it by the
        PARAM_VALUE that follows; LinkError if the vehicle keeps another value."""
        if not math.isfinite(value):
            raise ValueError(f"{name}: value must be finite, got {value!r}")
        with self.session.lock:
            known = self.session.params.get(name)
        param_type = (known or self.get(name, timeout_s, retries)).param_type
        target = self.require_vehicle()
        wanted = px4.decode_param(px4.encode_param(value, param_type), param_type)
        msg = mavlink.MAVLink_param_set_message(target[0], target[1], name.encode("ascii"), px4.encode_param(value, param_type),
                                                param_type)
        kept = self._exchange(name, msg, lambda pv: True, timeout_s, retries)
        if not math.isclose(kept.value, wanted, rel_tol=1e-6, abs_tol=1e-9):
            raise LinkError(f"vehicle kept {name} = {kept.value:g} (asked {value:g})")
        return kept

    def _exchange(self, name: str, msg: Any, accept: Callable[[ParamValue], bool], timeout_s: float,
                  retries: int) -> ParamValue:
        """Send ``msg`` until a PARAM_VALUE of ``name`` arrives after it (``retries`` resends,
        ``timeout_s`` [s of clock] each)."""
        s = self.session
        for _ in range(retries + 1):
            t_sent = s.clock.now()
            self.send(msg, None)
            deadline = t_sent + timeout_s
            with s.changed:
                while True:
                    pv = s.params.get(name)
                    if pv is not None and pv.rx_s >= t_sent and accept(pv):
                        return pv
                    if s.closed or not s.wait_locked(deadline):
                        break
        raise LinkTimeout(f"no PARAM_VALUE {name} after {retries + 1} attempts of {timeout_s:g} s")
