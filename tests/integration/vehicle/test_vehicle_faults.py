"""Mock vehicle fault injection and robustness: garbage on the socket, loss, latency, blackouts,
a pilot taking over, loss of the position estimate, arming refusal, MAVLink 2 signing."""
from __future__ import annotations

import random
import struct
import time

import numpy as np
import pytest

from mission.mavlink import px4
from mission.mavlink.env import mavlink
from sim.net import wait_for
from sim.vehicle.mock import FaultOptions, VehicleOptions
from sim.testing.probe import Probe, connect, start_offboard, vehicle_for, wait_flight

pytestmark = pytest.mark.timeout(30)
KEY = bytes(range(32))


def _frame(probe: Probe, msg: object) -> bytearray:
    data = bytearray(msg.pack(probe.mav))  # type: ignore[attr-defined]
    probe.mav.seq = (probe.mav.seq + 1) % 256
    return data


def test_garbage_bytes_are_counted_and_never_crash_it(probe: Probe) -> None:
    rng = random.Random(1234)
    with vehicle_for(probe, paced=True) as v:
        connect(probe)
        arm = _frame(probe, mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        good = _frame(probe, mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
        bad_crc = bytearray(arm)
        bad_crc[-1] ^= 0xFF
        unknown_id = bytearray(arm)
        unknown_id[7:10] = (54321).to_bytes(3, "little")  # an id outside the dialect
        corpus: list[bytes] = [bytes(bad_crc), bytes(unknown_id), bytes(arm[:9]), b"", b"\xfd", b"\xfe\xff" * 10,
                               b"\xfd\xff\x01" + bytes(300), bytes(good) + b"\x00\x01garbage"]
        corpus += [bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 300))) for _ in range(300)]
        corpus += [b"\xfd" + bytes(rng.getrandbits(8) for _ in range(rng.randint(8, 280))) for _ in range(200)]
        for data in corpus:
            probe.send_raw(data)
        wait_flight(v, lambda s: s.counters["rx_datagrams"] >= len(corpus), 5.0, "s.counters['rx_datagrams'] >= len(corpus)")
        counters = v.counters
        assert counters["rx_malformed"] >= 500 and counters["rx_unknown_ids"] >= 1
        assert counters["internal_errors"] == 0 and not v.snapshot().armed  # the bad-CRC arm was refused
        # still alive and answering
        ack = probe.arm()
        assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED
        assert "malformed=" in v.status_line()


def test_random_structured_fields_never_crash_it(probe: Probe) -> None:
    """Valid frames with random payload values (NaN, huge ints, odd modes, strings)."""
    rng = random.Random(99)
    floats = [float("nan"), float("inf"), -float("inf"), 0.0, 1.0, -1.0, 1e38, 21196.0, 176.0, 400.0, 6.0, 129.0]
    with vehicle_for(probe, paced=True) as v:
        connect(probe)
        for _ in range(300):
            p = [rng.choice(floats) for _ in range(7)]
            command = rng.choice([176, 400, 22, 21, 20, 512, 511, 520, rng.randrange(65536)])
            msgs = [mavlink.MAVLink_command_long_message(rng.choice([0, 1]), rng.choice([0, 1]), command, 0, *p),
                    mavlink.MAVLink_command_int_message(1, 1, 0, command, 0, 0, *p[:4], rng.randrange(-2**31, 2**31),
                                                        rng.randrange(-2**31, 2**31), p[6]),
                    mavlink.MAVLink_set_position_target_local_ned_message(0, 1, 1, rng.randrange(256), rng.randrange(65536),
                                                                          *(rng.choice(floats) for _ in range(11))),
                    mavlink.MAVLink_param_set_message(1, 1, bytes(rng.getrandbits(8) % 127 + 1 for _ in range(16)),
                                                      rng.choice(floats), rng.randrange(256)),
                    mavlink.MAVLink_param_request_read_message(1, 1, b"\xff\xfe", rng.randrange(-32768, 32768))]
            probe.send(rng.choice(msgs))
        wait_flight(v, lambda s: s.counters["rx_messages"] >= 300, 5.0, "s.counters['rx_messages'] >= 300")
        assert v.counters["internal_errors"] == 0
        v.force_mode("AUTO.LOITER")
        assert probe.wait_for("HEARTBEAT", after=probe.mark(), timeout_s=2.0) is not None


