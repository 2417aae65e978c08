"""The one place where pymavlink is imported, after selecting MAVLink 2.

pymavlink's ``mavutil`` picks its wire protocol from the ``MAVLINK20`` environment variable at
import time (global state we cannot avoid). Every module of this package imports pymavlink
through here::

    from mission.mavlink.env import mavutil, mavlink

``mavlink`` is the generated dialect module (message classes, ``MAVLink`` codec, enums) of
pymavlink's default dialect, MAVLink 2 wire format: ``pymavlink.dialects.v20.all``, the module
``mavutil.mavlink`` is with ``MAVLINK20`` set. It is imported directly: ``mavutil`` itself also
imports the MAVLink 1 dialect (for pyinstaller), about 30 ms of CPU in every process that starts,
and only the serial link and the tlog readers need it, so ``mavutil`` is imported when first asked for.
"""
from __future__ import annotations

import importlib
import os
import sys
from types import ModuleType
from typing import TYPE_CHECKING, Any

os.environ["MAVLINK20"] = "1"

mavlink: Any
if "pymavlink.mavutil" in sys.modules:
    from pymavlink import mavutil as _mavutil

    if not _mavutil.mavlink20():
        # Somebody imported mavutil before us without MAVLINK20: reload the dialect as MAVLink 2.
        _mavutil.set_dialect(_mavutil.current_dialect)
    mavlink = _mavutil.mavlink
else:
    mavlink = importlib.import_module("pymavlink.dialects.v20.all")  # what mavutil would pick: MAVLINK20, "all"

if TYPE_CHECKING:
    from pymavlink import mavutil


def __getattr__(name: str) -> ModuleType:
    """``mavutil``, imported on first use (its dialect is ``mavlink`` above: MAVLINK20 is set)."""
    if name == "mavutil":
        from pymavlink import mavutil

        return mavutil
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def read_signing_key(path: str | os.PathLike[str], field: str = "mavlink.signing_key_file") -> bytes:
    """A 32-byte MAVLink 2 signing key from a file holding 64 hex digits or 32 raw bytes
    (:func:`mission.config.keys.read_key_file`; :class:`~mission.errors.ConfigError` names ``field``)."""
    from mission.config.keys import read_key_file

    return read_key_file(path, field)


__all__ = ["mavutil", "mavlink", "read_signing_key"]
