"""Bus sample tags (pure): what verifies, what is refused and why, per-pair keys, replays."""
from __future__ import annotations

import pytest

from mission.bus.signing import MAX_SIGNERS, TRAILER_BYTES, Signer, Verifier, pair_key
from mission.bus.wire import WireError

KEY = pair_key(bytes(range(32)), "pair0")
STATE = "marsupial/pair0/carrier/state"
NOW = 1_800_000_000_000_000  # [us] since the Unix epoch


def reason(verifier: Verifier, key_expr: str, payload: bytes, attachment: bytes | None, now: int = NOW) -> str:
    with pytest.raises(WireError) as err:
        verifier.verify(key_expr, payload, attachment, now)
    return err.value.reason


def test_a_signed_sample_verifies_once_and_names_its_signer() -> None:
    signer, verifier = Signer(KEY), Verifier(KEY)
    tag = signer.attachment(STATE, b"{}", NOW)
    assert len(tag) == TRAILER_BYTES
    assert verifier.verify(STATE, b"{}", tag, NOW) == (signer.source, b"")
    assert reason(verifier, STATE, b"{}", tag) == "replay"  # the same sample again
    # counters are strictly increasing even when the wall clock stands still or steps back
    later = [signer.attachment(STATE, b"{}", NOW - 5) for _ in range(3)]
    assert [verifier.verify(STATE, b"{}", t, NOW)[0] for t in later] == [signer.source] * 3


def test_an_inner_attachment_travels_before_the_tag_and_is_covered_by_it() -> None:
    signer, verifier = Signer(KEY), Verifier(KEY)
    tag = signer.attachment("0/cmd_vel/x", b"twist", NOW, inner=b"rmw-attachment")
    assert verifier.verify("0/cmd_vel/x", b"twist", tag, NOW) == (signer.source, b"rmw-attachment")
    forged = b"rmw-attachmenX" + tag[len(b"rmw-attachment"):]
    assert reason(Verifier(KEY), "0/cmd_vel/x", b"twist", forged) == "signature"


@pytest.mark.parametrize("what", ["payload", "key expression", "counter", "signer", "other pair", "other key"])
def test_any_change_breaks_the_tag(what: str) -> None:
    signer = Signer(KEY)
    tag = bytearray(signer.attachment(STATE, b'{"seq": 1}', NOW))
    payload, key_expr, key = b'{"seq": 1}', STATE, KEY
    if what == "payload":
        payload = b'{"seq": 2}'
    elif what == "key expression":
        key_expr = "marsupial/pair0/passenger/state"
    elif what == "counter":
        tag[12 + 7] ^= 1
    elif what == "signer":
        tag[4] ^= 1
    elif what == "other pair":
        key = pair_key(bytes(range(32)), "pair1")
    else:
        key = pair_key(bytes(32), "pair0")
    assert reason(Verifier(key), key_expr, payload, bytes(tag)) == "signature"


def test_unsigned_and_foreign_attachments_are_unsigned() -> None:
    verifier = Verifier(KEY)
    assert reason(verifier, STATE, b"{}", None) == "unsigned"
    assert reason(verifier, STATE, b"{}", b"") == "unsigned"
    assert reason(verifier, STATE, b"{}", b"x" * 100) == "unsigned"  # an rmw_zenoh attachment alone


def test_a_new_signer_outside_the_replay_window_is_refused() -> None:
    old = Signer(KEY).attachment(STATE, b"{}", NOW - 61_000_000)  # recorded 61 s ago
    assert reason(Verifier(KEY), STATE, b"{}", old) == "replay"
    ahead = Signer(KEY).attachment(STATE, b"{}", NOW + 61_000_000)  # a clock a minute ahead
    assert reason(Verifier(KEY), STATE, b"{}", ahead) == "replay"
    recent = Signer(KEY).attachment(STATE, b"{}", NOW - 59_000_000)
    assert Verifier(KEY).verify(STATE, b"{}", recent, NOW)


def test_each_signer_has_its_own_sequence_and_the_memory_is_bounded() -> None:
    a, b, verifier = Signer(KEY), Signer(KEY), Verifier(KEY)
    tag_a = a.attachment(STATE, b"a", NOW + 10)
    tag_b = b.attachment(STATE, b"b", NOW)  # b's counter is lower than a's: still its own, accepted
    assert verifier.verify(STATE, b"a", tag_a, NOW)[0] == a.source
    assert verifier.verify(STATE, b"b", tag_b, NOW)[0] == b.source
    for _ in range(MAX_SIGNERS + 5):  # many signers (key holders only): the oldest is forgotten
        verifier.verify(STATE, b"c", Signer(KEY).attachment(STATE, b"c", NOW), NOW)
    assert len(verifier.streams._streams) == MAX_SIGNERS


