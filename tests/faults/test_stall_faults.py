"""A stalled controller on the recovery's approach, on the real processes of a pair (mock PX4,
``marsupial carrier``, ``marsupial run``) over real UDP and Zenoh, flying configs/recovery.toml:
``marsupial run`` stopped (SIGSTOP) for 1 s of the flight's clock 2 s into the approach, then
continued (SIGCONT), as a companion computer stalls. It goes around, at once, naming the stall,
and docks at the next approach; nothing jumps (mission/phases/stall.py, docs/recovery.md).

Not in lockstep: a stopped controller would stop the vehicle's clock with it, and the gap is the
point. The pair runs on a scaled wall clock (``SPEED``), so the stall is ``1 / SPEED`` wall
seconds. The mock's offboard loss comes at ``COM_OF_LOSS_T`` to the dot, PX4 SITL's came 2 s
after the last setpoint (docs/recovery.md, "PX4's home"): the mock here gets 1.5 s, so a 1 s gap
and its scheduling slack stay inside it as on PX4 (a longer stall ends in PX4's own failsafe:
docs/safety.md). Every wait is on an event of the flight (its record, its phases); 38-46 s.

The second flight stops the carrier and the controller while the passenger rides and at the
target (:data:`STALLS`): the mission carries on through each, to the return (docs/recovery.md,
"Riding and at the target"); at x1, 49 s (load average 12, nice 15).

Real time, so a machine that starves the pair fails it however the stall is handled: it passed
at load average 5-10 on 2 cores; at 10-27 (five test suites and PX4 flights beside it) it failed
4 times before or after the stall, on the machine's own stalls (a carrier state 0.8-2.1 s old
while riding; the mock's offboard loss in NAVIGATING; the vehicle silent for 3 s).
"""
from __future__ import annotations

import math
import signal
import time
from pathlib import Path
from typing import Any

import pytest

from mission.config.schema import load_config
from mission.model import mission_model
from mission.phases import TELEMETRY_SILENT_S
from mission.phases.stall import SETTLE_S as SETTLE_S_MISSION, STALL_S as STALL_S_MISSION
from tests.conftest import CONFIGS
from tests.faults.procs import assert_log_complete, assert_safe_end, flight, wait_for
from tests.faults.test_matrix import assert_never_disarmed_in_the_air
from tests.faults.test_recovery_faults import _approach_flown_s, _rows

pytestmark = [pytest.mark.slow, pytest.mark.timeout(150)]

SPEED = 2.0  # the pair's clock: x2 the wall clock
STALL_S = 1.0  # [s] of the flight's clock: the controller stopped this long
AFTER_S = 2.0  # [s] into the approach (of ~11 s): the passenger on the glide path
JUMP_M_S = 0.05  # [m/s] the command's change a tick that counts as a jump (summary's max_phase_switch_jump_m_s)
#: [m] the reference's (the dock point's) step a tick beyond the carrier's speed x the tick: a jump.
#: Measured up to 0.052 m, at the first fresh state after the carrier's stop (the prediction's
#: error: 2.6 cm of the carrier's 2 m/s), PX4's position loop making 0.05 m/s of it
DOCK_STEP_M = 0.1


def _config(tmp_path: Path) -> Path:
    """configs/recovery.toml with the carrier budgets of the PX4 configurations (a loaded 2-core
    machine stalls a process of the pair 0.5 s at times, at x2 a second of the flight's clock:
    with recovery.toml's 0.5 s the mission once lost the carrier while riding, before the stall)."""
    text = (CONFIGS / "recovery.toml").read_text()
    assert "carrier_timeout_s = 0.5\n" in text and "[recovery]\n" in text
    path = tmp_path / "stall.toml"
    path.write_text(text.replace("carrier_timeout_s = 0.5\n", "carrier_timeout_s = 1.0\n")
                    .replace("[recovery]\n", "[recovery]\ncarrier_max_age_s = 0.6\n"))
    return path


