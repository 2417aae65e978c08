"""Zenoh I/O between the carrier and the passenger (thin: knows nothing of the law).

This module is the bus's public face; the code is in :mod:`mission.bus.session` (sessions,
keys), :mod:`mission.bus.feeds` (receiving) and :mod:`mission.bus.publishers` (publishing).

Key expressions are namespaced per marsupial pair (:func:`keys`), so several pairs share one
Zenoh network without crosstalk::

    marsupial/<pair>/carrier/state      CarrierState (JSON, or CDR Odometry with --encoding cdr)
    marsupial/<pair>/carrier/alive      liveliness token of the carrier
    marsupial/<pair>/passenger/state    PassengerStatus (JSON)
    marsupial/<pair>/passenger/phase    the phase alone, UTF-8 text (for humans and tools)
    marsupial/<pair>/passenger/alive    liveliness token of the passenger

Receiving (:class:`CarrierFeed`, :class:`PassengerFeed`): a callback on Zenoh's thread checks
the payload size before anything else (:data:`MAX_PAYLOAD_BYTES`, drop reason "size": a 10 MB
sample costs a length read, not a copy and a parse), decodes and validates each sample, stamps
its receive time with the injected clock and keeps only the newest accepted one under a lock
(it never blocks and never calls Zenoh). A rejected sample is dropped and counted per reason
(``feed.counters``), never a crash and never returned.

- :class:`CarrierFeed` binds to one source and gates every state against the carrier's own
  limits (:mod:`mission.bus.gate`: source binding, sequence/stamp/position/velocity
  plausibility, resynchronisation); samples from other sources are counted per source.
- :class:`PassengerFeed`: samples must be newer than the last accepted one from the same key: a
  strictly greater sequence number and a stamp not older ("stale_seq", "stale_stamp").

When the sender's liveliness token goes away the ordering (and the carrier feed's binding) is
forgotten, so a restarted sender that counts from 0 again, from a new Zenoh session, is accepted.
Publishers put their Zenoh entity id and a sequence number in each sample's ``source_info``.

Staleness: ``latest()`` always returns the newest accepted state with its age on the local clock
(``age_s``) and ``stale = age_s > max_age_s``; it does not hide old data. The controller decides
what a stale or vanished carrier means (its failsafe), using ``age_s``, ``stale`` and ``alive``.
"""
from mission.bus.feeds import (
    MAX_PAYLOAD_BYTES,
    CarrierFeed,
    PassengerFeed,
    Received,
    ReceivedCarrierState,
    ReceivedPassengerStatus,
)
from mission.bus.publishers import CarrierPublisher, PassengerPublisher
from mission.bus.session import Encoding, Keys, declare, describe_endpoints, keys, open_session, undeclare, zenoh_config

__all__ = [
    "MAX_PAYLOAD_BYTES", "CarrierFeed", "CarrierPublisher", "Encoding", "Keys", "PassengerFeed", "PassengerPublisher",
    "Received", "ReceivedCarrierState", "ReceivedPassengerStatus", "declare", "describe_endpoints", "keys",
    "open_session", "undeclare", "zenoh_config",
]