def test_packet_loss_each_way(probe: Probe) -> None:
    faults = FaultOptions(loss_in=0.5, loss_out=0.3, seed=7)
    with vehicle_for(probe, paced=True, speed=10.0, faults=faults) as v:
        assert probe.wait_for("HEARTBEAT", timeout_s=3.0)
        for _ in range(400):
            probe.heartbeat()
        wait_flight(v, lambda s: s.counters["dropped_in"] + s.counters["rx_messages"] >= 400
                          and s.counters["tx_messages"] >= 400, 3.0, "s.counters['dropped_in'] + s.counters['rx_messages'] >= 400 and s.counters['tx_messages'] >= 400")
        counters = v.counters
        assert counters["dropped_in"] / 400 == pytest.approx(0.5, abs=0.08)
        assert counters["dropped_out"] / counters["tx_messages"] == pytest.approx(0.3, abs=0.06)
        v.set_faults(loss_in=0.0, loss_out=0.0)
        dropped = v.counters["dropped_in"]
        ack = probe.arm()
        assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED and v.counters["dropped_in"] == dropped


def test_latency_and_jitter_delay_both_ways(probe: Probe) -> None:
    speed, latency_s = 5.0, 0.4
    with vehicle_for(probe, paced=True, speed=speed, faults=FaultOptions(latency_s=latency_s, jitter_s=0.1, seed=3)) as v:
        assert probe.wait_for("HEARTBEAT", timeout_s=3.0)
        t_sent = time.monotonic()
        ack = probe.arm(timeout_s=3.0)
        round_trip_wall_s = time.monotonic() - t_sent
        assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED
        assert round_trip_wall_s >= 2 * latency_s / speed * 0.95  # a lower bound: robust on a loaded machine
        counters = v.counters
        assert counters["delayed_in"] >= 1 and counters["delayed_out"] >= 1
        # telemetry is late by at least the latency: its timestamp lags the vehicle clock
        mark = probe.mark()
        msg = probe.wait_for("LOCAL_POSITION_NED", after=mark, timeout_s=2.0)
        assert msg is not None and v.clock.now() - msg.time_boot_ms / 1000.0 >= latency_s * 0.95


def test_blackout_window_silences_both_ways(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=10.0, faults=FaultOptions(blackouts=((1.0, 2.0),))) as v:
        connect(probe)
        wait_flight(v, lambda s: s.t_s > 4.0, 3.0, "s.t_s > 4.0")
        stamps = np.array([m.time_boot_ms for m in probe.messages("LOCAL_POSITION_NED")])
        assert (stamps < 1000).any() and (stamps >= 3000).any()
        assert not ((stamps >= 1000) & (stamps < 3000)).any()
        counters = v.counters
        assert counters["blackout_in"] > 0 and counters["blackout_out"] > 0


def test_blackout_in_flight_triggers_offboard_loss(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=10.0) as v:
        connect(probe)
        with start_offboard(probe, (0.0, 0.0, -2.0)):
            wait_flight(v, lambda s: s.position_ned_m[2] < -2.0, 3.0, "s.position_ned_m[2] < -2.0")
            t_now = v.clock.now()
            v.set_faults(blackouts=[(t_now, 2.0)])
            wait_flight(v, lambda s: s.mode == "POSCTL" and s.in_failsafe, 2.0, "s.mode == 'POSCTL' and s.in_failsafe")
            # the link comes back while the stream still runs: PX4 returns to OFFBOARD by itself
            wait_flight(v, lambda s: s.mode == "OFFBOARD" and not s.in_failsafe, 3.0, "s.mode == 'OFFBOARD' and not s.in_failsafe")


def test_pilot_takeover_forces_mode_and_holds(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=10.0, estimate_error=0.0) as v:  # exact: holds to 0.02 m
        connect(probe)
        with start_offboard(probe, (1.0, 0.0, -2.0)):
            wait_flight(v, lambda s: s.position_ned_m[2] < -3.0, 3.0, "s.position_ned_m[2] < -3.0")
            v.force_mode("POSCTL")
            assert probe.wait_mode("POSCTL", 2.0)
            hb = probe.latest("HEARTBEAT")
            assert hb.system_status == px4.MAV_STATE_ACTIVE and hb.base_mode == 209  # no failsafe: a pilot flies
            settled = wait_flight(v, lambda s: np.allclose(s.velocity_ned_m_s, 0.0, atol=0.01), 3.0, "np.allclose(s.velocity_ned_m_s, 0.0, atol=0.01)")
            assert settled is not None
            later = wait_flight(v, lambda s: s.t_s > settled.t_s + 2.0, 2.0, "s.t_s > settled.t_s + 2.0")
            assert later is not None and np.allclose(later.position_ned_m, settled.position_ned_m, atol=0.02)
            assert later.mode == "POSCTL"  # setpoints still arrive, but it does not return to OFFBOARD
        with pytest.raises(ValueError):
            v.force_mode("NOT_A_MODE")


