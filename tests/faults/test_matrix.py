"""The fault matrix: the real processes of a pair (mock PX4, carrier simulator, ``marsupial run``)
over real UDP and Zenoh, one fault (or several whose reactions do not interfere) per flight.

For each fault the expected reaction is asserted (docs/safety.md): the vehicle ends
safe (Hold armed in the air, or landed and disarmed, never disarmed in the air), the flight log
is complete (record.csv to the last tick, summary.json with phase and reason), and the exit code
and the message say what happened. Flights that do not compete for the same resource run
concurrently. Speed 5: timeouts scale with it, and at 10x a 50 ms scheduling hiccup on a loaded
2-core CI machine already looks like a lost carrier.

Timeline in vehicle seconds (see tests/faults/procs.py): RIDING ~4.5-17 s, separation ~17 s,
arrival ~21 s. MAVLink faults are vehicle flags (``--loss-in/--loss-out``, ``--latency-ms``,
``--jitter-ms``, ``--blackout START:DURATION``, ``--lose-position AT``, ``--refuse-*``).
``MARSUPIAL_FAULTS_FULL=1`` adds more loss levels and seeds.
"""
from __future__ import annotations

import math
import os
import signal
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import numpy as np

from mission.flightdata.read import read_messages
from mission.mavlink import px4
from mission.mavlink.env import mavlink
from mission.mavlink.telemetry import DISARMED_AGREE_S
from mission.record.figures import summarise
from mission.record.table import read_record
from tests.faults.procs import DEMO, SPEED, Flight, Router, assert_log_complete, assert_safe_end, fleet_config, flight, wait_for

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]
# A class per test: `--dist loadscope` schedules a class as its own unit, so the flights spread over the workers.

FULL = os.environ.get("MARSUPIAL_FAULTS_FULL") == "1"


