"""The one place where pymavlink is imported, after selecting MAVLink 2.

pymavlink's ``mavutil`` picks its wire protocol from the ``MAVLINK20`` environment variable at
import time (global state we cannot avoid). Every module of this package imports pymavlink
through here::

    from mission.mavlink.env import mavutil, mavlink

``mavlink`` is the generated dialect module (message classes, ``MAVLink`` codec, enums) of
pymavlink's default dialect, MAVLink 2 wire format.
"""
from __future__ import annotations

import os
import sys

os.environ["MAVLINK20"] = "1"

_already_imported = "pymavlink.mavutil" in sys.modules

# mavutil imports the MAVLink 1 "all" dialect unconditionally (for pyinstaller, in a try/except),
# start-up time of every process for a module never used: MAVLINK20 is set above, so set_dialect
# takes the MAVLink 2 one. A None in sys.modules makes that one import fail at once; removed after.
_V10_ALL = "pymavlink.dialects.v10.all"
_skip_v10 = not _already_imported and _V10_ALL not in sys.modules
if _skip_v10:
    sys.modules[_V10_ALL] = None  # type: ignore[assignment]
try:
    from pymavlink import mavutil  # noqa: E402  (must follow the environment variable)
finally:
    if _skip_v10 and sys.modules.get(_V10_ALL, 0) is None:
        del sys.modules[_V10_ALL]

if _already_imported and not mavutil.mavlink20():
    # Somebody imported mavutil before us without MAVLINK20: reload the dialect as MAVLink 2.
    mavutil.set_dialect(mavutil.current_dialect)

mavlink = mavutil.mavlink


def read_signing_key(path: str | os.PathLike[str], field: str = "mavlink.signing_key_file") -> bytes:
    """A 32-byte MAVLink 2 signing key from a file holding 64 hex digits or 32 raw bytes
    (:func:`mission.config.keys.read_key_file`; :class:`~mission.errors.ConfigError` names ``field``)."""
    from mission.config.keys import read_key_file

    return read_key_file(path, field)


__all__ = ["mavutil", "mavlink", "read_signing_key"]
