"""A minimal pymavlink peer of the mock vehicle, for tests, the bench and demos.

Not the mission's link (that is ``mission/mavlink/link.py``): a plain ground-side endpoint on a UDP port
that records everything it receives and lets a caller wait for a condition with a deadline.
Times here are wall seconds (this is the outside observer), unless a name says otherwise.
"""
from __future__ import annotations

import collections
import math
import select
import socket
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from mission.mavlink import px4, setpoints
from mission.mavlink.env import mavlink
from mission.mavlink.codec import new_codec, setup_signing
from sim.vehicle.endpoints import parse_endpoint

NAN = float("nan")

if TYPE_CHECKING:
    from sim.vehicle.mock import MockVehicle


class Probe:
    """Ground-side MAVLink endpoint (sysid 255 by default) bound to ``bind`` (port 0: ephemeral).

    It talks to ``vehicle`` (``(host, port)``), or to whoever talked to it first.
    ``history`` keeps the last messages of each type with a receive index for ordering.
    """

    def __init__(self, bind: str = "127.0.0.1:0", vehicle: tuple[str, int] | None = None, sysid: int = 255,
                 compid: int = 190, signing_key: bytes | None = None, history_len: int = 4000) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self.sock.bind(parse_endpoint(bind).address)
        self.vehicle = vehicle
        self.mav = new_codec(sysid, compid)
        if signing_key is not None:  # a ground station's own link id; everything it receives must be signed
            setup_signing(self.mav, signing_key, sign_outgoing=True, unsigned_ids=(), link_id=1)
        self.history: dict[str, collections.deque[tuple[int, float, Any]]] = collections.defaultdict(
            lambda: collections.deque(maxlen=history_len))
        self.received = 0
        self.bad = 0
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._periodic: list[threading.Thread] = []
        self.pacer: Pacer | None = None  # moves a paced vehicle's time (vehicle_for(..., paced=True))
        self._rx = threading.Thread(target=self._receive_loop, name="probe-rx", daemon=True)
        self._rx.start()

    @property
    def port(self) -> int:
        return int(self.sock.getsockname()[1])

    def __enter__(self) -> Probe:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._stop.set()
        for thread in [self._rx, *self._periodic]:
            thread.join(timeout=2.0)
        self.sock.close()

    # ---- receiving -----------------------------------------------------------------------
    def _receive_loop(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self.sock], [], [], 0.02)
            if not ready:
                continue
            try:
                data, address = self.sock.recvfrom(65535)
            except OSError:
                continue
            if self.vehicle is None:
                self.vehicle = address
            self._record(self.mav.parse_buffer(data) or [], time.monotonic())
            self.mav.buf, self.mav.buf_index = bytearray(), 0

    def _record(self, messages: list[Any], t_wall: float) -> None:
        with self._cond:
            for msg in messages:
                kind = msg.get_type()
                if kind == "BAD_DATA":
                    self.bad += 1
                    continue
                self.received += 1
                self.history[kind].append((self.received, t_wall, msg))
            self._cond.notify_all()

    def mark(self) -> int:
        """Receive index now: pass it as ``after`` to wait for messages newer than this."""
        with self._cond:
            return self.received

    def latest(self, kind: str) -> Any | None:
        with self._cond:
            entries = self.history.get(kind)
            return entries[-1][2] if entries else None

    def messages(self, kind: str, after: int = 0) -> list[Any]:
        with self._cond:
            return [m for i, _, m in self.history.get(kind, ()) if i > after]

    def timed(self, kind: str) -> list[tuple[float, Any]]:
        """Every kept message of ``kind`` with its receive time (``time.monotonic()`` [s])."""
        with self._cond:
            return [(t, m) for _, t, m in self.history.get(kind, ())]

    def count_between(self, kind: str, t1_s: float, t2_s: float, timeout_s: float = 5.0) -> int:
        """How many ``kind`` messages the vehicle sent between its simulated times ``t1_s`` and
        ``t2_s``, using the time_boot_ms of LOCAL_POSITION_NED (received in the same order) as the
        clock. Waits until a LOCAL_POSITION_NED stamped after ``t2_s`` has arrived; -1 if not."""
        if self.wait_for("LOCAL_POSITION_NED", lambda m: m.time_boot_ms >= t2_s * 1000.0, timeout_s) is None:
            return -1
        with self._cond:
            stamps = [(i, m.time_boot_ms / 1000.0) for i, _, m in self.history["LOCAL_POSITION_NED"]]
            first = next(i for i, t in stamps if t >= t1_s)
            last = next(i for i, t in stamps if t >= t2_s)
            return sum(1 for i, _, _ in self.history.get(kind, ()) if first < i < last)

    def wait_for(self, kind: str, predicate: Callable[[Any], bool] | None = None, timeout_s: float = 5.0,
                 after: int = 0, *, wall: bool = False) -> Any | None:
        """First message of type ``kind`` received after index ``after`` that satisfies
        ``predicate``; None at the deadline (``timeout_s`` wall seconds; to a paced vehicle, unless
        ``wall``, the simulated time that takes at its speed, see :func:`flight_deadline`)."""
        pacer = None if wall else self.pacer
        passed = flight_deadline(timeout_s, pacer and (lambda: pacer.t_ns / 1e9), pacer.speed if pacer else 1.0)
        with self._cond:
            while True:
                for index, _, msg in self.history.get(kind, ()):
                    if index > after and (predicate is None or predicate(msg)):
                        return msg
                if passed():
                    return None
                self._cond.wait(0.01)

    # ---- vehicle state from telemetry ----------------------------------------------------
    def mode(self) -> str | None:
        hb = self.latest("HEARTBEAT")
        return None if hb is None else px4.mode_name(hb.custom_mode)

    def armed(self) -> bool:
        hb = self.latest("HEARTBEAT")
        return bool(hb is not None and hb.base_mode & px4.MAV_MODE_FLAG_SAFETY_ARMED)

    def wait_mode(self, mode: str, timeout_s: float = 5.0) -> bool:
        mark = self.mark()
        return self.wait_for("HEARTBEAT", lambda m: px4.mode_name(m.custom_mode) == mode, timeout_s, mark) is not None

    def wait_armed(self, armed: bool = True, timeout_s: float = 5.0) -> bool:
        mark = self.mark()
        flag = px4.MAV_MODE_FLAG_SAFETY_ARMED
        return self.wait_for("HEARTBEAT", lambda m: bool(m.base_mode & flag) == armed, timeout_s, mark) is not None

    # ---- sending -------------------------------------------------------------------------
    def send(self, msg: Any) -> None:
        if self.vehicle is None:
            raise RuntimeError("no vehicle address yet")
        data = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256
        self.sock.sendto(data, self.vehicle)

    def send_raw(self, data: bytes) -> None:
        if self.vehicle is None:
            raise RuntimeError("no vehicle address yet")
        self.sock.sendto(data, self.vehicle)

    def heartbeat(self) -> None:
        self.send(mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))

    def command(self, command: int, params: tuple[float, ...] = (), target: tuple[int, int] = (1, 1),
                timeout_s: float = 2.0, as_int: bool = False) -> Any | None:
        """Send a COMMAND_LONG (or COMMAND_INT) once and return its COMMAND_ACK, or None."""
        p = list(params) + [NAN] * (7 - len(params))
        mark = self.mark()
        if as_int:
            x, y = (int(v) if math.isfinite(v) else 0 for v in p[4:6])
            self.send(mavlink.MAVLink_command_int_message(*target, 0, command, 0, 0, *p[:4], x, y, p[6]))
        else:
            self.send(mavlink.MAVLink_command_long_message(*target, command, 0, *p))
        return self.wait_for("COMMAND_ACK", lambda m: m.command == command, timeout_s, mark)

    def set_mode(self, mode: str, timeout_s: float = 2.0) -> Any | None:
        main, sub = px4.MODES[mode]
        return self.command(px4.MAV_CMD_DO_SET_MODE, (px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | 128, int(main), int(sub)), timeout_s=timeout_s)

    def arm(self, arm: bool = True, force: bool = False, timeout_s: float = 2.0) -> Any | None:
        return self.command(px4.MAV_CMD_COMPONENT_ARM_DISARM,
                            (1.0 if arm else 0.0, float(px4.ARM_FORCE_MAGIC) if force else NAN), timeout_s=timeout_s)

    def setpoint_message(self, velocity_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0),
                         type_mask: int = setpoints.TYPE_MASK_VELOCITY, frame: int = px4.MAV_FRAME_LOCAL_NED,
                         position_ned_m: tuple[float, float, float] = (NAN, NAN, NAN), yaw_rad: float = NAN,
                         yaw_rate_rad_s: float = NAN, target: tuple[int, int] = (1, 1),
                         acceleration_ned_m_s2: tuple[float, float, float] = (NAN, NAN, NAN)) -> Any:
        return mavlink.MAVLink_set_position_target_local_ned_message(
            0, *target, frame, type_mask, *position_ned_m, *velocity_ned_m_s, *acceleration_ned_m_s2, yaw_rad,
            yaw_rate_rad_s)

    def every(self, period_s: float, action: Callable[[], None]) -> threading.Event:
        """Run ``action`` every ``period_s`` wall seconds until the returned event is set
        (or the probe closes)."""
        done = threading.Event()

        def loop() -> None:
            next_t = time.monotonic()
            while not done.is_set() and not self._stop.is_set():
                try:
                    action()
                except OSError:
                    pass
                next_t += period_s
                done.wait(max(0.0, next_t - time.monotonic()))

        thread = threading.Thread(target=loop, name="probe-periodic", daemon=True)
        self._periodic.append(thread)
        thread.start()
        return done

    def start_heartbeats(self, period_s: float = 0.5) -> threading.Event:
        return self.every(period_s, self.heartbeat)