def concurrently(*jobs: Callable[[], Any]) -> list[Any]:
    """Run ``jobs`` in threads; re-raise the first failure (after all have finished)."""
    results: list[Any] = [None] * len(jobs)
    errors: list[BaseException] = []

    def run(i: int, job: Callable[[], Any]) -> None:
        try:
            results[i] = job()
        except BaseException as exc:  # noqa: BLE001  (re-raised below)
            errors.append(exc)

    threads = [threading.Thread(target=run, args=(i, job)) for i, job in enumerate(jobs)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        raise errors[0]
    return results


def statustexts(f: Flight) -> list[str]:
    assert f.gcs is not None
    return [str(m.text) for m in f.gcs.messages("STATUSTEXT")]


def assert_never_disarmed_in_the_air(f: Flight) -> None:
    disarms = [t for t in statustexts(f) if t.startswith("Disarm")]
    assert all(t in ("Disarmed by landing", "Disarmed by auto preflight disarming") for t in disarms), disarms


def assert_exit(f: Flight, code: int, reason: str | None) -> None:
    """Exit code, and the message on stderr / the phase line on stdout naming the reason."""
    assert f.procs["mission"].returncode == code, (f.phases(), f.text("mission.err")[-2000:])
    if reason is None:
        assert "mission aborted" not in f.text("mission.err")
        assert f.phases()[-1] == "DONE"
    else:
        assert f"mission aborted: {reason}: " in f.text("mission.err")
        assert f"phase ABORT ({reason}: " in f.text("mission.out")


def assert_completed(f: Flight, *, p2: bool = True) -> dict[str, Any]:
    """The mission flew to the end: DONE, exit 0, separated at b c, arrived (P2; with ``p2``
    False only within 1 m of the target); vehicle in Hold."""
    f.wait_mission(60.0)
    assert_exit(f, 0, None)
    s = assert_log_complete(f, "DONE", None)
    assert (s["p2"] or not p2 and s["final_passenger_target_distance_m"] < 1.0) and s["p3"], s
    assert s["carrier_target_distance_at_separation_m"] == pytest.approx(8.0, abs=0.05)
    v = assert_safe_end(f, modes=("AUTO.LOITER",))
    assert math.dist(v["ned"], (24.0, 18.0, -5.0)) < 1.0
    assert_never_disarmed_in_the_air(f)
    return s


# ----------------------------------------------------------------------------- MAVLink faults


def _lossy(tmp_path: Path, name: str, loss: float, seed: int, extra: tuple[str, ...] = (), *,
           p2: bool = True, heartbeat_timeout_s: float | None = None) -> dict[str, int]:
    args = ("--loss-in", str(loss), "--loss-out", str(loss), "--seed", str(seed), *extra)
    config = DEMO
    if heartbeat_timeout_s is not None:
        config = tmp_path / f"{name}.toml"
        text = DEMO.read_text()
        assert "heartbeat_timeout_s = 3.0" in text
        config.write_text(text.replace("heartbeat_timeout_s = 3.0", f"heartbeat_timeout_s = {heartbeat_timeout_s}"))
    with flight(tmp_path, name, vehicle_args=args, lockstep=True, config=config) as f:
        assert_completed(f, p2=p2)
        c = f.vehicle_counters()
    if loss > 0:
        assert c["drop_out"] >= 0.5 * loss * c["tx"] and c["drop_in"] >= 0.5 * loss * c["rx"], c  # the fault acted
    return c


class TestLossyLinks:
    def test_lossy_late_and_briefly_blacked_out_links_still_fly_the_mission(self, tmp_path: Path) -> None:
        """10% loss each way with 100 ms latency, 50 ms jitter and 0.5 s blackouts before (RIDING)
        and after separation (NAVIGATING); and 30% loss each way. Reaction: none needed, the
        mission completes (exit 0): commands are retried, the 50 Hz stream outlives the 1 s
        offboard-loss timeout, a silent position stream only makes the controller hover, and the
        vehicle counts as lost only when its HEARTBEAT and its telemetry are both gone.

        With 100-150 ms of latency the passenger is only asked to end within 1 m of the target, not
        inside the 0.5 m arrival radius (P2): the tracking loop, tuned on PX4's ~0 ms, rings at
        arrival under that delay and once coasted out to 0.53 m while Hold was being confirmed.

        The late flight's mission waits 5 s for a HEARTBEAT (mission.heartbeat_timeout_s), as a user of
        such a link would set it: with the 3 s default, two HEARTBEATs lost in a row (1 % at 10 %
        loss) and the next one 100-150 ms late, across a blackout that silences the telemetry too, is
        a lost vehicle by design (seen once in about 20 runs: last HEARTBEAT at 6.105 s, abort at
        9.12 s, the next one arriving at 9.13 s). Its loss pattern is not the same every run: with
        latency the lockstep flight is not deterministic (mission ticks 2108-2358 in four runs)."""
        late = ("--latency-ms", "100", "--jitter-ms", "50", "--blackout", "8.5:0.5", "--blackout", "18.5:0.5")
        c10, c30 = concurrently(lambda: _lossy(tmp_path, "loss10", 0.1, 1, late, p2=False, heartbeat_timeout_s=5.0),
                                lambda: _lossy(tmp_path, "loss30", 0.3, 2))
        assert c10["drop_in"] > 0 and c10["drop_out"] > 0
        assert 0.2 < c30["drop_out"] / c30["tx"] < 0.4


class TestFullLossMatrix:
    @pytest.mark.skipif(not FULL, reason="larger fault matrix: set MARSUPIAL_FAULTS_FULL=1")
    @pytest.mark.parametrize("loss", [0.05, 0.2, 0.3, 0.4])
    @pytest.mark.parametrize("seed", [11, 12, 13])
    def test_full_loss_matrix(self, tmp_path: Path, loss: float, seed: int) -> None:
        _lossy(tmp_path, f"loss{loss}-{seed}", loss, seed, ("--latency-ms", "50", "--jitter-ms", "50"))


def _long_blackout(tmp_path: Path, name: str, start_s: float, after_separation: bool) -> None:
    with flight(tmp_path, name, vehicle_args=("--blackout", f"{start_s}:3"), lockstep=True) as f:
        f.wait_mission(40.0)
        assert_exit(f, 3, "vehicle_lost")
        assert_log_complete(f, "ABORT", "vehicle_lost")
        phases = [r["phase"] for r in f.record()]
        assert ("NAVIGATING" in phases) == after_separation and "RIDING" in phases
        # PX4's offboard-loss failsafe (COM_OBL_RC_ACT 0, no RC): POSCTL holding position,
        # descending; it lands and disarms by itself.
        assert_safe_end(f, modes=("landed",), timeout_s=20.0)
        modes = f.modes_seen()
        assert modes[modes.index("OFFBOARD"):][:2] == ["OFFBOARD", "POSCTL"], modes
        assert_never_disarmed_in_the_air(f)  # (the failsafe STATUSTEXT fell in the blackout)


class TestLongBlackouts:
    def test_long_blackouts_before_and_after_separation_lose_the_vehicle_and_px4_lands(self, tmp_path: Path) -> None:
        """3 s of silence both ways while riding and while navigating. The blackout starts just
        before a whole second, so the last HEARTBEAT is ~1 s old and the 3 s timeout fires ~0.95 s
        (simulated) before the link comes back. Reaction: abort vehicle_lost (exit 3), stop
        streaming; PX4 leaves OFFBOARD after COM_OF_LOSS_T into POSCTL, descends, lands, disarms."""
        # demo.toml on the mock's default estimate (seed 0) separates ~18.9 s into the vehicle's clock:
        # simulated 16.92 s (riding 4.50 s + 12.42 s), exact 16.26 s, which the exact mock flew at
        # 18.26 s; it arrives ~4.7 s later. 17.95 s fell before the separation with the errors.
        concurrently(lambda: _long_blackout(tmp_path, "riding", 9.95, False),
                     lambda: _long_blackout(tmp_path, "navigating", 20.95, True))


# Lockstep flights acted on from outside at a phase the test reads (a kill, a pilot): at most
# SPEED simulated seconds per wall second, so the flight never runs away from the test's reaction;
# the vehicle drops a silent controller after 8 s (wall) rather than 10: longer than the controller
# waits for its carrier (2 s for a dead one, mission.time.clock.CARRIER_WATCHDOG_WALL_S, or one that
# an outage made lose a message, LOST_WALL_S; for a slow one whose liveliness token is present it
# waits up to sim.lockstep_carrier_wait_wall_s and tells the vehicle meanwhile that it still works
# on the step), so a carrier fault never looks like offboard loss.
PACED = ("--lockstep-max-speed", str(SPEED), "--lockstep-watchdog", "8")


def _mission_killed(tmp_path: Path) -> None:
    with flight(tmp_path, "killed", lockstep=True, vehicle_args=PACED) as f:
        f.wait_phase("RIDING")
        wait_for(lambda: len(f.record()) > 0 and f.record()[-1]["phase"] == "RIDING", 10.0, "RIDING in the record")
        # and the carrier drives: it heard RIDING at a step of its own (the mission printing it is
        # not enough: under two busy loops the kill came first 2 times in 3, and a carrier that
        # never moved has nothing to pause)
        wait_for(lambda: "-> approaching" in f.text("carrier.err"), 10.0, "carrier approaching")
        rows_before = len(f.record())
        f.procs["mission"].send_signal(signal.SIGKILL)
        assert f.procs["mission"].wait(timeout=5.0) == -signal.SIGKILL
        # COM_OBL_RC_ACT = 0 with no RC: POSCTL, hold position, descend, land, disarm.
        assert_safe_end(f, modes=("landed",), timeout_s=20.0)
        modes = f.modes_seen()
        assert modes[-2:] == ["OFFBOARD", "POSCTL"], modes
        assert "Failsafe activated: offboard loss" in statustexts(f)
        assert_never_disarmed_in_the_air(f)
        # The record holds every tick up to the kill (one write per tick); no summary was
        # written, but one can be made from the record.
        rows = f.record()
        assert len(rows) >= rows_before and rows[-1]["phase"] == "RIDING"
        assert not (f.log_dir / "summary.json").exists()
        assert summarise(f.log_dir)["max_offset_before_separation_m"] is not None
        _assert_mcap_up_to_the_last_second(f.log_dir, float(rows[-1]["t_s"]))
        # the carrier stops when the passenger's liveliness token disappears
        wait_for(lambda: "-> paused" in f.text("carrier.err"), 10.0, "carrier paused")


def _assert_mcap_up_to_the_last_second(log_dir: Path, last_tick_s: float) -> None:
    """A killed mission's flight.mcap: no footer, an unfinished last chunk, and every message up
    to the last chunk it finished (one per second of mission clock), the record's rows among
    them, the same as record.csv's."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader

    content = read_messages(log_dir / "flight.mcap")
    assert not content.complete and content.metadata["clock"]["clock"] == "mission"
    mcap_rec, csv_rec = read_record(log_dir / "flight.mcap"), read_record(log_dir)
    assert last_tick_s - 1.1 <= mcap_rec.t[-1] <= last_tick_s, (mcap_rec.t[-1], last_tick_s)
    n = len(mcap_rec.t)
    assert (mcap_rec.t == csv_rec.t[:n]).all() and (mcap_rec.phase == csv_rec.phase[:n]).all()
    assert np.array_equal(mcap_rec.vec("x_p"), csv_rec.vec("x_p")[:n], equal_nan=True)
    seen = 0  # the mcap package's own reader reads it too, up to the chunk the writer never finished
    with open(log_dir / "flight.mcap", "rb") as fh:
        with pytest.raises(McapError):
            for _ in NonSeekingReader(fh).iter_messages(log_time_order=False):
                seen += 1
    assert seen == len(content.messages)


def _gcs_takeover(tmp_path: Path) -> None:
    with flight(tmp_path, "takeover", lockstep=True, vehicle_args=PACED) as f:
        f.wait_phase("RIDING")
        assert f.gcs is not None
        ack = f.gcs.set_mode(px4.HOLD)
        assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED
        f.wait_mission(20.0)
        assert_exit(f, 5, "pilot_override")
        assert "vehicle switched to AUTO.LOITER" in f.text("mission.err")
        assert_log_complete(f, "ABORT", "pilot_override")
        assert f.record()[-1]["u_cmd_n"] == "nan"  # nothing sent once the pilot took over
        v = assert_safe_end(f, modes=("AUTO.LOITER",))
        assert v["ned"][2] < -0.5
        assert f.modes_seen()[-1] == "AUTO.LOITER"  # never switched back: no fight


def _forced_disarm(tmp_path: Path) -> None:
    with flight(tmp_path, "disarmed", lockstep=True, vehicle_args=PACED) as f:
        f.wait_phase("RIDING")
        wait_for(lambda: "-> approaching" in f.text("carrier.err"), 10.0, "carrier approaching")
        assert f.gcs is not None  # a rogue ground station: COMPONENT_ARM_DISARM(0, 21196) in the air
        ack = f.gcs.arm(False, force=True)
        assert ack is not None and ack.result == px4.MAV_RESULT_ACCEPTED
        f.wait_mission(20.0)
        assert_exit(f, 5, "vehicle_disarmed")
        assert_log_complete(f, "ABORT", "vehicle_disarmed")
        tlog = f.tlog()
        t_disarmed = next(t for t, m in tlog if m.get_type() == "STATUSTEXT" and "Disarmed by external command" in m.text)
        rows = f.record()
        t_abort = float(rows[-1]["t_s"])
        assert rows[-2]["phase"] == "RIDING" and rows[-1]["u_cmd_n"] == "nan"
        # the verdict needs two agreeing samples (mission.mavlink.telemetry): a disarmed HEARTBEAT
        # with an ON_GROUND EXTENDED_SYS_STATE once the vehicle has fallen, or disarmed HEARTBEATs
        # DISARMED_AGREE_S apart; the mission must abort within a few ticks of the second one
        heard = [(t, m) for t, m in tlog if t > t_disarmed and m.get_srcComponent() == 1]
        hb = [t for t, m in heard if m.get_type() == "HEARTBEAT" and not m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED]
        ground = [t for t, m in heard if m.get_type() == "EXTENDED_SYS_STATE" and m.landed_state == px4.LANDED_ON_GROUND]
        t_agreed = min(max(hb[0], ground[0]), next((t for t in hb if t - hb[0] >= DISARMED_AGREE_S), math.inf))
        assert t_agreed - t_disarmed <= 1.5  # a fall from the ride, or the next two 1 Hz HEARTBEATs
        assert t_agreed - 0.005 <= t_abort <= t_agreed + 0.1, (t_disarmed, t_agreed, t_abort)  # on the mission clock
        sent = [t for t, m in tlog if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED" and m.get_srcComponent() == 191]
        assert sent[-1] < t_abort  # streaming stopped with the abort
        # the carrier stops, told why; the vehicle fell and lies on the ground, disarmed, still in OFFBOARD
        wait_for(lambda: "-> stopped (passenger aborted: vehicle_disarmed)" in f.text("carrier.err"), 10.0, "carrier stopped")
        assert_safe_end(f, modes=("landed",), timeout_s=20.0)
        assert f.modes_seen()[-1] == "OFFBOARD"
        print(f"forced disarm: agreed {t_agreed - t_disarmed:.3f} s after it, seen {t_abort - t_agreed:.3f} s later")
    assert f.carrier_summary()["mode"] == "stopped"


class TestMissionKilled:
    def test_mission_killed_pilot_takeover_and_a_forced_disarm(self, tmp_path: Path) -> None:
        """SIGKILL of ``marsupial run`` while riding: no background resend survives it, so PX4's
        offboard-loss failsafe fires (POSCTL, descend, land, disarm). A pilot (here a ground
        station) switching to Hold while riding: the mission stops commanding at once, exit 5.
        A rogue ground station's forced disarm while riding (the vehicle falls, as PX4's does): abort
        vehicle_disarmed within 0.5 s of the disarm on the mission clock (PX4's land detector says
        ON_GROUND 0.33 s after it; EXTENDED_SYS_STATE is asked at 10 Hz), nothing more sent, the
        carrier stopped with the reason, exit 5. All fly in lockstep until the event; the killed
        controller's vehicle goes on in real time after its watchdog (PX4's offboard-loss timer runs
        on the vehicle's simulated time)."""
        concurrently(lambda: _mission_killed(tmp_path), lambda: _gcs_takeover(tmp_path), lambda: _forced_disarm(tmp_path))


