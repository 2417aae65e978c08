"""COMMAND_LONG as PX4 answers it, as small state machines on the injected clock (no I/O).

:class:`CommandExchange` is one command's ACK cycle::

    SEND(confirmation 0) -> WAIT --ACK ACCEPTED--> DONE
                             |  --ACK other----> DONE (rejected: the caller reads ``final``)
                             |  --IN_PROGRESS--> WAIT (the wait restarts)
                             `--timeout_s-----> SEND(confirmation + 1), at most ``retries`` times
                                                -> TIMED_OUT

:class:`HeartbeatConfirmation` follows a mode or arming command: PX4 of 2025 ACKs DO_SET_MODE
twice (ACCEPTED from the MAVLink layer, then the real result), so an ACK alone is not trusted::

    WAIT --HEARTBEAT received after the command, showing the change--> CONFIRMED
      |  --a later non-ACCEPTED ACK of the same command------------> REJECTED
      `--confirm_timeout_s---------------------------------------> TIMED_OUT

The caller (:class:`mission.mavlink.link.VehicleLink`) sends, waits and raises; these only decide, from
the clock time, the ACKs received (an :class:`AckLog`) and the vehicle's state.
"""
from __future__ import annotations

import collections
import enum
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from mission.mavlink.telemetry import VehicleState
from mission.mavlink.env import mavlink

MAV_RESULT_ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
MAV_RESULT_IN_PROGRESS = mavlink.MAV_RESULT_IN_PROGRESS


@dataclass(frozen=True)
class Ack:
    """One COMMAND_ACK addressed to us: its arrival number, time [s], command and MAV_RESULT."""

    seq: int
    t_s: float
    command: int
    result: int


class AckLog:
    """The newest COMMAND_ACKs, numbered in arrival order (``seq`` is the latest number)."""

    def __init__(self, maxlen: int = 64) -> None:
        self._acks: collections.deque[Ack] = collections.deque(maxlen=maxlen)
        self.seq = 0

    def add(self, t_s: float, command: int, result: int) -> Ack:
        self.seq += 1
        ack = Ack(self.seq, t_s, int(command), int(result))
        self._acks.append(ack)
        return ack

    def __iter__(self):  # oldest first
        return iter(tuple(self._acks))


class Step(enum.Enum):
    SEND = "send"
    WAIT = "wait"
    DONE = "done"
    TIMED_OUT = "timed_out"


class CommandExchange:
    """One COMMAND_LONG's ACK / IN_PROGRESS / retry cycle (diagram in the module docstring).

    ``after``: the :class:`AckLog` number when the command was first due (older ACKs are not its
    answer). Call :meth:`step` with the clock time and the ACK log; on ``SEND`` send attempt
    number :attr:`confirmation`; on ``WAIT`` wait until :attr:`deadline_s` or the next ACK; on
    ``DONE`` :attr:`final` is the answer (ACCEPTED or not).
    """

    def __init__(self, command: int, timeout_s: float, retries: int, after: int) -> None:
        if retries < 0 or not timeout_s > 0:
            raise ValueError("retries must be >= 0 and timeout_s > 0")
        self.command, self.timeout_s, self.retries = int(command), float(timeout_s), int(retries)
        self.after = after
        self.sent = 0
        self.deadline_s = -math.inf
        self.final: Ack | None = None

    @property
    def confirmation(self) -> int:
        """MAVLink ``confirmation`` field of the latest send: 0 first, then 1, 2, ... (<= 255)."""
        return min(self.sent - 1, 255)

    def step(self, now_s: float, acks: Iterable[Ack]) -> Step:
        if self.final is not None:
            return Step.DONE
        for ack in acks:
            if ack.seq > self.after and ack.command == self.command:
                if ack.result != MAV_RESULT_IN_PROGRESS:
                    self.final = ack
                    return Step.DONE
                self.after, self.deadline_s = ack.seq, now_s + self.timeout_s  # still working on it
        if now_s < self.deadline_s:
            return Step.WAIT
        if self.sent > self.retries:
            return Step.TIMED_OUT
        self.sent += 1
        self.deadline_s = now_s + self.timeout_s
        return Step.SEND


class Confirmed(enum.Enum):
    WAIT = "wait"
    CONFIRMED = "confirmed"
    REJECTED = "rejected"
    TIMED_OUT = "timed_out"


class HeartbeatConfirmation:
    """Confirmation by HEARTBEAT of a command sent at ``t_sent_s`` (diagram in the module
    docstring). ``after``: the ACK log number before the command; ``confirmed(state)``: the
    change shows (armed, the mode). :meth:`start` once the ACK cycle ended; then :meth:`step`."""

    def __init__(self, command: int, t_sent_s: float, after: int, confirmed: Callable[[VehicleState], bool],
                 confirm_timeout_s: float) -> None:
        self.command, self.t_sent_s, self.after = int(command), t_sent_s, after
        self.confirmed, self.confirm_timeout_s = confirmed, confirm_timeout_s
        self.deadline_s = math.inf
        self.rejection: Ack | None = None

    def start(self, now_s: float) -> None:
        self.deadline_s = now_s + self.confirm_timeout_s

    def step(self, now_s: float, acks: Iterable[Ack], state: VehicleState) -> Confirmed:
        for ack in acks:
            if ack.seq > self.after and ack.command == self.command and \
                    ack.result not in (MAV_RESULT_ACCEPTED, MAV_RESULT_IN_PROGRESS):
                self.rejection = ack
                return Confirmed.REJECTED
        if state.heartbeat_rx_s is not None and state.heartbeat_rx_s >= self.t_sent_s and self.confirmed(state):
            return Confirmed.CONFIRMED
        return Confirmed.WAIT if now_s < self.deadline_s else Confirmed.TIMED_OUT


def refusal_reason(texts: Iterable[tuple[float, int, str]], t_from_s: float,
                   serious_severity: int = mavlink.MAV_SEVERITY_WARNING) -> tuple[str | None, str]:
    """The vehicle's reason for a refusal from its STATUSTEXTs ``(t [s], severity, text)``
    received since ``t_from_s``: (the latest of severity ``serious_severity`` or worse, or None;
    the latest of any severity, or ``""``). PX4 sends the reason just before or just after the
    ACK, so a caller waits a little for a serious one before settling for the other."""
    recent = [(sev, text) for t, sev, text in texts if t >= t_from_s]
    serious = [text for sev, text in recent if sev <= serious_severity]
    return (serious[-1] if serious else None), (recent[-1][1] if recent else "")
