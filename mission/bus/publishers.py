"""Publishing on the bus: the carrier's state, the passenger's status and phase, and each
side's liveliness token (thin I/O). Key expressions: :mod:`mission.bus.bridge`."""
from __future__ import annotations

from typing import Any

import zenoh

from mission.bus.auth import BusAuth
from mission.errors import BusError
from mission.bus.encodings import encode_carrier
from mission.bus.wire import CarrierState, PassengerStatus, encode_passenger_json
from mission.bus.session import ZENOH_ENCODING, Encoding, check_encoding, declare, keys, undeclare


class _Publisher:
    """A state publisher (``matched`` says whether anyone listens), maybe more publishers, and one
    liveliness token; closing undeclares them all (idempotent).

    States are streams where the newest wins: puts are express (not batched) and use congestion
    control DROP, so a congested link drops a sample instead of stalling the sender's loop (BLOCK
    in lockstep, ``congestion_control``: :func:`mission.bus.session.congestion_for`).
    Publish at a steady rate, not only on change: a receiver treats silence as loss.
    """

    def __init__(self, session: zenoh.Session, alive_key: str, state_key: str, state_encoding: zenoh.Encoding,
                 congestion_control: zenoh.CongestionControl = zenoh.CongestionControl.DROP,
                 auth: BusAuth | None = None) -> None:
        self._session, self._congestion = session, congestion_control
        self._signer = auth.signer() if auth is not None else None
        self._entities: list[Any] = []
        self._closed = False
        self._sn = 0
        self._token = declare(f"liveliness token {alive_key}", lambda: session.liveliness().declare_token(alive_key))
        self._entities.append(self._token)
        self._state = self._publisher(state_key, state_encoding)

    def _publisher(self, key: str, encoding: zenoh.Encoding) -> zenoh.Publisher:
        """Declare a publisher on ``key``; if Zenoh refuses, undeclare everything and raise."""
        try:
            pub = declare(f"publisher on {key}", lambda: self._session.declare_publisher(
                key, encoding=encoding, congestion_control=self._congestion, express=True))
        except BusError:
            self.close()
            raise
        self._entities.append(pub)
        return pub

    @property
    def congestion_control(self) -> zenoh.CongestionControl:
        """What a put does on a congested link: DROP the sample, or BLOCK until it is sent."""
        return self._congestion

    @property
    def matched(self) -> bool:
        """True when a subscriber somewhere matches the state key (a put would be delivered)."""
        return bool(self._state.matching_status.matching)  # type: ignore[attr-defined]  # stubs: bool

    def _put(self, pub: zenoh.Publisher, payload: bytes) -> None:
        """Put with our identity in ``source_info`` (the receiver binds to it)."""
        self._sn += 1
        attachment = None if self._signer is None else self._signer.attachment(str(pub.key_expr), payload)
        try:
            pub.put(payload, source_info=zenoh.SourceInfo(pub.id, self._sn), attachment=attachment)
        except zenoh.ZError as exc:
            raise BusError(f"cannot publish on {pub.key_expr}: {exc}") from None

    def close(self) -> None:
        """Undeclare the publishers and the liveliness token (idempotent)."""
        if self._closed:
            return
        self._closed = True
        undeclare(*reversed(self._entities))

    def __enter__(self) -> "_Publisher":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class CarrierPublisher(_Publisher):
    """Publishes the carrier's state on pair ``pair`` and holds the carrier's liveliness token.

    encoding "json" or "cdr" (Odometry, ENU, twist in ``base_link``); key overrides the state key;
    auth: the pair's signing key (:func:`mission.bus.auth.bus_auth`): every sample carries its tag.
    """

    def __init__(self, session: zenoh.Session, pair: str, encoding: Encoding = "json", *, key: str | None = None,
                 congestion_control: zenoh.CongestionControl = zenoh.CongestionControl.DROP,
                 auth: BusAuth | None = None) -> None:
        check_encoding(encoding)
        k = keys(pair)
        self.encoding = encoding
        self.key = key or k.carrier_state
        super().__init__(session, k.carrier_alive, self.key, ZENOH_ENCODING[encoding], congestion_control, auth)

    def publish(self, state: CarrierState) -> None:
        """Send ``state``; raises :class:`BusError` if Zenoh refuses."""
        self._put(self._state, encode_carrier(state, self.encoding))


class PassengerPublisher(_Publisher):
    """Publishes the passenger's status (state key, JSON) and phase (phase key, text) on pair
    ``pair`` and holds the passenger's liveliness token; signed with ``auth`` if given;
    ``passenger``: the name of one passenger of a team, on its own keys (None: the pair's)."""

    def __init__(self, session: zenoh.Session, pair: str,
                 congestion_control: zenoh.CongestionControl = zenoh.CongestionControl.DROP,
                 auth: BusAuth | None = None, passenger: str | None = None) -> None:
        k = keys(pair, passenger)
        super().__init__(session, k.passenger_alive, k.passenger_state, zenoh.Encoding.APPLICATION_JSON,
                         congestion_control, auth)
        self.last_seq = -1  # seq of the last status sent
        self._phase = self._publisher(k.passenger_phase, zenoh.Encoding.TEXT_PLAIN)

    def publish(self, status: PassengerStatus) -> None:
        """Send ``status`` on the state key and its phase on the phase key."""
        self._put(self._state, encode_passenger_json(status))
        self.last_seq = status.seq
        self._put(self._phase, status.phase.encode())