class SetpointStream:
    """Resend the current setpoint every ``period_s`` wall seconds (like MAVSDK's offboard); to
    a paced vehicle (the probe has a :class:`Pacer`), at every step of its simulated time."""

    def __init__(self, probe: Probe, period_s: float, **setpoint: Any) -> None:
        self.probe, self.period_s = probe, period_s
        self._lock = threading.Lock()
        self._msg = probe.setpoint_message(**setpoint)
        self._schedule: Callable[[float], dict[str, Any]] | None = None
        self.sent = 0
        if probe.pacer is not None:
            self._done = threading.Event()
            probe.pacer.add(self)
        else:
            self._done = probe.every(period_s, self._send_one)

    def set(self, send_now: bool = False, **setpoint: Any) -> None:
        """Change the setpoint (ending a :meth:`follow`); with ``send_now`` send it at once instead
        of at the next period."""
        msg = self.probe.setpoint_message(**setpoint)
        with self._lock:
            self._msg, self._schedule = msg, None
        if send_now:
            self._send_one()

    def follow(self, schedule: Callable[[float], dict[str, Any]]) -> None:
        """From now on each setpoint is ``probe.setpoint_message(**schedule(t_s))`` for the paced
        vehicle's simulated time ``t_s`` [s] at the step it is sent for: a moving goal flown the
        same way however loaded the machine is. Needs a :class:`Pacer` (``vehicle_for(paced=True)``)."""
        if self.probe.pacer is None:
            raise RuntimeError("a scheduled setpoint needs a paced vehicle (vehicle_for(..., paced=True))")
        with self._lock:
            self._schedule = schedule

    def _send_one(self) -> None:
        with self._lock:
            msg, schedule = self._msg, self._schedule
        if schedule is not None and self.probe.pacer is not None:
            msg = self.probe.setpoint_message(**schedule(self.probe.pacer.t_ns / 1e9))
        self.probe.send(msg)
        self.sent += 1

    def stop(self) -> None:
        self._done.set()
        if self.probe.pacer is not None:
            self.probe.pacer.remove(self)

    def __enter__(self) -> SetpointStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def sleep_until(clock: Any, t_s: float, spin_wall_s: float = 0.001) -> None:
    """Block until ``clock.now() >= t_s`` [s simulated]: sleep, then spin for the last
    ``spin_wall_s`` wall seconds (yielding the GIL), so a scripted client hits ``t_s`` within
    a few tens of microseconds of wall time at any speed factor."""
    while (remaining_wall_s := (t_s - clock.now()) / clock.speed) > 0:
        time.sleep(remaining_wall_s - spin_wall_s if remaining_wall_s > 2 * spin_wall_s else 0)


