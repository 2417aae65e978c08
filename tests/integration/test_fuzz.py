"""Fuzzing: random and mutated MAVLink frames into the mock vehicle's and the controller link's
UDP sockets, malformed Zenoh payloads into the carrier feed over a real Zenoh session.

No crash, every bad input counted (the counters account for every datagram or sample sent), and
the component still works afterwards. Seeded, so a failure reproduces. Budget: ~10^5 frames
into each MAVLink component and ~10^4 payloads into the bridge in ~20 s;
``MARSUPIAL_FUZZ_SCALE=N`` multiplies the counts.
"""
from __future__ import annotations

import itertools
import json
import math
import os
import random
import socket
import struct
import threading
from collections import Counter
from collections.abc import Callable, Iterator

import pytest

from mission.mavlink import px4
from mission.bus.bridge import CarrierFeed, keys
from mission.time.clock import ManualClock, ScaledClock
from mission.mavlink.link import VehicleLink
from mission.mavlink.env import mavlink
from mission.bus.wire import CarrierState, encode_carrier_json
from mission.bus.ros2 import encode_odometry_cdr
from sim.vehicle.mock import MockVehicle, VehicleOptions
from sim.testing.probe import Probe
from tests.support.zenoh_util import LENIENT, peer_pair, wait_for, wait_matched

SCALE = max(1, int(os.environ.get("MARSUPIAL_FUZZ_SCALE", "1")))
MAVLINK_FRAMES = 100_000 * SCALE
ZENOH_PAYLOADS = 10_000 * SCALE
# datagrams in flight at most: loopback UDP drops nothing below the receiver's socket buffer
# (1 MiB on the mock vehicle, the system default ~200 KiB on the controller's link)
VEHICLE_BATCH, LINK_BATCH = 500, 120

pytestmark = pytest.mark.timeout(120 * SCALE)

# --------------------------------------------------------------------------------------------- MAVLink corpus

_MESSAGE_IDS = sorted(mavlink.mavlink_map)


def _valid_frames(sysid: int, compid: int) -> list[bytes]:
    """Valid frames of the messages both ends handle, to mutate."""
    codec = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    msgs = [
        mavlink.MAVLink_heartbeat_message(2, 12, 29, px4.custom_mode_of("AUTO.LOITER"), 3, 3),
        mavlink.MAVLink_command_long_message(1, 1, px4.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0),
        mavlink.MAVLink_command_long_message(1, 1, px4.MAV_CMD_DO_SET_MODE, 0, 1, 6, 0, 0, 0, 0, 0),
        mavlink.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, 3527, 0, 0, 0, 1, 2, 3, 0, 0, 0, 0, 0),
        mavlink.MAVLink_param_set_message(1, 1, b"COM_OF_LOSS_T", 1.0, 9),
        mavlink.MAVLink_local_position_ned_message(1000, 1.0, 2.0, -3.0, 0.1, 0.2, 0.3),
        mavlink.MAVLink_command_ack_message(400, 0, 0, 0, 1, 191),
        mavlink.MAVLink_statustext_message(4, b"Preflight Fail: fuzz", 0, 0),
        mavlink.MAVLink_sys_status_message(1, 1, 1, 0, 0, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0, 0),
        mavlink.MAVLink_timesync_message(0, 12345),
    ]
    out = []
    for m in msgs:
        out.append(bytes(m.pack(codec)))
        codec.seq = (codec.seq + 1) % 256
    return out


def _garbage_valid_crc(rng: random.Random) -> bytes:
    """A MAVLink 2 frame of a random dialect message with random fields and a correct CRC."""
    msg_id = rng.choice(_MESSAGE_IDS)
    cls = mavlink.mavlink_map[msg_id]
    payload = bytes(rng.getrandbits(8) for _ in range(rng.randint(1, cls.unpacker.size)))
    header = struct.pack("<BBBBBBBHB", 253, len(payload), 0, 0, rng.getrandbits(8), rng.randint(1, 255),
                         rng.randint(0, 255), msg_id & 0xFFFF, msg_id >> 16)
    crc = mavlink.x25crc(header[1:] + payload)
    crc.accumulate(bytes([cls.crc_extra]))
    return header + payload + struct.pack("<H", crc.crc)