def test_pair_keys_differ_and_a_key_has_32_bytes() -> None:
    assert pair_key(bytes(32), "pair0") != pair_key(bytes(32), "pair1") and len(KEY) == 32
    with pytest.raises(ValueError):
        pair_key(b"short", "pair0")


def test_a_counter_far_ahead_of_its_stream_is_a_contest_and_the_stream_is_refused_for_good() -> None:
    """An insider with the key signing under the real signer id 50 s ahead: on main the real
    stream was then dropped as ``replay``, silently. Now the forgery is a contest, and so is every
    later sample of that signer, the real ones too."""
    real, verifier = Signer(KEY), Verifier(KEY)
    for k in range(5):
        verifier.verify(STATE, b"{}", real.attachment(STATE, b"{}", NOW + k * 33_000), NOW + k * 33_000)
    insider = Signer(KEY, signer=real.signer)
    assert reason(verifier, STATE, b"x", insider.attachment(STATE, b"x", NOW + 50_000_000), NOW + 200_000) == "contest"
    assert reason(verifier, STATE, b"{}", real.attachment(STATE, b"{}", NOW + 233_000), NOW + 233_000) == "contest"
    assert verifier.streams.contested(real.signer) and verifier.streams.contests == 1


def test_a_second_signer_just_ahead_is_a_contest_once_the_real_stream_is_heard_behind_it() -> None:
    real, verifier = Signer(KEY), Verifier(KEY)
    verifier.verify(STATE, b"{}", real.attachment(STATE, b"{}", NOW), NOW)
    insider = Signer(KEY, signer=real.signer)
    verifier.verify(STATE, b"x", insider.attachment(STATE, b"x", NOW + 1_000_000), NOW + 10_000)  # 1 s ahead: accepted
    assert reason(verifier, STATE, b"{}", real.attachment(STATE, b"{}", NOW + 40_000), NOW + 40_000) == "contest"


def test_copies_and_late_samples_are_replays_not_contests() -> None:
    signer, verifier = Signer(KEY), Verifier(KEY)
    tags = [signer.attachment(STATE, b"{}", NOW + k * 20_000) for k in range(10)]
    late = tags.pop(8)  # put 8 after 9: 20 ms late
    for tag in tags:
        verifier.verify(STATE, b"{}", tag, NOW + 200_000)
    assert reason(verifier, STATE, b"{}", late, NOW + 200_000) == "replay"
    assert reason(verifier, STATE, b"{}", tags[2], NOW + 5_000_000) == "replay"  # a copy, 5 s later
    assert verifier.streams.contests == 0


def test_one_key_per_robot_verifies_only_the_peer_s_signature() -> None:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    from mission.bus.signing import ED25519_TRAILER_BYTES, Ed25519Signer, Ed25519Verifier

    carrier, passenger = Ed25519PrivateKey.generate(), Ed25519PrivateKey.generate()
    verifier = Ed25519Verifier(carrier.public_key())  # the passenger's view of the carrier
    signer = Ed25519Signer(carrier)
    tag = signer.attachment(STATE, b"{}", NOW, inner=b"rmw")
    assert len(tag) == 3 + ED25519_TRAILER_BYTES and verifier.verify(STATE, b"{}", tag, NOW) == (signer.source, b"rmw")
    as_carrier = Ed25519Signer(passenger, signer=signer.signer).attachment(STATE, b"{}", NOW + 1)
    assert reason(verifier, STATE, b"{}", as_carrier) == "signature"  # the passenger's key cannot speak for it
    assert reason(verifier, STATE, b"{}", Signer(KEY).attachment(STATE, b"{}", NOW)) == "unsigned"  # a shared-key tag
    assert reason(Verifier(KEY), STATE, b"{}", tag) == "unsigned"


def test_a_stream_first_heard_on_an_old_copy_is_not_contested_by_its_real_samples() -> None:
    """A keyless replayer puts a 30 s old sample of the real signer before the verifier has heard
    it: the real samples that follow are not 'ahead of their stream'."""
    real, verifier = Signer(KEY), Verifier(KEY)
    old = real.attachment(STATE, b"{}", NOW - 30_000_000)
    verifier.verify(STATE, b"{}", old, NOW)
    for k in range(3):
        verifier.verify(STATE, b"{}", real.attachment(STATE, b"{}", NOW + k * 33_000), NOW + k * 33_000)
    assert verifier.streams.contests == 0
