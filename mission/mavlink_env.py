"""The one place where pymavlink is imported, after selecting MAVLink 2.

pymavlink's ``mavutil`` picks its wire protocol from the ``MAVLINK20`` environment variable at
import time (global state we cannot avoid). Every module of this package imports pymavlink
through here::

    from mission.mavlink_env import mavutil, mavlink

``mavlink`` is the generated dialect module (message classes, ``MAVLink`` codec, enums) of
pymavlink's default dialect, MAVLink 2 wire format.
"""
from __future__ import annotations

import os
import sys

os.environ["MAVLINK20"] = "1"

_already_imported = "pymavlink.mavutil" in sys.modules

from pymavlink import mavutil  # noqa: E402  (must follow the environment variable)

if _already_imported and not mavutil.mavlink20():
    # Somebody imported mavutil before us without MAVLINK20: reload the dialect as MAVLink 2.
    mavutil.set_dialect(mavutil.current_dialect)

mavlink = mavutil.mavlink

__all__ = ["mavutil", "mavlink"]
