"""The MAVLink layers without sockets: URL parsing, the telemetry reducer, the STATUSTEXT
assembler, and the command state machines on a manual clock with hand-built messages."""
from __future__ import annotations

import math

import numpy as np
import pytest

from mission.mavlink import px4
from mission.time.clock import ManualClock
from mission.mavlink import telemetry
from mission.mavlink.commands import (
    AckLog,
    CommandExchange,
    Confirmed,
    HeartbeatConfirmation,
    Step,
    refusal_reason,
)
from mission.config.urls import Endpoint, parse_url
from mission.mavlink.env import mavlink

IN_PROGRESS, ACCEPTED, DENIED = mavlink.MAV_RESULT_IN_PROGRESS, mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_DENIED
SET_MODE = mavlink.MAV_CMD_DO_SET_MODE

# ------------------------------------------------------------------------------ URLs


@pytest.mark.parametrize(("url", "default", "expected"), [
    ("udpin:127.0.0.1:14540", None, Endpoint("udpin", "127.0.0.1", 14540)),
    ("udp://0.0.0.0:0", None, Endpoint("udpin", "0.0.0.0", 0)),
    ("udpout:10.0.0.2:14550", None, Endpoint("udpout", "10.0.0.2", 14550)),
    ("udpout://10.0.0.2:14550", None, Endpoint("udpout", "10.0.0.2", 14550)),
    ("tcp:127.0.0.1:5760", None, Endpoint("tcp", "127.0.0.1", 5760)),
    ("127.0.0.1:14580", "udpin", Endpoint("udpin", "127.0.0.1", 14580)),
    (":14540", "udpout", Endpoint("udpout", "127.0.0.1", 14540)),
    ("/dev/ttyACM0:921600", None, Endpoint("serial", device="/dev/ttyACM0", baud=921600)),
    ("serial:/dev/ttyUSB1", None, Endpoint("serial", device="/dev/ttyUSB1", baud=57600)),
    ("COM3,115200", None, Endpoint("serial", device="COM3", baud=115200)),
])
def test_url_forms(url, default, expected):
    assert parse_url(url, default) == expected


@pytest.mark.parametrize(("url", "message"), [
    ("udpin:nonsense", "HOST:PORT"),
    ("udpin:127.0.0.1:notaport", "not an integer"),
    ("udpout:127.0.0.1:70000", "out of range"),
    ("carrier-pigeon:1", "expected udpin"),
    ("127.0.0.1:14540", "expected udpin"),  # a bare address needs a default scheme
    ("udpin:host:port", "not an integer"),
    ("/dev/ttyACM0:fast", "baud"),
])
def test_bad_urls_name_the_problem(url, message):
    with pytest.raises(ValueError, match=message):
        parse_url(url)


# ------------------------------------------------------------------------------ telemetry

def heartbeat(mode: str, armed: bool, status: int = mavlink.MAV_STATE_ACTIVE):
    return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4,
                                             px4.base_mode_of(mode, armed), px4.custom_mode_of(mode), status, 3)


def position(x=1.0, y=2.0, z=-3.0, vx=0.1, vy=0.2, vz=0.3):
    return mavlink.MAVLink_local_position_ned_message(0, x, y, z, vx, vy, vz)


def sys_status(present: bool, enabled: bool, healthy: bool, remaining: int = -1):
    bit = mavlink.MAV_SYS_STATUS_AHRS
    return mavlink.MAVLink_sys_status_message(bit if present else 0, bit if enabled else 0, bit if healthy else 0,
                                              0, 0, -1, remaining, 0, 0, 0, 0, 0, 0)


def battery_status(battery_id: int, remaining: int):
    """As PX4 SITL's battery simulator sends it (one 4S pack, no current sensor)."""
    return mavlink.MAVLink_battery_status_message(battery_id, 1, 1, 32767, [16200] + [65535] * 9, -100, 0, -1,
                                                  remaining)