class Lockstep:
    """The probe's side of the vehicle's lockstep clock (mission/mavlink/lockstep.py): wait at a barrier
    (the vehicle's TIMESYNC request), act, release the vehicle up to a wake time."""

    def __init__(self, probe: Probe, timeout_s: float = 10.0) -> None:
        self.timeout_s = timeout_s
        self.probe, self.mark, self.t_ns = probe, 0, -1

    def barrier(self) -> int:
        msg = self.probe.wait_for("TIMESYNC", lambda m: m.tc1 == 0 and m.ts1 > self.t_ns, self.timeout_s, self.mark,
                                  wall=True)
        if msg is None:
            raise TimeoutError("the vehicle never reached its next barrier")
        self.mark, self.t_ns = self.probe.mark(), int(msg.ts1)
        return self.t_ns

    def release(self, wake_ns: int) -> None:
        self.probe.send(mavlink.MAVLink_timesync_message(max(wake_ns, self.t_ns + 1), self.t_ns))

    def run_for(self, seconds: float, each: Callable[[], None], period_s: float = 0.02) -> None:
        """Call ``each`` (e.g. send a setpoint) at every barrier, ``period_s`` apart, for ``seconds``."""
        end_ns = self.t_ns + round(seconds * 1e9)
        while self.t_ns < end_ns:
            each()
            self.release(self.t_ns + round(period_s * 1e9))
            self.barrier()


