"""The rangefinder feed in flight (``mission.feeds = [..., "rangefinder"]``, entry point
``marsupial.feeds``): the vehicle's downward rangefinder as its autopilot streams it over the
mission's MAVLink link (DISTANCE_SENSOR, MAVLink common.xml id 132; PX4 streams each sample of
its ``distance_sensor`` topic: PX4-Autopilot src/modules/mavlink/streams/DISTANCE_SENSOR.hpp), each
reading a :class:`~mission.phases.measurements.DownwardRange` captured at the message's
``time_boot_ms`` moved onto the mission clock.

The I/O is a listener on the link (:meth:`mission.mavlink.link.VehicleLink.add_listener`: the
identified vehicle's messages, in the link's receiver thread); the conversion is
:func:`mission.mavlink.telemetry.downward_range` (pure): downward orientation only, the sigma from
the covariance or ``relnav.range_sigma_m`` when unknown, and the drops it names counted
(:attr:`RangefinderFeed.counters`, ``summary.json``'s ``feeds``); a message that cannot be read
is counted ``malformed``, never raised. :meth:`RangefinderFeed.poll` hands over what arrived
since the last poll, as it arrived (a real sensor's latency is in its capture stamps). The
mission asks the vehicle for the stream (:class:`mission.mavlink.requests.Px4Setup`).
"""
from __future__ import annotations

import threading
from typing import Any

from mission.config.schema import Config
from mission.mavlink.link import VehicleLink
from mission.mavlink.telemetry import RANGE_DROPS, downward_range
from mission.phases.measurements import DownwardRange, Measurement


class RangefinderFeed:
    """A :class:`~mission.interfaces.MeasurementSource` of the vehicle's DISTANCE_SENSOR
    messages on ``link`` (``default_sigma_m`` [m]: a range's sigma when the vehicle does not state it)."""

    def __init__(self, link: VehicleLink, default_sigma_m: float) -> None:
        self.link, self.default_sigma_m = link, default_sigma_m
        self._lock = threading.Lock()
        self._pending: list[DownwardRange] = []
        self._counts = dict.fromkeys(("received", "readings", *RANGE_DROPS), 0)
        self._closed = False
        link.add_listener(self._on_message)

    @property
    def counters(self) -> dict[str, Any]:
        """DISTANCE_SENSOR messages received, turned into readings, and dropped by reason
        (:data:`~mission.mavlink.telemetry.RANGE_DROPS`)."""
        with self._lock:
            return dict(self._counts)

    def _on_message(self, msg: Any) -> None:
        """The link's receiver thread: one message from the vehicle (others than DISTANCE_SENSOR ignored)."""
        try:
            if msg.get_type() != "DISTANCE_SENSOR" or self._closed:
                return
            found = downward_range(msg, self.link.state.vehicle_clock_offset_s, self.default_sigma_m)
        except Exception:  # noqa: BLE001  (a reading is dropped and counted; the link's thread goes on)
            found = "malformed"
        with self._lock:
            self._counts["received"] += 1
            if isinstance(found, str):
                self._counts[found] += 1
            else:
                self._counts["readings"] += 1
                self._pending.append(found)

    def poll(self, t_s: float) -> list[Measurement]:
        with self._lock:
            arrived, self._pending = self._pending, []
        return list(arrived)

    def close(self) -> None:
        with self._lock:
            self._closed, self._pending = True, []


def open_feed(cfg: Config, session: Any, clock: Any, link: VehicleLink, passenger: str | None = None) -> RangefinderFeed:
    """The opener ``marsupial run`` calls for the feed name ``rangefinder``: the mission's own
    link (a team passenger's is its own vehicle's; ``session`` and ``passenger`` are not needed)."""
    return RangefinderFeed(link, cfg.relnav.range_sigma_m)