def test_reducer_reads_heartbeat_position_origin_and_landed_state():
    tm = telemetry.Telemetry()
    tm = telemetry.reduce(tm, heartbeat("OFFBOARD", True), 1.0)
    tm = telemetry.reduce(tm, position(), 1.1)
    tm = telemetry.reduce(tm, mavlink.MAVLink_gps_global_origin_message(473977418, 85455939, 488000, 0), 1.2)
    tm = telemetry.reduce(tm, mavlink.MAVLink_extended_sys_state_message(0, mavlink.MAV_LANDED_STATE_IN_AIR), 1.3)
    s = telemetry.snapshot(tm, 1.4, (1, 1), position_timeout_s=0.5)
    assert (s.mode, s.armed, s.heartbeat_rx_s, s.system_id) == ("OFFBOARD", True, 1.0, 1)
    assert s.position_ned_m.tolist() == [1.0, 2.0, -3.0] and s.velocity_ned_m_s.tolist() == pytest.approx([0.1, 0.2, 0.3])
    assert s.origin == pytest.approx((47.3977418, 8.5455939, 488.0))
    assert s.landed_state == mavlink.MAV_LANDED_STATE_IN_AIR
    assert s.position_valid and s.heartbeat_age_s == pytest.approx(0.4)
    with pytest.raises(ValueError):
        s.position_ned_m[0] = 5.0  # read-only


def test_reducer_is_pure_and_ignores_other_messages():
    before = telemetry.reduce(telemetry.Telemetry(), heartbeat("AUTO.LOITER", False), 0.0)
    after = telemetry.reduce(before, heartbeat("OFFBOARD", True), 1.0)
    assert (before.mode, before.heartbeat_rx_s) == ("AUTO.LOITER", 0.0)
    assert after.mode == "OFFBOARD"
    assert telemetry.reduce(after, mavlink.MAVLink_vfr_hud_message(0, 0, 0, 0, 0, 0), 2.0) is after
    yawed = telemetry.reduce(after, mavlink.MAVLink_attitude_message(0, 0.1, 0.2, 1.5, 0, 0, 0), 2.0)
    assert telemetry.snapshot(yawed, 2.0, None, 0.5).yaw_rad == pytest.approx(1.5)
    assert telemetry.reduce(yawed, mavlink.MAVLink_attitude_message(0, 0, 0, math.nan, 0, 0, 0), 2.1).yaw_rad is None


def test_position_validity_age_finiteness_and_estimator_health():
    tm = telemetry.reduce(telemetry.Telemetry(), position(), 1.0)
    assert telemetry.snapshot(tm, 1.5, None, 0.5).position_valid
    assert not telemetry.snapshot(tm, 1.51, None, 0.5).position_valid  # stale
    assert not telemetry.snapshot(telemetry.reduce(tm, position(x=math.nan), 1.0), 1.0, None, 0.5).position_valid
    unhealthy = telemetry.reduce(tm, sys_status(True, True, False), 1.0)
    assert not telemetry.snapshot(unhealthy, 1.0, None, 0.5).position_valid
    not_reported = telemetry.reduce(unhealthy, sys_status(True, False, False), 1.0)
    assert telemetry.snapshot(not_reported, 1.0, None, 0.5).position_valid


def test_battery_from_sys_status_and_battery_status_the_lowest_known_minus_one_unknown():
    tm = telemetry.Telemetry()
    assert telemetry.snapshot(tm, 0.0, None, 0.5).battery_pct is None
    tm = telemetry.reduce(tm, sys_status(True, True, True, remaining=-1), 1.0)  # PX4 without a battery
    assert telemetry.snapshot(tm, 1.0, None, 0.5).battery_pct is None
    tm = telemetry.reduce(tm, sys_status(True, True, True, remaining=83), 2.0)
    assert telemetry.snapshot(tm, 2.0, None, 0.5).battery_pct == 83.0
    tm = telemetry.reduce(tm, battery_status(0, 84), 2.1)  # the same pack, a moment earlier: the lowest counts
    tm = telemetry.reduce(tm, battery_status(1, 40), 2.2)  # a second pack
    assert telemetry.snapshot(tm, 2.2, None, 0.5).battery_pct == 40.0
    tm = telemetry.reduce(tm, battery_status(1, -1), 2.3)  # that pack no longer known
    tm = telemetry.reduce(tm, sys_status(True, True, True, remaining=82), 2.4)
    assert telemetry.snapshot(tm, 2.4, None, 0.5).battery_pct == 82.0