PACED_WALL_CAP_S = 60.0  # longest wall wait on a paced vehicle whose time has stopped [s]


def flight_deadline(timeout_s: float, sim_now: Callable[[], float] | None = None,
                    speed: float = 1.0) -> Callable[[], bool]:
    """A deadline check: ``timeout_s`` wall seconds; with ``sim_now`` (a paced vehicle's time [s]),
    the ``timeout_s * speed`` simulated seconds that is at full pace, so a loaded machine that
    slows the vehicle's time does not shorten its flight (never longer than
    :data:`PACED_WALL_CAP_S` of wall)."""
    wall_end = time.monotonic() + (timeout_s if sim_now is None else max(timeout_s, PACED_WALL_CAP_S))
    if sim_now is None:
        return lambda: time.monotonic() > wall_end
    sim_end = sim_now() + timeout_s * speed
    return lambda: sim_now() > sim_end or time.monotonic() > wall_end


def wait_flight(v: "MockVehicle", predicate: Callable[[Any], bool], timeout_s: float, what: str) -> Any:
    """The vehicle's snapshot once ``predicate`` holds for it; ``AssertionError`` naming ``what``
    after ``timeout_s`` wall seconds at its speed, counted on its simulated time when it is paced
    (lockstep at most ``lockstep_max_speed``): :func:`flight_deadline`."""
    pace = v.options.lockstep_max_speed if v.options.lockstep else None
    passed = flight_deadline(timeout_s, pace and (lambda: v.snapshot().t_s), pace or 1.0)
    while True:
        snap = v.snapshot()
        if predicate(snap):
            return snap
        if passed():
            raise AssertionError(f"timed out after {timeout_s} s (at speed {v.options.speed:g}) waiting for {what}")
        time.sleep(0.002)


