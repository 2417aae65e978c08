"""Blocking vehicle commands and parameters over a link: the executor of
:mod:`mission.mavlink.commands`, and :class:`ParamClient` (PARAM_REQUEST_READ and PARAM_SET, each
answered by the PARAM_VALUE PX4 sends back, integers bit-packed as :mod:`mission.mavlink.px4` says);
:class:`HomeKeeper` and :class:`ParamKeeper`, which keep the vehicle's home and failsafe
parameters where the mission set them (read back, and restored when someone else moved them).

One command at a time (thread-safe). Each call sends through the link, waits on the session's
clock for what the state machines need, and turns their verdicts into our errors:
:class:`~mission.errors.CommandRejected` (with the vehicle's STATUSTEXT reason),
:class:`~mission.errors.LinkTimeout`, :class:`~mission.errors.LinkError`.
"""
from __future__ import annotations

import contextlib
import logging
import math
import collections
import threading
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any, Callable, Protocol

import numpy as np

from mission.core import geodesy
from mission.flight_mode import FlightMode
from mission.mavlink import px4
from mission.errors import CommandRejected, LinkError, LinkTimeout
from mission.time.clock import join_thread, start_thread
from mission.mavlink.commands import CommandExchange, Confirmed, HeartbeatConfirmation, Step, refusal_reason
from mission.mavlink.session import LinkSession, ParamValue
from mission.mavlink.telemetry import VehicleState
from mission.mavlink.env import mavlink

if TYPE_CHECKING:
    from mission.time.clock import Clock

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
        """Set ``name`` to ``value`` (its type read first if not yet known) and confirm it by a
        PARAM_VALUE showing it; LinkError if, after every attempt, the vehicle shows another value.

        A PARAM_VALUE of another value does not end an attempt: it may be a late answer to an
        earlier read (a read that timed out and was sent again is answered twice; under load the
        second answer came after the set, and was taken for the vehicle's refusal)."""
        if not math.isfinite(value):
            raise ValueError(f"{name}: value must be finite, got {value!r}")
        with self.session.lock:
            known = self.session.params.get(name)
        param_type = (known or self.get(name, timeout_s, retries)).param_type
        target = self.require_vehicle()
        wanted = px4.decode_param(px4.encode_param(value, param_type), param_type)
        msg = mavlink.MAVLink_param_set_message(target[0], target[1], name.encode("ascii"), px4.encode_param(value, param_type),
                                                param_type)
        t_first = self.session.clock.now()
        try:
            return self._exchange(name, msg, lambda pv: math.isclose(pv.value, wanted, rel_tol=1e-6, abs_tol=1e-9),
                                  timeout_s, retries)
        except LinkTimeout:
            with self.session.lock:
                shown = self.session.params.get(name)
            if shown is not None and shown.rx_s >= t_first:
                raise LinkError(f"vehicle kept {name} = {shown.value:g} (asked {value:g})") from None
            raise

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


# ------------------------------------------------------------------------------ the vehicle's settings, kept

HOME_MOVED_M = 1.0
"""PX4's home read back (HOME_POSITION) this far [m] from every home we set lately: moved by someone else."""
HOME_SETTLE_S = 0.2
"""A HOME_POSITION received this long [s] after our last DO_SET_HOME shows it (PX4 applies it before the ACK)."""
KEPT_PARAMS = ("COM_OBL_RC_ACT", "COM_OF_LOSS_T", "RTL_RETURN_ALT", "RTL_MIN_DIST", "RTL_CONE_ANG")
"""PX4's failsafe parameters a mission relies on: the offboard-loss action and timeout, and how
Return flies to the home (docs/recovery.md, "PX4's home")."""


def home_moved(sent: list[tuple[float, Any]], reported_ned_m: Any, reported_rx_s: float | None,
               moved_m: float = HOME_MOVED_M, settle_s: float = HOME_SETTLE_S) -> float | None:
    """How far [m] PX4's home as read back (``reported_ned_m`` [m] NED, received at
    ``reported_rx_s`` [s]) is from the nearest of the homes we ``sent`` lately ((time [s], point
    [m] NED), oldest first), when that is more than ``moved_m``; None when it is not, or when the
    report is older than the newest home sent plus ``settle_s``."""
    if not sent or reported_ned_m is None or reported_rx_s is None or reported_rx_s < sent[-1][0] + settle_s:
        return None
    reported = np.asarray(reported_ned_m, dtype=float)
    nearest = min(float(np.linalg.norm(reported - np.asarray(home, dtype=float))) for _, home in sent)
    return nearest if nearest > moved_m else None