def test_home_position_read_back_in_local_ned():
    home = mavlink.MAVLink_home_position_message(473977462, 85455951, 489029, -9.99, 5.0, -0.98, [1, 0, 0, 0],
                                                 0, 0, 0, 2652000)
    tm = telemetry.reduce(telemetry.Telemetry(), home, 3.0)
    s = telemetry.snapshot(tm, 3.5, None, 0.5)
    assert s.home_ned_m.tolist() == pytest.approx([-9.99, 5.0, -0.98]) and s.home_rx_s == 3.0
    nan_home = mavlink.MAVLink_home_position_message(0, 0, 0, math.nan, 0, 0, [1, 0, 0, 0], 0, 0, 0, 0)
    assert telemetry.reduce(tm, nan_home, 4.0) is tm  # a non-finite one is not a home


def test_statustext_chunks_are_joined():
    a = telemetry.StatusTextAssembler()
    head = "Preflight Fail: " + "x" * 34
    assert len(head) == 50
    assert a.feed("single", 0, 0) == "single"
    assert a.feed(head, 7, 0) is None
    assert a.feed("tail", 7, 1) == head + "tail"
    assert a.feed("tail again", 7, 1) == "tail again"  # a finished id starts over


# ------------------------------------------------------------------------------ commands


def run_exchange(ex: CommandExchange, clock: ManualClock, acks: AckLog, answers: dict[int, list[int]], dt=0.01):
    """Drive ``ex``: after send number k, the vehicle answers ``answers[k]`` (results) at once."""
    sends = []
    while True:
        step = ex.step(clock.now(), acks)
        if step is Step.SEND:
            sends.append(ex.confirmation)
            for result in answers.get(len(sends), []):
                acks.add(clock.now(), ex.command, result)
        elif step is Step.WAIT:
            clock.advance(dt)
        else:
            return step, sends


def test_exchange_accepted_at_once():
    clock, acks = ManualClock(), AckLog()
    step, sends = run_exchange(CommandExchange(SET_MODE, 0.5, 3, acks.seq), clock, acks, {1: [ACCEPTED]})
    assert step is Step.DONE and sends == [0] and clock.now() == 0.0


def test_exchange_retries_with_rising_confirmation_then_times_out():
    clock, acks = ManualClock(), AckLog()
    ex = CommandExchange(SET_MODE, 0.5, 3, acks.seq)
    step, sends = run_exchange(ex, clock, acks, {})
    assert step is Step.TIMED_OUT and sends == [0, 1, 2, 3] and ex.final is None
    assert clock.now() == pytest.approx(4 * 0.5, abs=0.02)


def test_exchange_in_progress_extends_the_wait_and_a_late_answer_counts():
    clock, acks = ManualClock(), AckLog()
    ex = CommandExchange(SET_MODE, 0.5, 0, acks.seq)
    assert ex.step(clock.now(), acks) is Step.SEND
    clock.advance(0.4)
    acks.add(clock.now(), SET_MODE, IN_PROGRESS)
    clock.advance(0.4)  # 0.8 s after the send: past the first deadline, inside the restarted one
    assert ex.step(clock.now(), acks) is Step.WAIT
    acks.add(clock.now(), SET_MODE, DENIED)
    assert ex.step(clock.now(), acks) is Step.DONE and ex.final.result == DENIED


def test_exchange_ignores_older_acks_and_other_commands():
    acks = AckLog()
    acks.add(0.0, SET_MODE, ACCEPTED)  # an answer to an earlier command
    ex = CommandExchange(SET_MODE, 0.5, 0, acks.seq)
    assert ex.step(0.0, acks) is Step.SEND
    acks.add(0.1, mavlink.MAV_CMD_COMPONENT_ARM_DISARM, ACCEPTED)
    assert ex.step(0.1, acks) is Step.WAIT
    assert ex.step(0.6, acks) is Step.TIMED_OUT


def state_at(t_s: float, mode: str, heartbeat_rx_s: float | None) -> telemetry.VehicleState:
    tm = telemetry.Telemetry()
    if heartbeat_rx_s is not None:
        tm = telemetry.reduce(tm, heartbeat(mode, True), heartbeat_rx_s)
    return telemetry.snapshot(tm, t_s, (1, 1), 0.5)