def _refused(tmp_path: Path, name: str, flag: str, text: str, reason: str) -> None:
    with flight(tmp_path, name, vehicle_args=(flag, text), lockstep=True) as f:
        f.wait_mission(30.0)
        assert_exit(f, 5, reason)
        assert text in f.text("mission.err")  # the vehicle's STATUSTEXT is the reason given
        assert_log_complete(f, "ABORT", reason)
        assert_safe_end(f, modes=("landed",), timeout_s=15.0)  # on the ground, disarmed
        assert_never_disarmed_in_the_air(f)


class TestRefusals:
    def test_arming_and_offboard_refused_and_position_estimate_lost(self, tmp_path: Path) -> None:
        """The vehicle refuses to arm, or to switch to OFFBOARD: bounded retries, then abort with
        the vehicle's reason (exit 5); it never leaves the ground (an armed one disarms itself).
        The vehicle loses its position estimate while riding: PX4's own failsafe takes it out of
        OFFBOARD (Descend); the mission stops commanding and exits 5."""
        concurrently(
            lambda: _position_lost(tmp_path),
            lambda: _refused(tmp_path, "arming", "--refuse-arming", "Arming denied: test preflight failure",
                             "arming_refused"),
            lambda: _refused(tmp_path, "offboard", "--refuse-offboard", "Offboard denied: test", "offboard_refused"))


