"""The carrier state's encodings on the bus, by the name ``zenoh.encoding`` gives (pure: no Zenoh):
``json`` (:mod:`mission.bus.wire`) and ``cdr``, ROS 2's ``nav_msgs/msg/Odometry``
(:mod:`mission.bus.ros2`, which builds on the wire's types)."""
from __future__ import annotations

from mission.bus.ros2 import decode_odometry_cdr, encode_odometry_cdr
from mission.bus.wire import CarrierState, decode_carrier_json, encode_carrier_json


def decode_carrier(raw: bytes | bytearray | memoryview, encoding: str, *, seq: int = 0) -> CarrierState:
    """Dispatch on ``encoding`` ("json" or "cdr"); ``seq`` is used by CDR only."""
    if encoding == "json":
        return decode_carrier_json(raw)
    if encoding == "cdr":
        return decode_odometry_cdr(raw, seq=seq)
    raise ValueError(f"unknown encoding {encoding!r}")


def encode_carrier(state: CarrierState, encoding: str) -> bytes:
    """Dispatch on ``encoding`` ("json" or "cdr")."""
    if encoding == "json":
        return encode_carrier_json(state)
    if encoding == "cdr":
        return encode_odometry_cdr(state)
    raise ValueError(f"unknown encoding {encoding!r}")