def test_confirmation_needs_a_heartbeat_after_the_command():
    acks = AckLog()
    conf = HeartbeatConfirmation(SET_MODE, 1.0, acks.seq, lambda s: s.mode == "OFFBOARD", 2.5)
    conf.start(1.1)
    assert conf.step(1.2, acks, state_at(1.2, "OFFBOARD", 0.9)) is Confirmed.WAIT  # an older HEARTBEAT
    assert conf.step(1.3, acks, state_at(1.3, "POSCTL", 1.25)) is Confirmed.WAIT
    assert conf.step(1.4, acks, state_at(1.4, "OFFBOARD", 1.35)) is Confirmed.CONFIRMED
    assert conf.step(3.7, acks, state_at(3.7, "POSCTL", 3.5)) is Confirmed.TIMED_OUT


def test_confirmation_rejected_by_pxs_second_ack():
    acks = AckLog()
    acks.add(0.5, SET_MODE, ACCEPTED)  # before the command: not ours
    conf = HeartbeatConfirmation(SET_MODE, 1.0, acks.seq, lambda s: s.mode == "OFFBOARD", 2.5)
    acks.add(1.05, SET_MODE, ACCEPTED)  # the MAVLink layer's ACK
    conf.start(1.05)
    assert conf.step(1.1, acks, state_at(1.1, "POSCTL", 1.08)) is Confirmed.WAIT
    acks.add(1.15, SET_MODE, mavlink.MAV_RESULT_TEMPORARILY_REJECTED)  # the commander's real answer
    assert conf.step(1.2, acks, state_at(1.2, "POSCTL", 1.18)) is Confirmed.REJECTED
    assert conf.rejection.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED


def test_refusal_reason_prefers_a_serious_recent_text():
    texts = [(0.5, 2, "old and serious"), (1.1, 6, "info"), (1.2, 3, "Arming denied: throttle"), (1.3, 6, "later info")]
    assert refusal_reason(texts, 1.0) == ("Arming denied: throttle", "later info")
    assert refusal_reason(texts[:2], 1.0) == (None, "info")
    assert refusal_reason([], 1.0) == (None, "")


def test_snapshot_arrays_are_shared_not_copied():
    tm = telemetry.reduce(telemetry.Telemetry(), position(), 1.0)
    a, b = telemetry.snapshot(tm, 1.0, None, 0.5), telemetry.snapshot(tm, 1.1, None, 0.5)
    assert a.position_ned_m is b.position_ned_m and np.shares_memory(a.velocity_ned_m_s, tm.velocity_ned_m_s)


# ------------------------------------------------------------------------------ receiver


class FakeTransport:
    datagram = True

    def __init__(self) -> None:
        self.peer = None

    def set_peer(self, address):
        self.peer = address


def make_receiver(clock, target_system=1, key=None):
    from mission.mavlink.codec import link_codecs
    from mission.mavlink.identity import Adoption
    from mission.mavlink.receiver import Receiver
    from mission.mavlink.session import LinkSession

    session = LinkSession("test", clock, position_timeout_s=0.5)
    session.closed = False
    identified, packets = [], []
    receiver = Receiver(session, link_codecs((1, 191), key)[0], source_system=1, adoption=Adoption(target_system, 1, 3.0),
                        signed=key is not None, on_identified=identified.append, on_packet=packets.append)
    return session, receiver, identified, packets


def packet(msg, sysid=1, compid=1) -> bytes:
    from mission.mavlink.codec import new_codec

    return bytes(msg.pack(new_codec(sysid, compid)))


def test_receiver_identifies_the_px4_autopilot_and_ignores_others():
    clock = ManualClock(5.0)
    session, receiver, identified, packets = make_receiver(clock)
    t = FakeTransport()
    receiver.handle_bytes(packet(position()), ("127.0.0.1", 1), t)  # before identification: ignored
    gcs = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
    receiver.handle_bytes(packet(gcs, sysid=255, compid=190), ("127.0.0.1", 2), t)
    assert session.vehicle is None and t.peer is None and session.counts["rx_ignored"] == 2
    receiver.handle_bytes(packet(heartbeat("AUTO.LOITER", False)), ("127.0.0.1", 3), t)
    assert session.vehicle == (1, 1) and identified == [(1, 1)] and t.peer == ("127.0.0.1", 3)
    receiver.handle_bytes(packet(position(x=9.0), sysid=42), ("127.0.0.1", 4), t)  # a rogue system
    receiver.handle_bytes(packet(position(x=1.5)), ("127.0.0.1", 3), t)
    state = session.snapshot_locked()
    assert session.counts["rejected_foreign"] == 1 and state.position_ned_m[0] == 1.5 and state.position_rx_s == 5.0
    assert state.mode == "AUTO.LOITER" and len(packets) == 5  # every valid packet reaches the tlog