def _position_lost(tmp_path: Path) -> None:
    with flight(tmp_path, "position", vehicle_args=("--lose-position", "10"), lockstep=True) as f:
        f.wait_mission(30.0)
        # PX4 itself leaves OFFBOARD for its failsafe (Descend, shown as AUTO.LAND); the
        # mission sees the vehicle leave OFFBOARD and stops commanding, never fights it.
        assert_exit(f, 5, "vehicle_failsafe")
        assert "vehicle switched to AUTO.LAND" in f.text("mission.err")
        assert "Failsafe activated: no local position" in f.text("mission.err")  # the vehicle's reason
        assert_log_complete(f, "ABORT", "vehicle_failsafe")
        assert_safe_end(f, modes=("landed",), timeout_s=20.0)
        assert f.modes_seen()[-2:] == ["OFFBOARD", "AUTO.LAND"]
        assert_never_disarmed_in_the_air(f)


# ----------------------------------------------------------------------------- carrier and Zenoh


def _carrier_killed(tmp_path: Path, name: str, during: str) -> None:
    with flight(tmp_path, name, lockstep=True, vehicle_args=PACED) as f:
        f.wait_phase(during)
        f.procs["carrier"].send_signal(signal.SIGKILL)
        f.procs["carrier"].wait(timeout=5.0)
        wait_for(lambda: not f.carrier_alive(), 5.0, "carrier token gone")
        first_log = len(f.text("carrier.err"))  # the restarted carrier appends to the same log
        if during == "RIDING":  # the controller waits 2 s (wall) for the dead carrier's step, then flies on without it
            f.wait_mission(30.0)
            f.start_carrier(lockstep=False)  # restarted, with no passenger riding: counts from seq 0 at its start
            assert_exit(f, 5, "carrier_lost")
            assert_log_complete(f, "ABORT", "carrier_lost")
            v = assert_safe_end(f, modes=("AUTO.LOITER",))  # Hold, armed, in the air
            assert v["ned"][2] < -0.5
            assert_never_disarmed_in_the_air(f)
        else:
            f.start_carrier(lockstep=False)  # restarted while the passenger navigates (real time: not a participant)
            assert_completed(f)
        wait_for(f.carrier_alive, 15.0, "restarted carrier up")
        # the restarted carrier never drives at the target without a riding passenger
        assert "-> approaching" not in f.text("carrier.err")[first_log:]


