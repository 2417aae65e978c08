"""Zenoh I/O between the carrier and the passenger (thin: knows nothing of the law).

The bus's public face, re-exporting :mod:`mission.bus.session` (sessions, keys),
:mod:`mission.bus.feeds` (receiving) and :mod:`mission.bus.publishers` (publishing). Key
expressions are namespaced per marsupial pair (:func:`keys`)::

    marsupial/<pair>/carrier/state      CarrierState (JSON, or CDR Odometry with --encoding cdr)
    marsupial/<pair>/carrier/alive      liveliness token of the carrier
    marsupial/<pair>/passenger/state    PassengerStatus (JSON)
    marsupial/<pair>/passenger/phase    the phase alone, UTF-8 text (for humans and tools)
    marsupial/<pair>/passenger/alive    liveliness token of the passenger
    marsupial/<pair>/passenger/<name>/{state,phase,alive}   a team's passenger ``name``, on its own keys
    marsupial/<pair>/passenger/camera   camera frames for the marker feed (:mod:`mission.bus.frames`)

What a feed accepts, drops and counts, and how staleness is reported: docs/wire.md; signed
samples (``zenoh.signing_key_file``, :mod:`mission.bus.signing`): docs/security.md.
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