class Pacer:
    """Moves a lockstep vehicle's simulated time from a thread of the probe, ``step_s`` at a time
    (at most as fast as the vehicle's ``lockstep_max_speed``), and sends the setpoint of every
    :class:`SetpointStream` at each step. The vehicle then flies as a real-time one at that speed
    would, but a stalled machine only slows its time: at speed 10 a real-time stream stalled 0.1 s
    of wall was 1 s without setpoints, PX4's offboard loss."""

    def __init__(self, probe: Probe, speed: float, step_s: float = 0.01) -> None:
        self.probe, self.speed, self.step_ns = probe, speed, round(step_s * 1e9)
        self.t_ns = 0  # the vehicle's time at its last barrier [ns]
        self._clock = Lockstep(probe, timeout_s=0.2)
        self._streams: list[SetpointStream] = []
        self._lock = threading.Lock()
        thread = threading.Thread(target=self._run, name="probe-pacer", daemon=True)
        probe._periodic.append(thread)
        thread.start()

    def add(self, stream: SetpointStream) -> None:
        with self._lock:
            self._streams.append(stream)

    def remove(self, stream: SetpointStream) -> None:
        with self._lock:
            if stream in self._streams:
                self._streams.remove(stream)

    def _run(self) -> None:
        while not self.probe._stop.is_set():
            try:
                t_ns = self.t_ns = self._clock.barrier()
            except TimeoutError:  # no vehicle yet, or it stopped: look again until the probe closes
                continue
            with self._lock:
                streams = list(self._streams)
            try:
                for stream in streams:
                    stream._send_one()
                self._clock.release(t_ns + self.step_ns)
            except OSError:  # the probe closed
                return


def vehicle_for(probe: Probe, speed: float = 10.0, paced: bool = False, **options: Any) -> "MockVehicle":
    """A :class:`sim.vehicle.mock.MockVehicle` on an ephemeral port that talks to ``probe``. ``paced``:
    in lockstep, its time moved by the probe's :class:`Pacer` at most ``speed`` times the wall clock."""
    from sim.vehicle.mock import MockVehicle, VehicleOptions

    if paced:
        options.update(lockstep=True, lockstep_max_speed=speed)
        if probe.pacer is None:
            probe.pacer = Pacer(probe, speed)
    return MockVehicle(VehicleOptions(bind="127.0.0.1:0", target=f"127.0.0.1:{probe.port}", speed=speed, **options))


def connect(probe: Probe, timeout_s: float = 3.0, heartbeat_period_s: float = 0.1) -> Probe:
    """Wait for the vehicle's first HEARTBEAT, then send our own periodically (PX4 needs them
    before it sends STATUSTEXT)."""
    if probe.wait_for("HEARTBEAT", timeout_s=timeout_s) is None:
        raise TimeoutError(f"no HEARTBEAT within {timeout_s} s")
    probe.heartbeat()
    probe.start_heartbeats(heartbeat_period_s)
    return probe


def start_offboard(probe: Probe, velocity_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0), period_s: float = 0.01,
                   arm: bool = True, timeout_s: float = 3.0, **setpoint: Any) -> SetpointStream:
    """Stream a setpoint, switch to OFFBOARD (retrying while it is rejected) and arm."""
    stream = SetpointStream(probe, period_s, velocity_ned_m_s=velocity_ned_m_s, **setpoint)
    deadline = time.monotonic() + timeout_s
    while True:
        ack = probe.set_mode("OFFBOARD", timeout_s=0.5)
        if ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED:
            break
        if time.monotonic() > deadline:
            stream.stop()
            raise TimeoutError("OFFBOARD not accepted")
    if arm:
        ack = probe.arm()
        if ack is None or ack.result != px4.MAV_RESULT_ACCEPTED:
            stream.stop()
            raise RuntimeError(f"arming failed: {ack}")
    return stream