def test_receiver_keeps_acks_for_us_and_joins_statustext():
    clock = ManualClock()
    session, receiver, _, _ = make_receiver(clock)
    t = FakeTransport()
    receiver.handle_bytes(packet(heartbeat("AUTO.LOITER", False)), None, t)
    receiver.handle_bytes(packet(mavlink.MAVLink_command_ack_message(SET_MODE, ACCEPTED, 0, 0, 1, 191)), None, t)
    receiver.handle_bytes(packet(mavlink.MAVLink_command_ack_message(SET_MODE, DENIED, 0, 0, 7, 191)), None, t)  # not ours
    assert [(a.command, a.result) for a in session.acks] == [(SET_MODE, ACCEPTED)]
    receiver.handle_bytes(packet(mavlink.MAVLink_statustext_message(3, b"x" * 50, 9, 0)), None, t)
    receiver.handle_bytes(packet(mavlink.MAVLink_statustext_message(3, b"end", 9, 1)), None, t)
    assert [text for _, _, text in session.statustexts] == ["x" * 50 + "end"]
    assert session.snapshot_locked().last_statustext == "x" * 50 + "end"


def test_receiver_counts_garbage_and_a_truncated_datagram():
    clock = ManualClock()
    session, receiver, _, _ = make_receiver(clock)
    t = FakeTransport()
    whole = packet(heartbeat("AUTO.LOITER", False))
    receiver.handle_bytes(whole[:-4], None, t)  # cut short: cannot continue in the next datagram
    receiver.handle_bytes(b"\x00garbage", None, t)
    receiver.handle_bytes(whole, None, t)
    assert session.counts["rx_bad"] >= 1 and session.vehicle == (1, 1)


def test_vehicle_time_maps_onto_the_link_clock_by_the_least_delayed_sample():
    t, st = telemetry.vehicle_time_to_link(None, 10.0, 100.2)  # first sample: 0.2 s late
    assert t == pytest.approx(100.2)
    t, st = telemetry.vehicle_time_to_link(st, 10.1, 100.25)  # a faster one: the offset shrinks
    assert t == pytest.approx(100.25) and st[0] == pytest.approx(90.15)
    t, st = telemetry.vehicle_time_to_link(st, 10.2, 100.9)  # read 0.55 s late (a stall): stamped when taken
    assert t == pytest.approx(10.2 + 90.15 + 0.1 * 0.65)  # the offset may only creep up by the drift
    t, st = telemetry.vehicle_time_to_link(st, 0.5, 101.0)  # the vehicle rebooted: start afresh
    assert t == pytest.approx(101.0)


def test_reducer_stamps_position_samples_on_the_link_clock():
    tm = telemetry.reduce(telemetry.Telemetry(), mavlink.MAVLink_local_position_ned_message(5000, 0, 0, 0, 0, 0, 0), 7.0)
    tm = telemetry.reduce(tm, mavlink.MAVLink_local_position_ned_message(5100, 0, 0, 0, 0, 0, 0), 7.3)
    s = telemetry.snapshot(tm, 7.3, None, 0.5)
    assert s.position_rx_s == 7.3 and s.position_t_s == pytest.approx(7.1 + 0.1 * 0.3)