def test_position_estimate_loss_exits_and_refuses_offboard(probe: Probe) -> None:
    with vehicle_for(probe, paced=True, speed=10.0) as v:
        connect(probe)
        with start_offboard(probe, (1.0, 0.0, -2.0)):
            wait_flight(v, lambda s: s.position_ned_m[2] < -3.0, 3.0, "s.position_ned_m[2] < -3.0")
            v.lose_position_estimate(True)
            assert probe.wait_mode("AUTO.LAND", 2.0)
            snap = v.snapshot()
            assert snap.in_failsafe and not snap.position_valid
            assert probe.wait_for("STATUSTEXT", lambda m: "no local position" in m.text, 2.0)
            ack = probe.set_mode("OFFBOARD")
            assert ack is not None and ack.result == px4.MAV_RESULT_TEMPORARILY_REJECTED
            status = probe.wait_for("SYS_STATUS", lambda m: not m.onboard_control_sensors_health & px4.SENSOR_GPS,
                                    after=probe.mark(), timeout_s=2.0)
            assert status is not None and not status.onboard_control_sensors_health & px4.SENSOR_PREARM_CHECK
            wait_flight(v, lambda s: not s.armed, 10.0, "not s.armed")  # descends, lands, disarms
        v.lose_position_estimate(False)
        wait_flight(v, lambda s: s.position_valid, 1.0, "s.position_valid")


def test_arming_refusal_with_reason(probe: Probe) -> None:
    reason = "Arming denied: Preflight Fail: Accel uncalibrated"
    with vehicle_for(probe, paced=True, faults=FaultOptions(refuse_arming_reason=reason)) as v:
        connect(probe)
        status = probe.wait_for("SYS_STATUS", timeout_s=2.0)
        assert status is not None and not status.onboard_control_sensors_health & px4.SENSOR_PREARM_CHECK
        ack = probe.arm()
        assert ack is not None and ack.result == px4.MAV_RESULT_TEMPORARILY_REJECTED
        wait_for(lambda: reason in "".join(m.text for m in probe.messages("STATUSTEXT")), 2.0, f"STATUSTEXT {reason!r}")
        v.refuse_arming(None)
        assert probe.arm().result == px4.MAV_RESULT_ACCEPTED
        v.set_faults(refuse_arming_reason="Arming denied: again")
        assert probe.arm(False).result == px4.MAV_RESULT_ACCEPTED
        assert probe.arm().result == px4.MAV_RESULT_TEMPORARILY_REJECTED


def test_offboard_refusal_with_reason(probe: Probe) -> None:
    reason = "Mode OFFBOARD rejected: test"
    with vehicle_for(probe, paced=True, faults=FaultOptions(refuse_offboard_reason=reason)) as v:
        connect(probe)
        with pytest.raises(TimeoutError):
            start_offboard(probe, timeout_s=0.5)
        assert probe.wait_for("STATUSTEXT", lambda m: m.text == reason, 2.0)
        v.refuse_offboard(None)
        with start_offboard(probe, arm=False):
            assert probe.wait_mode("OFFBOARD", 2.0)