def test_a_controller_stalled_1_s_on_the_approach_goes_around_and_docks_at_the_next(tmp_path: Path) -> None:
    with flight(tmp_path, "stall", config=_config(tmp_path), speed=SPEED, mission_verbose=True,
                vehicle_args=("--param", "COM_OF_LOSS_T=1.5")) as f:
        f.wait_phase("APPROACH", timeout_s=90.0)
        wait_for(lambda: _approach_flown_s(f) >= AFTER_S, 30.0, "the passenger on the glide path")
        mission = f.procs["mission"]
        mission.send_signal(signal.SIGSTOP)
        time.sleep(STALL_S / SPEED)  # the fault itself: its length is measured below, from the record
        mission.send_signal(signal.SIGCONT)
        assert f.wait_mission(90.0) == 0, (f.phases(), f.text("mission.err")[-2000:])
        s = assert_log_complete(f, "DONE", None)
        assert_safe_end(f, modes=("AUTO.LOITER",))
        assert_never_disarmed_in_the_air(f)
        assert "OFFBOARD" in f.modes_seen() and not any("Failsafe" in t for t in f.text("vehicle.err").splitlines())
    rows = _rows(f)
    gaps = [(b["t_s"] - a["t_s"], i + 1) for i, (a, b) in enumerate(zip(rows, rows[1:]))]
    gap, i = max(gaps)
    assert STALL_S - 0.05 <= gap <= 1.5, gap  # the stall, seen by the mission's clock (not PX4's offboard loss)
    # The first ticks after the gap may find no vehicle position read since (the link's thread
    # stalled too): they resend the last command by velocity only; the first that reads one goes
    # round, naming the stall. The stop may also land inside a tick, after it read its clock: that
    # tick, the record's last before the gap, reads the carrier's states a stall old and goes round
    # on their age (once on CI: "carrier state 1.03 s old", the stall named on the next tick).
    g = next(j for j in range(i - 1, len(rows)) if rows[j]["phase"] != "APPROACH")
    assert rows[g - 1]["phase"] == "APPROACH" and rows[g]["phase"] == "GO_AROUND", (rows[g - 1]["phase"], rows[g]["phase"])
    err = f.text("mission.err")
    if g == i - 1:  # stopped inside the tick that went round
        assert "go-around: carrier state" in err and "stalled: no tick for" in err, err[-2000:]
    else:
        assert rows[g]["t_s"] - rows[i]["t_s"] < 0.2
        last = (rows[i - 1]["u_cmd_n"], rows[i - 1]["u_cmd_e"], rows[i - 1]["u_cmd_d"])
        assert all((r["u_cmd_n"], r["u_cmd_e"], r["u_cmd_d"]) == last for r in rows[i:g])
        assert "go-around: no tick for" in err and "(the controller stalled; recovery.carrier_max_age_s = 0.6)" in err, err[-2000:]
    phases = f.phases()
    k = phases.index("GO_AROUND")
    assert phases[k - 1:k + 5] == ["APPROACH", "GO_AROUND", "HOLDOFF", "APPROACH", "DOCKED", "HOME"], phases
    assert s["docked_again"] and s["recovery_outcome"] == "docked" and s["contact"]["attempts"] == 2, s
    assert s["contact"]["horizontal_error_m"] <= 0.10 and s["contact"]["horizontal_relative_speed_m_s"] <= 0.2, s
    assert s["deck_violations"] == 0, s
    # The first commands after the gap go on from the vehicle's velocity (the restart; for the
    # settling, 0.2 s, they follow it), then change by at most the passenger's acceleration limit
    # a tick. Not from the last command before the gap: PX4 flew the stale setpoint for the gap
    # and the vehicle no longer moves as it was told (on the mock it slowed from 1.7 to 1.2 m/s),
    # so the summary's switch jump (command to command) is not this flight's measure.
    t0 = rows[i]["t_s"]
    after = max(g, i)  # the first tick after the gap that flies the go-around
    settling = [r for r in rows[after:] if r["t_s"] - t0 < 0.2]
    for r in settling:  # a tick's change (0.04 m/s) and tracking's terms on it: up to 0.059 m/s measured
        cmd, vel = (r["u_cmd_n"], r["u_cmd_e"], r["u_cmd_d"]), (r["v_p_n"], r["v_p_e"], r["v_p_d"])
        assert math.dist(cmd, vel) <= 0.1, (r["t_s"], cmd, vel)
    j = after + len(settling)
    for a, b in zip(rows[j:j + 100], rows[j + 1:j + 101]):
        step = math.dist((a["u_cmd_n"], a["u_cmd_e"], a["u_cmd_d"]), (b["u_cmd_n"], b["u_cmd_e"], b["u_cmd_d"]))
        assert step <= JUMP_M_S, (b["t_s"], step)