def test_without_a_target_system_a_vehicle_is_adopted_after_consistent_heartbeats_only():
    from mission.mavlink.identity import ADOPT_HEARTBEATS, Adoption

    adoption = Adoption(None, 1, heartbeat_timeout_s=3.0)
    quad, px4_ap = mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4
    assert not adoption.offer(mavlink.MAV_TYPE_GCS, px4_ap, (1, 1), 0.0)  # not a vehicle type
    assert not adoption.offer(quad, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, (1, 1), 0.0)  # not PX4
    assert [adoption.offer(quad, px4_ap, (1, 1), t) for t in (1.0, 2.0, 3.0)] == [False] * (ADOPT_HEARTBEATS - 1) + [True]
    rogue = Adoption(None, 1, heartbeat_timeout_s=3.0)  # two autopilots at once: neither is adopted
    answers = [rogue.offer(quad, px4_ap, src, t) for t in (1.0, 2.0, 3.0, 4.0) for src in ((1, 1), (42, 1))]
    assert not any(answers)
    late = Adoption(None, 1, heartbeat_timeout_s=3.0)  # gaps longer than the timeout start the count again
    assert not any(late.offer(quad, px4_ap, (1, 1), t) for t in (0.0, 5.0, 10.0))


# ------------------------------------------------------------------------------ identity: replay, reply address, adoption

KEY = bytes(range(32))


def signer(link_id, ahead, sysid=1, compid=1, base=None):
    """A codec signing as ``sysid``/``compid`` on ``link_id``, its timestamp ``ahead`` ticks (10 us)
    past ``base`` (default: now)."""
    from mission.mavlink.codec import new_codec, setup_signing, signing_timestamp_now

    codec = new_codec(sysid, compid)
    setup_signing(codec, KEY, sign_outgoing=True, unsigned_ids=(), link_id=link_id)
    codec.signing.timestamp = (signing_timestamp_now() if base is None else base) + ahead
    return codec


def test_signing_replay_protection_is_per_link_id_system_and_component():
    """The MAVLink 2 signing spec keys the replay state by (link id, system, component), and so
    does pymavlink (``stream_timestamps[(link_id, sys, comp)]``): a vehicle's two links each keep
    their own clock; only an old timestamp on a packet's own stream is a replay."""
    from mission.mavlink.codec import link_codecs, reset_parser

    rx, _ = link_codecs((1, 191), KEY)
    base = rx.signing.timestamp

    def accepted(codec, msg=None):
        data = bytes((msg or heartbeat("OFFBOARD", True)).pack(codec))
        out = [m.get_type() for m in rx.parse_buffer(data) or []]
        reset_parser(rx)
        return out == ["HEARTBEAT"]

    gcs = signer(0, 10**6, base=base)  # the vehicle's GCS link, 10 s ahead
    onboard = signer(1, 10, base=base)
    assert accepted(gcs) and accepted(onboard)  # link 1 is not refused for being behind link 0
    assert sorted(rx.signing.stream_timestamps) == [(0, 1, 1), (1, 1, 1)]
    assert not accepted(signer(1, 5, base=base))  # older on its own stream: a replay
    assert accepted(signer(1, 5, base=base, compid=2)) and accepted(signer(1, 5, base=base, sysid=2))
    assert accepted(onboard)  # the real stream goes on


def test_signed_link_pins_the_reply_address_and_link_id_a_forwarded_link_moves_nothing():
    """The attack: the vehicle's own GCS-link packets (signed, link id 0, timestamps ahead)
    forwarded to our port from elsewhere. Counted as another link and ignored: the reply address
    stays, the telemetry is not theirs, and the real link (id 1) is never refused. A packet of the
    pinned link from a new address (the vehicle restarted on another port) moves the address."""
    clock = ManualClock(5.0)
    session, receiver, identified, _ = make_receiver(clock, key=KEY)
    t = FakeTransport()
    base = receiver.codec.signing.timestamp
    onboard, gcs = signer(1, 10, base=base), signer(0, 10**6, base=base)
    real, relay = ("127.0.0.1", 14580), ("127.0.0.1", 40000)
    receiver.handle_bytes(bytes(heartbeat("OFFBOARD", True).pack(onboard)), real, t)
    assert identified == [(1, 1)] and t.peer == real and receiver.pin.link_id == 1
    for k in range(5):
        receiver.handle_bytes(bytes(heartbeat("POSCTL", False).pack(gcs)), relay, t)
        receiver.handle_bytes(bytes(position(x=9.0).pack(gcs)), relay, t)
    state = session.snapshot_locked()
    assert session.counts["rx_other_link"] == 10 and t.peer == real and state.mode == "OFFBOARD" and state.armed
    assert state.position_ned_m is None
    receiver.handle_bytes(bytes(position(x=1.5).pack(onboard)), real, t)
    assert session.snapshot_locked().position_ned_m[0] == 1.5 and session.counts["rx_bad"] == 0
    moved = ("127.0.0.1", 14581)
    receiver.handle_bytes(bytes(position(x=2.5).pack(onboard)), moved, t)
    assert t.peer == moved and session.counts["peer_moves"] == 1