def test_signing_rejects_unsigned_commands_but_accepts_unsigned_heartbeat(probe: Probe) -> None:
    with vehicle_for(probe, signing_key=KEY) as v:  # real time: the probe signs nothing, so it could not pace it
        hb = probe.wait_for("HEARTBEAT", timeout_s=2.0)
        assert hb is not None and hb.get_msgbuf()[2] & 0x01  # the vehicle signs what it sends
        probe.heartbeat()  # unsigned HEARTBEAT: accepted
        wait_flight(v, lambda s: s.counters["rx_messages"] >= 1, 2.0, "s.counters['rx_messages'] >= 1")
        assert probe.arm(timeout_s=0.3) is None
        probe.send(probe.setpoint_message())
        wait_flight(v, lambda s: s.counters["rx_unsigned_rejected"] >= 2, 2.0, "s.counters['rx_unsigned_rejected'] >= 2")
        assert v.counters["setpoints_accepted"] == 0
        with Probe(vehicle=("127.0.0.1", v.port), signing_key=bytes(32)) as wrong_key:
            assert wrong_key.arm(timeout_s=0.3) is None
        with Probe(vehicle=("127.0.0.1", v.port), signing_key=KEY) as signed:
            # the vehicle latched on the first probe: a signed peer is still heard, answered there
            signed.send(mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
            ack = probe.wait_for("COMMAND_ACK", timeout_s=2.0)
            assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED
        assert v.snapshot().armed


def test_signed_links_sign_with_their_own_link_ids_and_share_one_replay_state() -> None:
    """As PX4: each MAVLink instance signs with its instance number as link id (the GCS link 0 and
    the onboard link 1, PX4 SITL's start order) and all check replays against one table keyed by
    (link id, system, component): a signed command accepted on the GCS link and replayed, byte
    for byte, on the onboard link is refused."""
    from sim.vehicle.mock import MockVehicle

    with Probe(signing_key=KEY) as onboard, Probe(signing_key=KEY) as gcs, \
            MockVehicle(VehicleOptions(target=f"127.0.0.1:{onboard.port}", gcs_target=f"127.0.0.1:{gcs.port}",
                                       signing_key=KEY, speed=5.0)) as v:
        a, b = onboard.wait_for("HEARTBEAT", timeout_s=3.0), gcs.wait_for("HEARTBEAT", timeout_s=3.0)
        assert a is not None and a.get_signed() and a.get_link_id() == 1
        assert b is not None and b.get_signed() and b.get_link_id() == 0
        command = bytes(mavlink.MAVLink_command_long_message(1, 1, px4.MAV_CMD_REQUEST_MESSAGE, 0, 148.0,
                                                             0, 0, 0, 0, 0, 0).pack(gcs.mav))
        mark_gcs, mark_onboard = gcs.mark(), onboard.mark()
        gcs.send_raw(command)
        assert gcs.wait_for("COMMAND_ACK", timeout_s=2.0, after=mark_gcs) is not None
        refused = v.counters["rx_unsigned_rejected"]
        onboard.send_raw(command)
        wait_flight(v, lambda s: s.counters["rx_unsigned_rejected"] > refused, 2.0, "the replay refused")
        assert onboard.wait_for("COMMAND_ACK", timeout_s=0.5, after=mark_onboard) is None


def test_signing_key_must_be_32_bytes() -> None:
    with pytest.raises(ValueError, match="32 bytes"):
        VehicleOptions(signing_key=b"short")


def test_fault_options_are_validated() -> None:
    with pytest.raises(ValueError):
        FaultOptions(loss_in=1.5)
    with pytest.raises(ValueError):
        FaultOptions(blackouts=((1.0, -1.0),))
    assert struct.calcsize("<f") == 4


def test_a_stalled_machine_slows_a_paced_vehicle_and_never_starves_it_of_setpoints(probe: Probe) -> None:
    """The probe's pacer stalled for 0.5 s of wall (as a loaded machine stalls a thread): at speed
    10 in real time that is 5 s without setpoints, PX4's offboard loss; a paced vehicle's time
    stands still meanwhile, so it stays in OFFBOARD."""
    with vehicle_for(probe, paced=True, speed=10.0) as v:
        connect(probe)
        with start_offboard(probe, (0.0, 0.0, -1.0)):
            wait_flight(v, lambda s: s.position_ned_m[2] < -1.0, 5.0, "the vehicle climbing")
            assert probe.pacer is not None
            with probe.pacer._lock:  # the pacer blocks at its next step, the vehicle waits at its barrier
                t_stalled = v.snapshot().t_s
                time.sleep(0.5)
                assert v.snapshot().t_s - t_stalled <= 0.011  # at most the step that was under way
            wait_flight(v, lambda s: s.t_s > t_stalled + 2.0, 5.0, "time going on")
            snap = v.snapshot()
            assert snap.mode == "OFFBOARD" and not snap.in_failsafe