class ParamKeeper:
    """Keeps vehicle parameters at the values the mission chose (:meth:`keep`): :meth:`check_once`
    reads the next one back (round robin) through ``get(name)`` and, if someone else changed it,
    puts ours back through ``set(name, value)`` (the value kept) with a warning. ``counters``:
    ``read``, ``unread`` (no answer), ``moved``, ``restored``, ``failed``; ``moves``: each change
    found, with what became of it (for the summary)."""

    def __init__(self, get: Callable[[str], float], set_: Callable[[str, float], float]) -> None:
        self.get, self.set = get, set_
        self.kept: dict[str, float] = {}
        self.counters = {"read": 0, "unread": 0, "moved": 0, "restored": 0, "failed": 0}
        self.moves: list[dict[str, Any]] = []
        self._next = 0

    def keep(self, name: str, value: float) -> None:
        self.kept[name] = float(value)

    def check_once(self) -> None:
        if not self.kept:
            return
        names = sorted(self.kept)
        name = names[self._next % len(names)]
        self._next += 1
        ours = self.kept[name]
        try:
            found = self.get(name)
        except LinkError:
            self.counters["unread"] += 1
            return
        self.counters["read"] += 1
        if math.isclose(found, ours, rel_tol=1e-6, abs_tol=1e-6):
            return
        self.counters["moved"] += 1
        move: dict[str, Any] = {"name": name, "found": found, "ours": ours}
        try:
            move["restored"] = self.set(name, ours)
            self.counters["restored"] += 1
            log.warning("PX4's %s was changed by someone else to %g (ours %g): restored", name, found, ours)
        except LinkError as exc:
            move["failed"] = str(exc)
            self.counters["failed"] += 1
            log.error("PX4's %s was changed by someone else to %g (ours %g) and could not be restored: %s",
                      name, found, ours, exc)
        self.moves.append(move)


HOME_PERIOD_S = 1.0  # PX4's home is moved at most this often [s] ...
HOME_MIN_MOVE_M = 0.5  # ... and only when the carrier moved this far from it [m]
OFFBOARD_LOSS_RETURN = 3  # COM_OBL_RC_ACT: Return
CHECK_PERIOD_S = 1.0  # PX4's home and one failsafe parameter read back this often [s]


def home_update_due(last: tuple[float, np.ndarray] | None, now_s: float, home_ned_m: np.ndarray,
                    period_s: float = HOME_PERIOD_S, min_move_m: float = HOME_MIN_MOVE_M) -> bool:
    """Should PX4's home move to ``home_ned_m`` [m] NED now? Yes if none was sent yet (``last``:
    the time [s] and point of the last one sent), else once ``period_s`` [s] have passed and it
    is ``min_move_m`` [m] or more from the last one."""
    if last is None:
        return True
    return now_s - last[0] >= period_s and float(np.linalg.norm(home_ned_m - last[1])) >= min_move_m


class HomeVehicle(Protocol):
    """What :class:`HomeKeeper` needs of a vehicle (a :class:`~mission.interfaces.Vehicle` has it)."""

    @property
    def state(self) -> VehicleState: ...

    def set_home(self, home_ned_m: Any) -> int: ...


