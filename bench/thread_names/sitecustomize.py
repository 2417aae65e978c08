"""Names each Python thread's OS thread after it (``prctl(PR_SET_NAME)``, 15 characters), so
``/proc/PID/task/*/comm`` tells the threads apart. Loaded only when ``bench.lockstep_profile
--threads`` puts this directory on the children's ``PYTHONPATH``."""
import ctypes
import threading

_libc = ctypes.CDLL(None)
_bootstrap_inner = threading.Thread._bootstrap_inner  # type: ignore[attr-defined]


def _named(self: threading.Thread) -> None:
    try:
        _libc.prctl(15, self.name[:15].encode(), 0, 0, 0)  # PR_SET_NAME
    except Exception:  # noqa: BLE001 - a name is a nicety
        pass
    _bootstrap_inner(self)


threading.Thread._bootstrap_inner = _named  # type: ignore[attr-defined]