def mavlink_corpus(seed: int, count: int, sysid: int, compid: int) -> Iterator[tuple[str, bytes]]:
    """``count`` (kind, datagram) pairs; every kind but ``garbage_valid_crc`` is malformed."""
    rng = random.Random(seed)
    frames = _valid_frames(sysid, compid)

    def flip(f: bytes) -> bytes:
        b = bytearray(f)
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        return bytes(b)

    def length_lie(f: bytes) -> bytes:
        b = bytearray(f)
        b[1] = (b[1] + rng.randint(1, 255)) % 256
        return bytes(b)

    def bad_crc(f: bytes) -> bytes:
        b = bytearray(f)
        b[-rng.randint(1, 2)] ^= rng.randint(1, 255)
        return bytes(b)

    def random_id(f: bytes) -> bytes:
        b = bytearray(f)
        b[7:10] = rng.randrange(1 << 24).to_bytes(3, "little")
        return bytes(b)

    mutators: dict[str, Callable[[bytes], bytes]] = {
        "bit_flips": flip,
        "truncated": lambda f: f[: rng.randint(1, len(f) - 1)],
        "length_lie": length_lie,
        "bad_crc": bad_crc,
        "random_id": random_id,
    }
    kinds = ["random_bytes", *mutators, "garbage_valid_crc"]
    for _ in range(count):
        kind = rng.choice(kinds)
        if kind == "random_bytes":
            data = bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 280)))
        elif kind == "garbage_valid_crc":
            data = _garbage_valid_crc(rng)
        else:
            data = mutators[kind](rng.choice(frames))
        yield kind, data


def _pump(send: Callable[[bytes], None], corpus: Iterator[tuple[str, bytes]], caught_up: Callable[[int], bool],
          batch_size: int) -> Counter[str]:
    """Send the corpus in batches, waiting after each until the receiver has taken all of it."""
    kinds: Counter[str] = Counter()
    batch: list[bytes] = []
    sent = 0

    def flush() -> None:
        nonlocal sent
        for data in batch:
            send(data)
        sent += len(batch)
        batch.clear()
        wait_for(lambda: caught_up(sent), 20.0, f"receiver caught up with {sent} datagrams")

    for kind, data in corpus:
        kinds[kind] += 1
        batch.append(data)
        if len(batch) == batch_size:
            flush()
    flush()
    return kinds


# --------------------------------------------------------------------------------------------- the mock vehicle

VEHICLE_CLASSES = ("rx_messages", "rx_malformed", "rx_unknown_ids", "rx_unsigned_rejected")


def test_mock_vehicle_survives_mutated_and_random_frames_and_counts_them() -> None:
    with Probe() as probe, MockVehicle(VehicleOptions(bind="127.0.0.1:0", target=f"127.0.0.1:{probe.port}")) as v:
        wait_for(lambda: probe.wait_for("HEARTBEAT", timeout_s=5.0), 6.0, "vehicle HEARTBEAT")
        before = v.counters
        per_kind: dict[str, dict[str, int]] = {}
        total: Counter[str] = Counter()
        # one kind at a time, so each kind's counts can be checked on their own
        corpus = list(mavlink_corpus(1, MAVLINK_FRAMES, 255, 190))
        for kind in sorted({k for k, _ in corpus}):
            start = v.counters
            subset = [(k, d) for k, d in corpus if k == kind]
            n = _pump(probe.send_raw, iter(subset), lambda sent: v.counters["rx_datagrams"] - start["rx_datagrams"] >= sent, VEHICLE_BATCH)[kind]
            end = v.counters
            per_kind[kind] = {c: end[c] - start[c] for c in (*VEHICLE_CLASSES, "rx_datagrams")}
            assert per_kind[kind]["rx_datagrams"] == n  # every datagram reached the parser
            total[kind] = n
        after = v.counters
        assert after["internal_errors"] == before["internal_errors"] == 0
        assert after["rx_datagrams"] - before["rx_datagrams"] == len(corpus) >= 100_000
        for kind, d in per_kind.items():
            # every datagram is counted at least once in a class (one datagram may hold several)
            assert sum(d[c] for c in VEHICLE_CLASSES) >= total[kind], (kind, d)
            if kind in ("truncated", "bad_crc", "length_lie"):
                assert d["rx_messages"] == 0 and d["rx_malformed"] >= total[kind], (kind, d)
            if kind == "random_id":
                assert d["rx_messages"] + d["rx_unknown_ids"] + d["rx_malformed"] >= total[kind]
        # still alive and answering a command, and still streaming
        mark = probe.mark()
        ack = probe.command(px4.MAV_CMD_REQUEST_MESSAGE, (float(mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION),))
        assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED
        assert probe.wait_for("HEARTBEAT", timeout_s=3.0, after=mark) is not None