def _flown_s(f: Any, phase: str) -> float:
    """How long [s] the mission has been in ``phase`` since it first entered it (record time; 0 before)."""
    rows = [r for r in f.record() if r.get("t_s")]  # complete rows (the record is read while it is written)
    start = next((float(r["t_s"]) for r in rows if r["phase"] == phase), None)
    return 0.0 if start is None or not rows else float(rows[-1]["t_s"]) - start


def _stop(f: Any, who: str) -> None:
    """``who``'s process (``mission``: the controller, ``carrier``) stopped for STALL_S of the flight's clock."""
    proc = f.procs[who]
    proc.send_signal(signal.SIGSTOP)
    time.sleep(STALL_S / f.speed)  # the fault itself: its length is measured from the record
    proc.send_signal(signal.SIGCONT)


#: [s] mission.carrier_lost_s of the flight: real time at x2 doubles the loaded machine's own stalls
#: of the carrier process (0.5-1.2 s of wall time at load average 10-20, beside the stop: at the
#: default 1.5 s one run lost the carrier in JOIN, its state 1.53 s old); carrier_lost_s itself is
#: tested on the fake world (tests/unit/phases/test_stall.py)
LOST_S = 3.0
#: The flight's clock: the wall clock (x1, not the approach flight's x2), which does not double the
#: loaded machine's own stalls of the pair (at x2, load average 10-20: a 1.3 s stall of the loop
#: and a 3 s silence of the vehicle, each beside the stops, ended two of three flights).
RIDE_SPEED = 1.0

#: After the controller's stop while riding: [s] the time the vehicle takes to catch up with the
#: dock point again (measured 1.4 s), and [m] how far from it it may seem meanwhile (measured 1.27
#: on the first tick after the gap, 2.27 on the tick the stop caught: see the test)
CATCH_UP_S = 2.5
CATCH_UP_OFFSET_M = 2.5

#: (process stopped, phase, [s] into it): the carrier, then the controller, while the passenger
#: rides (of ~12 s); the controller, then the carrier, at the target (of mission.at_target_s, 5 s)
STALLS = (("carrier", "RIDING", 2.0), ("mission", "RIDING", 6.0), ("mission", "ARRIVED", 1.0), ("carrier", "ARRIVED", 3.0))


