"""A supervised process ends with its supervisor.

A supervisor (``marsupial demo``, the test suite) names itself in the environment variable
``MARSUPIAL_PARENT_PID`` before it starts our commands. A command started that way watches its
parent: when the parent is gone (even by SIGKILL, when it had no chance to stop its children), the
command gets SIGTERM, its normal clean stop (a vehicle stops streaming, a carrier stops, a mission
closes its log), and is forced out 5 s later if that stop hangs. Without the variable nothing is
watched: a command started by a person or a service manager lives on its own terms.
"""
from __future__ import annotations

import os
import signal
import threading
import time

PARENT_PID_ENV = "MARSUPIAL_PARENT_PID"
POLL_S = 0.5  # [s] how often the parent is looked at (wall time)
FORCE_AFTER_S = 5.0  # [s] after SIGTERM, the process is forced out if still alive


def supervise_children() -> None:
    """Name this process as the supervisor of the commands it starts from now on."""
    os.environ[PARENT_PID_ENV] = str(os.getpid())


def end_with_parent() -> bool:
    """If a supervisor named itself, watch it on a daemon thread; returns whether one did. The
    variable is consumed, so this process's own children are not tied to the grandparent."""
    value = os.environ.pop(PARENT_PID_ENV, "")
    try:
        parent = int(value)
    except ValueError:
        return False
    if parent == os.getpid():  # the supervisor runs a command in its own process (a test calling main())
        os.environ[PARENT_PID_ENV] = value
        return False
    threading.Thread(target=_watch, args=(parent,), name="end-with-parent", daemon=True).start()
    return True


def _watch(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(POLL_S)
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(FORCE_AFTER_S)
    os._exit(143)