# --------------------------------------------------------------------------------------------- the controller link

LINK_CLASSES = ("rx_messages", "rx_bad")


def test_controller_link_survives_mutated_and_random_frames_and_counts_them() -> None:
    with VehicleLink("udpin:127.0.0.1:0", ScaledClock(1.0), target_system=1) as link, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as vehicle:
        vehicle.bind(("127.0.0.1", 0))
        to_link = ("127.0.0.1", link.port)
        codec = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)

        def send_msg(msg: object) -> None:
            vehicle.sendto(bytes(msg.pack(codec)), to_link)  # type: ignore[attr-defined]
            codec.seq = (codec.seq + 1) % 256

        send_msg(mavlink.MAVLink_heartbeat_message(2, 12, 29, px4.custom_mode_of("AUTO.LOITER"), 3, 3))
        link.wait_vehicle(5.0)
        corpus = list(mavlink_corpus(2, MAVLINK_FRAMES, 1, 1))
        per_kind: dict[str, dict[str, int]] = {}
        for kind in sorted({k for k, _ in corpus}):
            subset = [d for k, d in corpus if k == kind]
            start = link.counters
            cumulative = [0, *itertools.accumulate(len(d) for d in subset)]
            size = cumulative[-1]
            _pump(lambda d: vehicle.sendto(d, to_link), iter((kind, d) for d in subset),
                  lambda sent: link.counters.rx_bytes - start.rx_bytes >= cumulative[sent], LINK_BATCH)
            end = link.counters
            assert end.rx_bytes - start.rx_bytes == size  # every byte reached the parser
            per_kind[kind] = {c: getattr(end, c) - getattr(start, c) for c in (*LINK_CLASSES, "rx_unknown", "rx_errors")}
            assert sum(per_kind[kind][c] for c in LINK_CLASSES) >= len(subset), (kind, per_kind[kind])
            if kind in ("truncated", "bad_crc", "length_lie"):
                assert per_kind[kind]["rx_messages"] == 0 and per_kind[kind]["rx_bad"] >= len(subset), (kind, per_kind[kind])
        c = link.counters
        assert c.rx_errors == 0 and len(corpus) >= 100_000
        assert c.rejected_foreign > 0  # garbage from other systems was refused, not applied
        # still decoding: a valid HEARTBEAT and position from the vehicle are applied
        send_msg(mavlink.MAVLink_heartbeat_message(2, 12, 157, px4.custom_mode_of("OFFBOARD"), 4, 3))
        send_msg(mavlink.MAVLink_local_position_ned_message(1, 7.0, 8.0, -9.0, 0.0, 0.0, 0.0))
        state = link.wait_until(lambda s: s.mode == "OFFBOARD" and s.position_ned_m is not None
                                and s.position_ned_m.tolist() == [7.0, 8.0, -9.0], 5.0)
        assert state.system_id == 1 and state.armed
        assert all(t.is_alive() for t in threading.enumerate() if t.name.startswith("marsupial-link-rx"))


