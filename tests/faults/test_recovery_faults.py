"""Faults of the recovery, on the real processes of a pair (mock PX4, ``marsupial carrier``,
``marsupial run``) over real UDP and Zenoh, in lockstep, flying configs/recovery.toml (the
carrier drives away from the target at 1.5 m/s while the passenger comes home):

- the carrier killed during the approach: the passenger climbs and goes around within 1 s, then
  falls back (Hold off the carrier's path) once no fresh carrier state came for
  recovery.carrier_lost_s;
- the carrier turning 90 deg during the approach (a scripted carrier.recovery_course): the
  passenger goes around and approaches again, and docks.

Timeline of configs/recovery.toml in record seconds (the mission's clock): RETURNING ~28.6 s,
APPROACH ~34.8 s, DOCKED ~45.8 s; the carrier's course starts when it hears RETURNING.
"""
from __future__ import annotations

import math
import signal
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import CONFIGS
from tests.faults.procs import assert_log_complete, assert_safe_end, flight, wait_for
from tests.faults.test_matrix import PACED, assert_never_disarmed_in_the_air, concurrently

pytestmark = [pytest.mark.slow, pytest.mark.timeout(150)]

RECOVERY = CONFIGS / "recovery.toml"
AWAY_DEG = math.degrees(math.atan2(-18.0, -24.0)) % 360.0  # the carrier's course: from the target through its stop
KILL_AFTER_S = 4.0  # [s] into the approach (of ~11 s): the passenger ~1 m down the glide path
TURN_AFTER_S = 10.0  # [s] into the recovery (~3.5 s into the approach): the carrier turns 90 deg


def _config(tmp_path: Path, name: str, carrier: str = "") -> Path:
    text = RECOVERY.read_text()
    assert "[carrier]\n" in text
    path = tmp_path / f"{name}.toml"
    path.write_text(text.replace("[carrier]\n", f"[carrier]\n{carrier}"))
    return path


def _rows(f: Any) -> list[dict[str, float | str]]:
    return [{k: (v if k in ("phase", "mode") else float(v)) for k, v in row.items()} for row in f.record()]


def _first(rows: list[dict[str, Any]], phase: str, after_s: float = -math.inf) -> dict[str, Any]:
    return next(r for r in rows if r["phase"] == phase and r["t_s"] > after_s)


def _approach_flown_s(f: Any) -> float:
    """How long [s] the passenger has been on its first approach (record time; 0 before it)."""
    rows = f.record()
    start = next((float(r["t_s"]) for r in rows if r["phase"] == "APPROACH"), None)
    return 0.0 if start is None or not rows else float(rows[-1]["t_s"]) - start


def _carrier_killed_on_the_approach(tmp_path: Path) -> None:
    with flight(tmp_path, "killed", config=_config(tmp_path, "killed"), lockstep=True, vehicle_args=PACED) as f:
        f.wait_phase("APPROACH", timeout_s=90.0)
        wait_for(lambda: _approach_flown_s(f) >= KILL_AFTER_S, 30.0, "the passenger down the glide path")
        f.procs["carrier"].send_signal(signal.SIGKILL)
        f.procs["carrier"].wait(timeout=5.0)
        assert f.wait_mission(90.0) == 0, (f.phases(), f.text("mission.err")[-2000:])
        s = assert_log_complete(f, "DONE", None)
        assert_safe_end(f, modes=("AUTO.LOITER",))
        assert_never_disarmed_in_the_air(f)
    rows = _rows(f)
    # the carrier's last state: the last tick that saw it fresh and alive on the approach
    lost = max(r["t_s"] for r in rows if r["phase"] == "APPROACH" and r["carrier_age_s"] <= 0.05)
    around = _first(rows, "GO_AROUND", lost)
    assert around["t_s"] - lost <= 1.0, (lost, around["t_s"])
    climb = [r for r in rows if around["t_s"] <= r["t_s"] <= around["t_s"] + 1.0]
    assert min(r["u_cmd_d"] for r in climb) < -0.1  # climbing (NED: up is negative) within 1 s
    fallback = _first(rows, "FALLBACK", lost)
    assert fallback["t_s"] - lost == pytest.approx(3.0, abs=0.1)  # recovery.carrier_lost_s after the last state
    assert [p for p in f.phases() if p not in ("HOLDOFF", "GO_AROUND")][-4:] == ["APPROACH", "FALLBACK", "HOLD", "DONE"]
    assert s["docked_again"] is False and s["recovery_outcome"].startswith("fallback: no fresh carrier state"), s
    assert s["deck_violations"] == 0 and s["max_phase_switch_jump_m_s"] <= 0.05, s


def _carrier_turns_on_the_approach(tmp_path: Path) -> None:
    legs = f"recovery_course = [[{AWAY_DEG:.3f}, 1.5, {TURN_AFTER_S}]]\nrecovery_heading_deg = {AWAY_DEG + 90.0:.3f}\n"
    # an exact estimate: PX4's errors put the contact 0.03-0.15 m off by seed (this flight, seed 0: 0.123 m)
    with flight(tmp_path, "turn", config=_config(tmp_path, "turn", legs), lockstep=True,
                vehicle_args=("--estimate-error", "0")) as f:
        assert f.wait_mission(120.0) == 0, (f.phases(), f.text("mission.err")[-2000:])
        s = assert_log_complete(f, "DONE", None)
    rows = _rows(f)
    heading = [(r["t_s"], math.degrees(math.atan2(r["v_c_e"], r["v_c_n"])) % 360.0, r["phase"]) for r in rows
               if math.hypot(r["v_c_n"], r["v_c_e"]) > 1.0 and r["phase"] not in ("HOME", "HOLD", "DONE")]
    turn_t, _, turn_phase = next((t, h, p) for t, h, p in heading if abs(h - AWAY_DEG) > 2.0 and t > 30.0)
    assert turn_phase == "APPROACH"  # the carrier turned while the passenger was on the approach
    around = _first(rows, "GO_AROUND", turn_t - 0.1)
    assert around["t_s"] - turn_t <= 1.0, (turn_t, around["t_s"])  # the turn seen within a second
    phases = f.phases()
    i = phases.index("GO_AROUND")
    assert phases[i:i + 4] == ["GO_AROUND", "HOLDOFF", "APPROACH", "DOCKED"], phases
    assert s["docked_again"] and s["contact"]["attempts"] == 2, s
    docked = _first(rows, "DOCKED")
    assert math.degrees(math.atan2(docked["v_c_e"], docked["v_c_n"])) % 360.0 == pytest.approx(AWAY_DEG + 90.0, abs=1.0)
    assert s["contact"]["horizontal_error_m"] <= 0.10 and s["contact"]["horizontal_relative_speed_m_s"] <= 0.2, s
    assert s["deck_violations"] == 0 and s["max_phase_switch_jump_m_s"] <= 0.05, s
    assert s["p3"] and s["min_carrier_target_distance_m"] >= 7.5 - 1e-3, s


def test_recovery_carrier_killed_or_turning_during_the_approach(tmp_path: Path) -> None:
    """The carrier killed during APPROACH: go-around (climbing) within 1 s, FALLBACK after
    recovery.carrier_lost_s, Hold (exit 0, recovery_outcome "fallback: ..."). The carrier turning
    90 deg during APPROACH: go-around within 1 s of the turn, a second approach, docked."""
    concurrently(lambda: _carrier_killed_on_the_approach(tmp_path), lambda: _carrier_turns_on_the_approach(tmp_path))
