"""A process that stood still (SIGSTOP, starved) does not take its own stop for its upstream's
silence: its lockstep clock stays in step and takes the next barrier, instead of falling back
to the wall clock and running on by it (a carrier that did so never rejoined the lockstep)."""
from __future__ import annotations

import contextlib
import threading
import time
import types
from collections.abc import Iterator

import pytest

import mission.time.clock as clock_module
from mission.time.clock import OWN_STALL_WALL_S, LockstepClock, Silence
from sim.net import wait_for
from tests.support.stepper import Stepper


class _Wall:
    """``time`` for the clock module, whose monotonic clock can jump ahead (the process stopped)."""

    def __init__(self) -> None:
        self.jumped_s = 0.0

    def monotonic(self) -> float:
        return time.monotonic() + self.jumped_s

    def sleep(self, duration_s: float) -> None:
        time.sleep(duration_s)


@pytest.fixture
def wall(monkeypatch: pytest.MonkeyPatch) -> _Wall:
    fake = _Wall()
    monkeypatch.setattr(clock_module, "time", types.SimpleNamespace(monotonic=fake.monotonic, sleep=fake.sleep))
    return fake


def test_a_stretch_this_process_stood_still_is_not_silence(wall: _Wall) -> None:
    silence = Silence()
    assert silence.elapsed() < OWN_STALL_WALL_S
    wall.jumped_s += 30.0  # stopped for 30 s between two checks
    assert silence.elapsed() < OWN_STALL_WALL_S and silence.own_stalls == 1
    silence.restart()
    assert silence.elapsed() < OWN_STALL_WALL_S


def _participant(clock: LockstepClock) -> None:
    while clock.lockstep:
        clock.sleep(0.02)


@contextlib.contextmanager
def _stepped(watchdog_wall_s: float, name: str) -> Iterator[tuple[LockstepClock, Stepper]]:
    """A lockstep clock with one participant (a 20 ms sleeper), the test its upstream; closed after."""
    clock = LockstepClock(watchdog_wall_s=watchdog_wall_s, name=name, creator_runs=False)
    stepper = Stepper(clock)
    threading.Thread(target=_participant, args=(clock,), name="participant", daemon=True).start()
    try:
        yield clock, stepper
    finally:
        clock.close()


def test_a_clock_stopped_longer_than_its_watchdog_stays_in_step(wall: _Wall) -> None:
    with _stepped(0.5, "stopped") as (clock, stepper):
        stepper.step()
        stepper.step()
        wall.jumped_s += 6.0  # the process stood still 6 s (wall), its upstream's barrier waiting in a socket
        wait_for(lambda: clock._silence.own_stalls >= 1, 5.0, "the scheduler saw its own stall")
        assert clock.lockstep, clock.fallback_reason
        stepper.step()  # the barrier that was waiting: taken, in step
        assert clock.now() == pytest.approx(0.04) and clock.counters["held"], clock.counters


def test_an_upstream_silent_while_this_process_runs_is_gone() -> None:
    with _stepped(0.3, "silent") as (clock, stepper):
        stepper.step()
        wait_for(lambda: not clock.lockstep, 5.0, "the clock fell back")
        assert clock.fallback_reason is not None and "upstream silent" in clock.fallback_reason
        assert clock.counters["held"] is False
        # and it says it left, so the vehicle goes on in real time at once (its own watchdog is
        # longer than ours: it sent nothing meanwhile, and the flight took it for lost)
        wait_for(lambda: stepper.reports[-1][1] < 0, 5.0, "the leave reported upstream")
        assert stepper.reports[-1][0] == stepper.reports[0][0]


def test_a_barrier_sent_again_is_answered_again() -> None:
    """Over UDP a barrier or its answer can be lost; the vehicle sends the barrier again, and a
    step already done is answered again, the same answer, without stepping twice."""
    with _stepped(5.0, "again") as (clock, stepper):
        stepper.step()
        stepper.step()
        steps, (t_ns, wake_ns) = clock.barriers, stepper.reports[-1]
        clock.barrier(t_ns)  # the same barrier again (its answer was lost)
        wait_for(lambda: len(stepper.reports) >= 3, 5.0, "the barrier answered again")
        assert set(stepper.reports[1:]) == {(t_ns, wake_ns)} and clock.barriers == steps and clock.now() == t_ns / 1e9


def test_a_clock_idle_at_a_barrier_reports_its_step_again_and_its_watchdog_still_counts() -> None:
    """A report can be lost, or put before a peer's route was up (a carrier's ready for step 0 that
    the vehicle's deck never heard): every RESEND_WALL_S without a barrier the step done is
    reported again. The repeats are this process speaking, not the upstream: the watchdog still
    fires."""
    with _stepped(1.6, "idle") as (clock, stepper):
        stepper.step()
        done = stepper.reports[-1]
        wait_for(lambda: len(stepper.reports) >= 3, 5.0, "the step reported again")
        assert set(stepper.reports[:3]) == {done}
        wait_for(lambda: not clock.lockstep, 5.0, "the clock fell back")
        assert "upstream silent" in (clock.fallback_reason or "")
