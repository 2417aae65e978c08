"""A command started by a supervisor ends when the supervisor is killed outright (no orphans)."""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import textwrap

from sim.net import free_port, stop_process, wait_for

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