def test_unsigned_link_keeps_the_reply_address_while_the_vehicle_talks_from_it():
    """Without signing, the address is the link: another address claiming the vehicle's ids is
    ignored while the vehicle's own one talks; after PEER_SILENT_S of silence it may take over."""
    from mission.mavlink.receiver import PEER_SILENT_S

    clock = ManualClock(5.0)
    session, receiver, _, _ = make_receiver(clock)
    t = FakeTransport()
    real, other = ("127.0.0.1", 14580), ("127.0.0.1", 40000)
    receiver.handle_bytes(packet(heartbeat("OFFBOARD", True)), real, t)
    receiver.handle_bytes(packet(heartbeat("POSCTL", True)), other, t)
    receiver.handle_bytes(packet(position(x=9.0)), other, t)
    assert session.counts["rx_other_address"] == 2 and t.peer == real and session.snapshot_locked().mode == "OFFBOARD"
    clock.advance(PEER_SILENT_S * 0.9)
    receiver.handle_bytes(packet(position(x=1.0)), real, t)
    clock.advance(PEER_SILENT_S * 0.9)
    receiver.handle_bytes(packet(position(x=9.0)), other, t)  # the vehicle spoke 0.9 s ago: still its address
    assert session.counts["rx_other_address"] == 3 and session.snapshot_locked().position_ned_m[0] == 1.0
    clock.advance(PEER_SILENT_S * 0.2)
    receiver.handle_bytes(packet(position(x=2.0)), other, t)  # silent for 1.1 s: a restarted vehicle
    assert t.peer == other and session.counts["peer_moves"] == 1 and session.snapshot_locked().position_ned_m[0] == 2.0


def test_without_target_system_a_lone_rogue_is_adopted_loudly_and_refused_once_another_px4_talks(caplog):
    """A rogue PX4 HEARTBEAT (sysid 42) talking alone for 3 HEARTBEATs is adopted, with a warning
    that says so; the real vehicle's first HEARTBEAT is then an identity conflict (the mission
    aborts vehicle_ambiguous). With target_system set, another system is only counted."""
    import logging

    caplog.set_level(logging.WARNING)
    clock = ManualClock(0.0)
    session, receiver, identified, _ = make_receiver(clock, target_system=None)
    t = FakeTransport()
    for _ in range(3):
        clock.advance(1.0)
        receiver.handle_bytes(packet(heartbeat("AUTO.LOITER", False), sysid=42), ("127.0.0.1", 6666), t)
    assert identified == [(42, 1)] and session.identity_problem() is None
    assert "WITHOUT mavlink.target_system" in caplog.text and "sysid 42 compid 1" in caplog.text
    gcs = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
    receiver.handle_bytes(packet(gcs, sysid=255, compid=190), ("127.0.0.1", 7777), t)  # not an autopilot: no conflict
    assert session.identity_problem() is None
    receiver.handle_bytes(packet(heartbeat("AUTO.LOITER", False)), ("127.0.0.1", 14580), t)  # the real vehicle
    problem = session.identity_problem()
    assert problem is not None and "sysid 1 compid 1" in problem and "target_system" in problem
    assert t.peer == ("127.0.0.1", 6666)  # nothing more: the mission aborts on it
    pinned_session, pinned, _, _ = make_receiver(ManualClock(), target_system=1)
    pinned.handle_bytes(packet(heartbeat("AUTO.LOITER", False)), ("127.0.0.1", 14580), t)
    pinned.handle_bytes(packet(heartbeat("AUTO.LOITER", False), sysid=42), ("127.0.0.1", 6666), t)
    assert pinned_session.identity_problem() is None and pinned_session.counts["rejected_foreign"] == 1

