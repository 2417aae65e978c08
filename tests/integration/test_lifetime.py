"""How a command's process ends: a stop signal stops it even when it lands while the main thread
holds a lock, and a command started by a supervisor ends when the supervisor is killed outright
(no orphans)."""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

from mission.lifetime import on_stop_signals
from sim.net import free_port, stop_process, wait_for

ROOT = Path(__file__).resolve().parents[2]

# The main thread holds the stop event's own lock, as ``Event.wait`` does between two waits, when
# SIGTERM lands: Python's handler runs right there. A handler that set the event itself would wait
# for ever on that lock (a mock vehicle hung so on SIGTERM); on_stop_signals' stop runs on its own
# thread and sets the event once the main thread lets go.
LOCK_HELD = textwrap.dedent("""
    import os, signal, threading
    from mission.lifetime import on_stop_signals

    stop = threading.Event()
    before = signal.getsignal(signal.SIGTERM)
    with on_stop_signals(lambda signum: stop.set()) as installed:
        with stop._cond:
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(200_000):
                pass
        print(installed, stop.wait(10.0), flush=True)
    print(signal.getsignal(signal.SIGTERM) is before, signal.set_wakeup_fd(-1), flush=True)
""")


def test_a_stop_signal_landing_while_the_main_thread_holds_the_stop_event_s_lock_stops_it():
    out = subprocess.run([sys.executable, "-c", LOCK_HELD], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    # stopped; and on exit the old handler and no wake-up socket are back
    assert out.stdout.split() == ["True", "True", "True", "-1"], out.stdout + out.stderr


def test_off_the_main_thread_nothing_is_installed():
    seen = []

    def call() -> None:
        with on_stop_signals(lambda signum: None) as installed:
            seen.append((installed, signal.getsignal(signal.SIGTERM)))

    before = signal.getsignal(signal.SIGTERM)
    worker = threading.Thread(target=call)
    worker.start()
    worker.join()
    assert seen == [(False, before)]


def test_no_other_module_installs_a_signal_handler():
    """Every command's SIGINT and SIGTERM go through mission.lifetime.on_stop_signals."""
    found = [f"{p.relative_to(ROOT)}:{n}" for top in ("mission", "sim", "bench") for p in sorted((ROOT / top).rglob("*.py"))
             if p != ROOT / "mission" / "lifetime.py"
             for n, line in enumerate(p.read_text().splitlines(), 1) if "signal.signal(" in line or "set_wakeup_fd(" in line]
    assert found == []

SUPERVISOR = textwrap.dedent("""
    import subprocess, sys, time
    from mission.lifetime import supervise_children
    supervise_children()
    child = subprocess.Popen([sys.executable, "-m", "mission.cli", "mock-vehicle", "--mavlink",
                              "udpin:127.0.0.1:0", "--target", "udpout:127.0.0.1:" + sys.argv[1]])
    print(child.pid, flush=True)
    time.sleep(600)
""")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:  # a zombie (reaped by init later) counts as gone
        return f.read().split(")")[-1].split()[0] != "Z"


def test_a_supervised_vehicle_stops_when_its_supervisor_is_killed():
    supervisor = subprocess.Popen([sys.executable, "-c", SUPERVISOR, str(free_port(socket.SOCK_DGRAM))],
                                  stdout=subprocess.PIPE, text=True)
    try:
        assert supervisor.stdout is not None
        child = int(supervisor.stdout.readline())
        assert _alive(child)
        supervisor.send_signal(signal.SIGKILL)  # no chance to stop its child
        supervisor.wait()
        wait_for(lambda: not _alive(child), timeout_s=20.0, what="the orphaned vehicle to stop")
    finally:
        stop_process(supervisor)
        if supervisor.stdout is not None:
            supervisor.stdout.close()


def test_an_unsupervised_command_is_not_watched(monkeypatch):
    from mission.lifetime import PARENT_PID_ENV, end_with_parent

    monkeypatch.delenv(PARENT_PID_ENV, raising=False)
    assert end_with_parent() is False
    monkeypatch.setenv(PARENT_PID_ENV, "not-a-pid")
    assert end_with_parent() is False