# --------------------------------------------------------------------------------------------- Zenoh payloads


def _valid(seq: object, stamp: float | None = None, **over: object) -> dict[str, object]:
    d: dict[str, object] = {"stamp": (float(seq) if isinstance(seq, int) else 2000.0) if stamp is None else stamp, "seq": seq, "frame": "local_ned",
                            "position": [1.0, 2.0, 0.0], "velocity": [0.5, 0.0, 0.0], "yaw": 0.1}
    d.update(over)
    return d


def _without(d: dict[str, object], key: str) -> dict[str, object]:
    return {k: v for k, v in d.items() if k != key}


def zenoh_corpus(seed: int, count: int, last_seq: int) -> Iterator[tuple[str, bytes]]:
    """(expected drop reason, payload) for a feed whose last accepted seq and stamp are ``last_seq``."""
    rng = random.Random(seed)
    good = encode_carrier_json(CarrierState(5.0, 5, "local_ned", [1.0, 2.0, 0.0], [0.5, 0.0, 0.0], 0.1))
    nxt = last_seq + 1
    bad_numbers = [float("nan"), float("inf"), -float("inf")]

    def dumps(d: dict[str, object]) -> bytes:
        return json.dumps(d).encode()  # NaN / Infinity literals allowed, as a sloppy sender writes them

    makers: list[Callable[[], tuple[str, bytes]]] = [
        lambda: ("decode", bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 200))) + b"\xff"),
        lambda: ("decode", good[: rng.randint(0, len(good) - 1)]),
        lambda: ("decode", rng.choice([b"[]", b"1", b'"x"', b"null", b"{", b"{}}", b"\xef\xbb\xbf{}"])),
        lambda: ("nonfinite", dumps(_valid(nxt, **{rng.choice(["position", "velocity"]):
                                                   [rng.choice(bad_numbers), 0.0, 0.0]}))),
        lambda: ("nonfinite", dumps(_valid(nxt, stamp=rng.choice(bad_numbers)))),
        lambda: ("nonfinite", dumps(_valid(nxt, yaw=rng.choice(bad_numbers)))),
        lambda: ("nonfinite", f'{{"stamp": 1e{rng.randint(309, 999)}, "seq": {nxt}, "frame": "local_ned", '
                              f'"position": [0, 0, 0], "velocity": [0, 0, 0]}}'.encode()),
        lambda: ("nonfinite", dumps(_valid(nxt, position=[10 ** rng.randint(309, 400), 0, 0]))),
        lambda: ("range", dumps(_valid(nxt, position=[rng.choice([-1, 1]) * 10.0 ** rng.uniform(7.1, 308), 0.0, 0.0]))),
        lambda: ("range", dumps(_valid(nxt, velocity=[0.0, 10.0 ** rng.uniform(3.1, 308), 0.0]))),
        lambda: ("range", dumps(_valid(2 ** rng.randint(63, 200)))),
        lambda: ("range", dumps(_valid(-rng.randint(1, 10 ** 6)))),
        lambda: ("type", dumps(_valid(nxt, **{rng.choice(["position", "velocity"]):
                                              rng.choice(["abc", {"x": 1}, 3.0, None, [True, 0, 0], ["1", 0, 0]])}))),
        lambda: ("type", dumps(_valid(rng.choice([1.5, "7", None, [1], True])))),
        lambda: ("type", dumps(_valid(nxt, stamp=rng.choice(["now", [1.0], False, {"s": 1}])))),
        lambda: ("type", dumps(_valid(nxt, frame=rng.choice([1, None, ["local_ned"], {"f": 1}])))),
        lambda: ("shape", dumps(_valid(nxt, position=[0.0] * rng.choice([0, 1, 2, 4, 9])))),
        lambda: ("missing", dumps(_without(_valid(nxt), rng.choice(["stamp", "seq", "frame", "position", "velocity"])))),
        lambda: ("frame", dumps(_valid(nxt, frame=rng.choice(["ecef", "enu", "", "LOCAL_NED", "wgs"])))),
        lambda: ("stale_seq", dumps(_valid(rng.randint(0, last_seq)))),
        lambda: ("stale_stamp", dumps(_valid(last_seq + rng.randint(1, 1000), stamp=last_seq - rng.uniform(0.1, 1e6)))),
    ]
    for _ in range(count):
        yield rng.choice(makers)()


