"""pymavlink codecs as both ends of our links use them: robust parsing, one datagram at a time,
and MAVLink 2 signing."""
from __future__ import annotations

import time
from collections.abc import Collection
from typing import Any

from mission.mavlink.env import mavlink

SIGNING_EPOCH_S = 1420070400  # 2015-01-01T00:00:00Z, the MAVLink 2 signing epoch


def new_codec(source_system: int, source_component: int) -> Any:
    """A pymavlink MAVLink 2 encoder/decoder (our dialect) with robust parsing."""
    codec = mavlink.MAVLink(None, srcSystem=source_system, srcComponent=source_component)
    codec.robust_parsing = True
    return codec


def reset_parser(codec: Any) -> int:
    """Drop a partial packet left in the parser (a datagram never continues in the next);
    returns how many bytes were dropped."""
    leftover = len(codec.buf) - codec.buf_index
    codec.buf = bytearray()
    codec.buf_index = 0
    codec.expected_length = mavlink.HEADER_LEN_V1 + 2
    return leftover


def signing_timestamp_now() -> int:
    """MAVLink 2 signing timestamp: 10 us units since 2015-01-01 UTC (a calendar value by spec)."""
    return int((time.time_ns() / 1e9 - SIGNING_EPOCH_S) * 1e5)


def setup_signing(codec: Any, key: bytes, *, sign_outgoing: bool, unsigned_ids: Collection[int],
                  link_id: int = 0) -> None:
    """Sign (``sign_outgoing``, as ``link_id``) and check with the 32-byte ``key``; packets with a
    message id in ``unsigned_ids`` may arrive unsigned."""
    allowed = frozenset(unsigned_ids)

    def allow_unsigned(_codec: Any, msg_id: int) -> bool:
        return msg_id in allowed

    signing = codec.signing
    signing.secret_key = bytes(key)
    signing.sign_outgoing = sign_outgoing
    signing.allow_unsigned_callback = allow_unsigned
    signing.link_id = link_id
    signing.timestamp = signing_timestamp_now()


def keep_replay_state_on_failure(codec: Any) -> None:
    """Make ``codec``'s signature check leave its per-stream replay timestamp alone when the
    check fails (pymavlink stores a packet's timestamp before verifying its signature, so one
    forged packet stamped in the future would lock the real vehicle out)."""
    check = codec.check_signature

    def check_signature(msgbuf: bytearray, src_system: int, src_component: int) -> bool:
        streams = codec.signing.stream_timestamps
        stream = (msgbuf[-13], src_system, src_component)
        before = streams.get(stream)
        ok = bool(check(msgbuf, src_system, src_component))
        if not ok:
            if before is None:
                streams.pop(stream, None)
            else:
                streams[stream] = before
        return ok

    codec.check_signature = check_signature


def link_codecs(source: tuple[int, int], signing_key: bytes | None) -> tuple[Any, Any]:
    """``(rx, tx)`` codecs of our end of a link as ``source`` (system, component). With a
    ``signing_key`` outgoing packets are signed and every incoming one must be, HEARTBEAT
    included; a refused packet never advances the replay state (:func:`keep_replay_state_on_failure`)."""
    rx, tx = new_codec(*source), new_codec(*source)
    if signing_key is not None:
        for codec, outgoing in ((rx, False), (tx, True)):
            setup_signing(codec, signing_key, sign_outgoing=outgoing, unsigned_ids=())
        keep_replay_state_on_failure(rx)
    return rx, tx
