"""The mock vehicle as its own process (``python -m sim.vehicle.cli``), for tests and benches."""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from typing import Any


def spawn_process(args: Sequence[str], timeout_s: float = 60.0, **popen_kwargs: Any) -> tuple[subprocess.Popen[bytes], int]:
    """Start ``python -m sim.vehicle.cli ARGS`` as its own process; return it and its UDP port.
    ``timeout_s`` [s] of wall time for it to report its port: an event waited on, long only when it
    fails (a start takes 0.6 s of CPU; at load 20 it once took over 15 s).

    The port comes from ``--port-file`` (added here). Stop the process with ``terminate()``
    (SIGTERM: clean exit 0) and ``wait()``.
    """
    directory = tempfile.mkdtemp(prefix="mock-vehicle-")
    port_file = os.path.join(directory, "port")
    command = [sys.executable, "-m", "sim.vehicle.cli", "--port-file", port_file, *args]
    process = subprocess.Popen(command, **popen_kwargs)
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline:
            if os.path.exists(port_file):
                with open(port_file, encoding="ascii") as handle:
                    text = handle.read().strip()
                if text.isdigit():
                    return process, int(text)
            if process.poll() is not None:
                raise RuntimeError(f"mock vehicle exited with code {process.returncode} before listening")
            time.sleep(0.02)
        process.kill()
        process.wait()
        raise TimeoutError(f"mock vehicle did not report its port within {timeout_s} s")
    finally:
        if os.path.exists(port_file):
            os.unlink(port_file)
        os.rmdir(directory)