def test_stalls_while_riding_and_at_the_target_and_the_mission_carries_on(tmp_path: Path) -> None:
    """One flight, four 1 s stops (:data:`STALLS`), configs/recovery.toml (its carrier budget,
    mission.carrier_timeout_s = 0.5 s, is shorter than the carrier's stop: the ride goes on on the
    predicted dock point) with mission.carrier_lost_s = :data:`LOST_S`: the mission carries on
    through each, separates at b c, and begins the return when the task at the target is done;
    nothing jumps. The flight is interrupted there (SIGINT: Hold): the recovery after the stops is
    the approach flight's subject (a whole recovery at x1 on a loaded machine timed out in 2 of 5
    runs on the machine's own stalls, going round "off the glide path")."""
    text = (CONFIGS / "recovery.toml").read_text()
    assert "carrier_timeout_s = 0.5\n" in text
    path = tmp_path / "stalls.toml"
    path.write_text(text.replace("carrier_timeout_s = 0.5\n", f"carrier_timeout_s = 0.5\ncarrier_lost_s = {LOST_S}\n"))
    cfg = load_config(path)
    model = mission_model(cfg)
    assert model.command_safety.max_accel_m_s2 is not None
    ramp = model.command_safety.max_accel_m_s2 * model.dt_s  # [m/s] the command's largest change a tick
    with flight(tmp_path, "stalls", config=path, speed=RIDE_SPEED, mission_verbose=True,
                vehicle_args=("--param", "COM_OF_LOSS_T=1.5")) as f:
        for who, phase, after_s in STALLS:
            f.wait_phase(phase, timeout_s=90.0)
            wait_for(lambda: _flown_s(f, phase) >= after_s, 30.0, f"{after_s} s into {phase}")
            assert f.phases()[-1] == phase, (who, phase, f.phases())
            _stop(f, who)
        f.wait_phase("RETURNING", timeout_s=30.0)
        f.procs["mission"].send_signal(signal.SIGINT)
        assert f.wait_mission(30.0) == 5, (f.phases(), f.text("mission.err")[-2000:])
        s = assert_log_complete(f, "ABORT", "interrupted")
        assert_safe_end(f, modes=("AUTO.LOITER",))
        assert_never_disarmed_in_the_air(f)
        assert not any("Failsafe" in t for t in f.text("vehicle.err").splitlines())
    err = f.text("mission.err")
    phases = f.phases()
    k = phases.index("RIDING")
    assert phases[k:] == ["RIDING", "SEPARATED", "NAVIGATING", "ARRIVED", "RETURNING", "ABORT"], phases
    assert s["p2"] and s["p3"], s
    assert s["carrier_target_distance_at_separation_m"] == pytest.approx(cfg.law.b * cfg.law.c, abs=0.02), s
    rows = _rows(f)
    # The carrier's stop while riding: its state aged past mission.carrier_timeout_s, the ride went
    # on on the predicted dock point (no abort, no latch on it), and the state came fresh again.
    assert "riding the dock point predicted with its age, no separation on it" in err, err[-3000:]
    fresh = [float(line.split("fresh again after ")[1].split()[0]) for line in err.splitlines() if "fresh again after" in line]
    assert fresh and max(fresh) >= STALL_S - cfg.mission.carrier_timeout_s - 0.1, fresh
    riding = [r for r in rows if r["phase"] == "RIDING"]
    oldest = max(riding, key=lambda r: r["carrier_age_s"])
    assert STALL_S - 0.1 <= oldest["carrier_age_s"] <= cfg.mission.carrier_timeout_s + LOST_S, oldest
    k = rows.index(oldest)
    window = [r for r in rows if oldest["t_s"] - 1.5 <= r["t_s"] <= oldest["t_s"] + 1.0 and r["phase"] == "RIDING"]
    woke = [b["t_s"] for a, b in zip(rows, rows[1:]) if b["t_s"] - a["t_s"] > STALL_S_MISSION]
    for a, b in zip(window, window[1:]):  # the command and the reference (the dock point) go on smoothly
        if any(0.0 <= b["t_s"] - w < SETTLE_S_MISSION + 0.1 for w in woke):
            continue  # the loop's own stalls (the reference restarts on the vehicle there): below
        step = math.dist(*((r["u_cmd_n"], r["u_cmd_e"], r["u_cmd_d"]) for r in (a, b)))
        assert step <= JUMP_M_S, (b["t_s"], step)
        moved = math.dist(*((r["x_ref_n"], r["x_ref_e"], r["x_ref_d"]) for r in (a, b)))
        expected = math.hypot(b["v_c_n"], b["v_c_e"], b["v_c_d"]) * (b["t_s"] - a["t_s"])
        assert abs(moved - expected) <= DOCK_STEP_M, (b["t_s"], moved, expected, rows[k]["t_s"])
    # After every stall of the loop (the two stops, and any the machine made), the command went on
    # from the vehicle's velocity (the summary's figure; 0.059 m/s measured on the approach).
    assert s["max_stall_command_offset_m_s"] is not None and s["max_stall_command_offset_m_s"] <= 0.1, s
    # P1 (the vehicle within mission.dock_tolerance_m of the dock point while riding) held through
    # the carrier's stop and everywhere but the CATCH_UP_S after the controller's: for that gap PX4
    # (the mock as PX4) flew the last full setpoint, whose position stayed where the dock was, and
    # its position loop braked the vehicle towards it while the carrier drove on at 2 m/s (measured:
    # 0.65-0.77 m behind once positions were read again, 1.27 m on the first tick with a position
    # read before the gap). Not the mission's to prevent in the gap: docs/recovery.md.
    # The window begins with the tick the stop caught (it read the carrier's state, aged by the
    # stop, after it, and the vehicle's position from before: 2.27 m apart in one run).
    stop = max(((a["t_s"], b["t_s"]) for a, b in zip(riding, riding[1:])), key=lambda ab: ab[1] - ab[0])
    for r in riding[1:]:
        off = math.dist((r["x_p_n"], r["x_p_e"], r["x_p_d"]), (r["dock_n"], r["dock_e"], r["dock_d"]))
        if math.isnan(off):  # no dock point worked out: only on the tick before the vehicle is read again
            assert r["vehicle_age_s"] > TELEMETRY_SILENT_S, r  # (its last command repeated: stall.unread)
            continue
        caught_up = not stop[0] <= r["t_s"] < stop[1] + CATCH_UP_S
        assert off <= (cfg.mission.dock_tolerance_m if caught_up else CATCH_UP_OFFSET_M), (r["t_s"], off, stop)
    # The controller's stops, riding and at the target: the gap seen by the mission's clock, the
    # phase the same on both sides, the first commands from the vehicle's velocity, then no jump.
    gaps = sorted(((b["t_s"] - a["t_s"], i + 1) for i, (a, b) in enumerate(zip(rows, rows[1:]))), reverse=True)[:2]
    assert all(STALL_S - 0.05 <= gap <= 1.5 for gap, _ in gaps), gaps
    assert sorted(rows[i]["phase"] for _, i in gaps) == ["ARRIVED", "RIDING"], [rows[i]["phase"] for _, i in gaps]
    assert err.count("stalled: no tick for") >= 2, err[-3000:]
    # riding, the reference restarted on the vehicle and chased the dock point back (not left on
    # it, 0.63-0.77 m ahead of the vehicle, for PX4's position loop to pull it there)
    assert "the reference goes on from the vehicle, chasing the dock point" in err, err[-3000:]
    for _, i in gaps:
        assert rows[i - 1]["phase"] == rows[i]["phase"], (rows[i - 1]["phase"], rows[i]["phase"])
        t0 = rows[i]["t_s"]
        # the settling, as on the approach; the tick before the vehicle is read again repeats the last
        # command (stall.unread) beside the velocity from before the gap: nothing to compare there
        for r in [r for r in rows[i:] if r["t_s"] - t0 < 0.2 and not r["vehicle_age_s"] > TELEMETRY_SILENT_S]:
            cmd, vel = (r["u_cmd_n"], r["u_cmd_e"], r["u_cmd_d"]), (r["v_p_n"], r["v_p_e"], r["v_p_d"])
            assert math.dist(cmd, vel) <= 0.1, (r["t_s"], cmd, vel)
        # then it ramps back to the law's command at most at the command's acceleration limit a
        # tick (riding, measured: 0.060 m/s a tick for 0.2 s after the settling), never faster
        j = next(n for n in range(i, len(rows)) if rows[n]["t_s"] - t0 >= 0.2)
        for a, b in zip(rows[j:j + 100], rows[j + 1:j + 101]):
            step = math.dist((a["u_cmd_n"], a["u_cmd_e"], a["u_cmd_d"]), (b["u_cmd_n"], b["u_cmd_e"], b["u_cmd_d"]))
            assert step <= ramp + 1e-3, (b["t_s"], step, ramp)