class TestCarrierKilled:
    def test_carrier_killed_and_restarted_before_and_after_separation(self, tmp_path: Path) -> None:
        """SIGKILL of the carrier while riding: its liveliness token goes at once; abort
        carrier_lost to Hold (exit 5); the restarted carrier does not move. While navigating: the
        anchor is latched, the mission completes (exit 0). In lockstep until the kill."""
        concurrently(lambda: _carrier_killed(tmp_path, "carrier-riding", "RIDING"),
                     lambda: _carrier_killed(tmp_path, "carrier-navigating", "NAVIGATING"))


def _router_restart(tmp_path: Path, name: str, during: str) -> None:
    router = Router()
    try:
        config = fleet_config(tmp_path / f"{name}.toml")
        with flight(tmp_path, name, router=router, config=config, lockstep=True, vehicle_args=PACED) as f:
            f.wait_phase(during)
            router.close()
            router.open()  # same port; the clients reconnect within ~0.2 s
            if during == "RIDING":
                f.wait_mission(30.0)
                assert_exit(f, 5, "carrier_lost")
                assert "carrier liveliness token gone" in f.text("mission.err")
                assert_log_complete(f, "ABORT", "carrier_lost")
                assert_safe_end(f, modes=("AUTO.LOITER",))
            else:  # a clock message or sample the outage lost is asked again or given up: still in step
                assert_completed(f)
                assert "the controller is gone" not in f.text("vehicle.err")
            wait_for(f.carrier_alive, 10.0, "carrier reconnected to the restarted router")
    finally:
        router.close()


class TestRouterRestart:
    def test_zenoh_router_restart_in_the_fleet_configuration(self, tmp_path: Path) -> None:
        """Every process a Zenoh client of one router (configs/zenoh/fleet_client.json5); the router
        is closed and reopened on the same port. A router outage drops the carrier's liveliness
        token at once, so before separation it is a lost carrier whatever its length: abort to
        Hold (exit 5). After separation the mission completes (exit 0). In lockstep (paced): during
        the outage simulated time stands still (the controller waits for the carrier's step, and
        calls again while unanswered: under ``-n 2`` a call sent as the route came back was lost, the
        vehicle dropped the waiting controller and PX4's offboard-loss failsafe ended the flight), and
        the token is back before the next tick, which must still see that it went."""
        concurrently(lambda: _router_restart(tmp_path, "router-riding", "RIDING"),
                     lambda: _router_restart(tmp_path, "router-navigating", "NAVIGATING"))