class HomeKeeper:
    """Keeps PX4's home at the carrier (each flying decision's ``home_ned_m``), and the failsafe
    parameters the mission relies on (``params``), off the loop.

    :meth:`offer` (from the loop, never blocks) leaves the newest home; a thread on the clock
    sends it with one DO_SET_HOME attempt when :func:`home_update_due` says so, and counts what
    the vehicle did with it (a missing EKF origin is waited out quietly). Every
    :data:`CHECK_PERIOD_S` it reads the home back (HOME_POSITION): one moved by someone else
    (:func:`~mission.mavlink.commander.home_moved`) is set again at once (``moved``,
    ``restored``); and it reads one of ``params`` back, restoring it if changed
    (:class:`~mission.mavlink.commander.ParamKeeper`). :meth:`close` checks the home a last time,
    so the vehicle is never left with a home someone else moved. ``threaded=False`` sends inside
    :meth:`offer` and checks in :meth:`check` (unit tests on a manual clock). docs/recovery.md,
    "PX4's home"."""

    def __init__(self, vehicle: HomeVehicle, clock: Clock, threaded: bool = True, params: ParamKeeper | None = None) -> None:
        self.vehicle, self.clock, self.params = vehicle, clock, params
        self.counters: dict[str, int] = {"sent": 0, "accepted": 0, "refused": 0, "lost": 0, "moved": 0, "restored": 0}
        self._last: tuple[float, np.ndarray] | None = None
        self._sent: collections.deque[tuple[float, np.ndarray]] = collections.deque(maxlen=4)
        self._wanted: np.ndarray | None = None
        self._closed = False
        self._next_check_s = -math.inf
        self._cond = threading.Condition()
        self._thread = start_thread(clock, self._run, "mission-home") if threaded else None

    def offer(self, home_ned_m: np.ndarray | None) -> None:
        if home_ned_m is None:
            return
        with self._cond:
            self._wanted = np.array(home_ned_m, dtype=float)
            due = home_update_due(self._last, self.clock.now(), self._wanted)
            if due:  # else nothing for the thread to do until its own wake (a woken thread costs a lockstep hand-off)
                self.clock.notify(self._cond)
        if self._thread is None and due:
            self._send(self._wanted)

    def _run(self) -> None:
        with self._cond:
            while not self._closed:
                wanted, now = self._wanted, self.clock.now()
                if wanted is not None and home_update_due(self._last, now, wanted):
                    work: Callable[[], object] = lambda: self._send(wanted)  # noqa: E731
                elif now >= self._next_check_s:
                    self._next_check_s = now + CHECK_PERIOD_S
                    work = self.check
                else:
                    wake = self._next_check_s - now
                    if self._last is not None and wanted is not None and self._last[0] + HOME_PERIOD_S > now:
                        wake = min(wake, self._last[0] + HOME_PERIOD_S - now)  # (past it, only a new home makes one due)
                    self.clock.wait(self._cond, max(wake, 1e-3))
                    continue
                self._cond.release()
                try:
                    work()
                finally:
                    self._cond.acquire()

    def check(self) -> None:
        """Read the home back and set ours again if someone else moved it; read one parameter back."""
        self._check_home()
        if self.params is not None:
            self.params.check_once()

    def _check_home(self) -> None:
        if self._sent:
            st = self.vehicle.state
            moved = home_moved(list(self._sent), st.home_ned_m, st.home_rx_s)
            if moved is not None and self._last is not None:
                ours = self._last[1]
                self.counters["moved"] += 1
                log.warning("PX4's home was moved by someone else to %s, %.1f m from ours %s: setting ours again",
                            np.round(np.asarray(st.home_ned_m), 2).tolist(), moved, np.round(ours, 2).tolist())
                if self._send(ours):
                    self.counters["restored"] += 1

    def _send(self, home: np.ndarray) -> bool:
        """One DO_SET_HOME to ``home`` [m] NED; True if the vehicle accepted it."""
        ok = False
        try:
            self.vehicle.set_home(home)
            ok = True
        except CommandRejected as exc:
            self.counters["refused"] += 1
            log.warning("vehicle refused the home %s: %s", np.round(home, 2).tolist(), exc.reason or exc.result)
        except LinkError as exc:  # no EKF origin yet, or the ACK lost: a newer home follows
            self.counters["lost"] += 1
            log.debug("home not moved: %s", exc)
        else:
            self.counters["accepted"] += 1
        self.counters["sent"] += 1
        self._last = (self.clock.now(), home)
        self._sent.append(self._last)
        return ok

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self.clock.notify(self._cond)
        if self._thread is not None:
            join_thread(self.clock, self._thread, 5.0)
        try:
            self._check_home()  # the last word on the home is ours
        except LinkError as exc:
            log.warning("PX4's home not checked at the end: %s", exc)