def test_carrier_feed_drops_and_counts_every_malformed_payload() -> None:
    with peer_pair() as (a, b), CarrierFeed(b, "fz", ManualClock(), limits=LENIENT) as feed, \
            CarrierFeed(b, "fz", ManualClock(), encoding="cdr", key="fz/odom", limits=LENIENT) as cdr_feed:
        import zenoh

        pub = a.declare_publisher(keys("fz").carrier_state, congestion_control=zenoh.CongestionControl.BLOCK)
        cdr_pub = a.declare_publisher("fz/odom", congestion_control=zenoh.CongestionControl.BLOCK)
        try:
            wait_matched(pub)
            wait_matched(cdr_pub)
            last_seq = 1000
            pub.put(json.dumps(_valid(last_seq)).encode())
            wait_for(feed.latest, what="first valid state")
            expected: Counter[str] = Counter()
            sent = 1
            for i, (reason, payload) in enumerate(zenoh_corpus(3, ZENOH_PAYLOADS, last_seq)):
                pub.put(payload)
                expected[reason] += 1
                sent += 1
                if i % 2000 == 1999:  # latest() is never a bad sample, at any moment
                    rx = feed.latest()
                    assert rx is not None and rx.state.seq == last_seq and rx.state.position.tolist() == [1.0, 2.0, 0.0]
            wait_for(lambda: feed.counters["received"] == sent, 20.0, "every payload received")
            c = feed.counters
            assert c["dropped"] == dict(expected)  # each bad payload counted under its own reason
            assert c["accepted"] == 1 and c["accepted"] + sum(c["dropped"].values()) == c["received"]
            assert feed.latest().state.seq == last_seq  # type: ignore[union-attr]
            # still works: the next valid state goes through
            pub.put(json.dumps(_valid(last_seq + 1)).encode())
            wait_for(lambda: feed.latest().state.seq == last_seq + 1, what="a valid state after the fuzz")  # type: ignore[union-attr]

            # CDR (ROS 2 Odometry): random and truncated buffers; a mutated one may decode to a
            # valid state, but never to a non-finite or unvalidated one.
            rng = random.Random(4)
            good = encode_odometry_cdr(CarrierState(3.0, 0, "local_ned", [1.0, 2.0, 0.0], [0.0, 0.0, 0.0], 0.5))
            n_cdr = ZENOH_PAYLOADS // 5
            for _ in range(n_cdr):
                kind = rng.randrange(3)
                if kind == 0:
                    payload = bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 400)))
                elif kind == 1:
                    payload = good[: rng.randint(0, len(good) - 1)]
                else:
                    b_ = bytearray(good)
                    b_[rng.randrange(len(b_))] ^= 1 << rng.randrange(8)
                    payload = bytes(b_)
                cdr_pub.put(payload)
            wait_for(lambda: cdr_feed.counters["received"] == n_cdr, 20.0, "every CDR payload received")
            cc = cdr_feed.counters
            assert cc["accepted"] + sum(cc["dropped"].values()) == n_cdr and cc["dropped"].get("decode", 0) > n_cdr // 2
            assert "internal" not in cc["dropped"] and "internal" not in c["dropped"]
            rx = cdr_feed.latest()
            if rx is not None:
                st = rx.state
                assert all(math.isfinite(x) for x in [*st.position, *st.velocity_ned_m_s, st.stamp_s])
        finally:
            pub.undeclare()
            cdr_pub.undeclare()
