"""The mission flown on a real PX4 SITL (SIH quadrotor), each flight a fresh PX4 in its own
network namespace, stopped by its pid (:mod:`sim.sitl.px4`). About 40 s of wall time each; the
flights fly at once (``conftest.px4_jobs``), each test checks its own; the two that hold the dock
and the target fly alone (``alone=True``: what they measure is PX4's hold, not the rig's CPU).

PX4's clock is measured against ours in every flight (from the flight's tlog) and must stay near
wall time: ``PX4_SIM_SPEED_FACTOR`` 1.03 makes up for SIH's loop falling behind here. Three
scenarios hold the dock and the target (docs/px4-hold.md): the shipped config, and in one more
flight a Remark-1 carrier at 2.5 m/s with the target at another bearing and height.
"""
from __future__ import annotations

import json
import signal
from pathlib import Path

import numpy as np
import pytest

from mission.mavlink import px4
from mission.config.schema import load_config
from mission.record.table import read_record
from sim.sitl.px4 import clock_ratio, patched_config, px4_flight
from sim.net import wait_for
from tests.conftest import CONFIGS
from tests.px4_sitl.conftest import ARRIVAL_RADIUS_M, HOVER_SPEED_M_S, LAST_METRE_S, RIDING_OFFSET_M, px4_job

pytestmark = [pytest.mark.slow, pytest.mark.timeout(240)]
PX4_SITL = CONFIGS / "px4_sitl.toml"
SPEED_FACTOR = 1.03


def _px4(msg) -> bool:
    """A HEARTBEAT of PX4's autopilot (the GCS link also forwards our controller's)."""
    return msg.get_srcComponent() == 1 and msg.autopilot == px4.MAV_AUTOPILOT_PX4


def _px4_in(mode: str):
    return lambda m: _px4(m) and px4.mode_name(m.custom_mode) == mode


def _check_clock(log_dir: Path) -> dict[str, float]:
    clock = clock_ratio(log_dir / "flight.tlog")
    assert clock is not None, "no LOCAL_POSITION_NED in the flight's tlog"
    print(f"PX4 clock / wall {clock['ratio']:.3f}, LOCAL_POSITION_NED {clock['rate_hz']:.1f} Hz")
    assert 0.9 <= clock["ratio"] <= 1.12, f"PX4 ran at {clock['ratio']:.3f}x wall time: the flight is not a real-time one"
    return clock




def _scenario(directory: Path, name: str, overrides: dict[str, str]) -> Path:
    """``configs/px4_sitl.toml`` with ``section.key = value`` lines changed (TOML values)."""
    config = directory / f"{name}.toml"
    config.write_text(patched_config(PX4_SITL.read_text(), overrides))
    load_config(config)
    return config


def _largest_offsets(log_dir: Path, n: int = 8) -> str:
    """The ``n`` riding ticks farthest from the dock point, with what they saw: a failed riding
    figure says whether it was a late sample or the vehicle."""
    r = read_record(log_dir)
    riding = np.flatnonzero(r.phase == "RIDING")
    off = np.linalg.norm(r.vec("x_p")[riding] - r.vec("dock")[riding], axis=1)
    dt = np.diff(r.t, prepend=np.nan)
    rows = [f"t {r.t[k]:.2f} s offset {off[i]:.3f} m, tick dt {dt[k]:.3f} s, vehicle age {r.cols['vehicle_age_s'][k]:.3f} s, "
            f"carrier age {r.cols['carrier_age_s'][k]:.3f} s" for i, k in sorted(enumerate(riding), key=lambda ik: -off[ik[0]])[:n]]
    return "the largest riding offsets:\n" + "\n".join(rows)


def _flown(f, config: Path) -> dict:
    rc = f.wait_mission(180.0)
    assert rc == 0, f"mission exit {rc}: {f.text('mission.out')[-1500:]}{f.text('mission.err')[-1500:]}"
    target = load_config(config).scenario.target
    after = f.watch_after(target, 2.0)  # PX4's own Hold once the mission has ended
    s = f.summary()
    print(json.dumps({k: s.get(k) for k in ("p1", "p2", "p3", "max_offset_before_separation_m", "riding_offset_held_m",
                                            "last_metre_s", "hover_speed_m_s",
                                            "max_target_distance_after_arrival_m", "relative_input_jump_m_s",
                                            "carrier_target_distance_at_separation_m", "position_rate_hz")}), f"hold {after:.2f} m")
    assert s["p1"] and s["p2"] and s["p3"], s
    assert abs(s["carrier_target_distance_at_separation_m"] - 8.0) < 0.01
    assert s["relative_input_jump_m_s"] <= 0.05  # the law's command is continuous at separation
    assert s["position_rate_hz"] >= 40.0, "PX4 did not stream LOCAL_POSITION_NED at the rate asked (50 Hz)"
    # held for two ticks: a one-tick spike is a sample read late by a stalled process, not the
    # vehicle's motion (docs/px4-hold.md); the raw maximum is P1's, against dock_tolerance_m
    if s["max_offset_before_separation_m"] > RIDING_OFFSET_M:
        print(_largest_offsets(f.log_dir))
    assert s["riding_offset_held_m"] <= RIDING_OFFSET_M, _largest_offsets(f.log_dir)
    assert s["last_metre_s"] is not None and s["last_metre_s"] <= LAST_METRE_S, s["last_metre_s"]
    assert s["hover_speed_m_s"] is not None and s["hover_speed_m_s"] <= HOVER_SPEED_M_S, s["hover_speed_m_s"]
    assert s["max_target_distance_after_arrival_m"] <= ARRIVAL_RADIUS_M  # once within 0.5 m, never outside
    # PX4's own Hold, after we handed the vehicle over inside the arrival radius: no swing back out.
    # Its SIH EKF holds its own estimate 0.4 m RMS off a point (docs/px4-hold.md), so from the edge
    # of the 0.5 m radius PX4 alone wanders 0.9 m at times (0.92 m seen): 1.2 m is a swing, not that.
    assert after <= 1.2, f"PX4's Hold drifted {after:.2f} m from the target"
    _check_clock(f.log_dir)
    return s


@px4_job("config", alone=True)
def _fly_config(directory: Path, build: Path) -> dict:
    with px4_flight(directory / "f", PX4_SITL, build=build, speed_factor=SPEED_FACTOR) as f:
        return _flown(f, PX4_SITL)


@px4_job("remark1", alone=True)
def _fly_a_fast_remark1_carrier_to_another_bearing_and_height(directory: Path, build: Path) -> dict:
    """A Remark-1 carrier (keeps its plan after separation) at 2.5 m/s (the shipped config: 2.0),
    and the target at another bearing (north-west instead of north-east) and 3 m higher: the two
    scenarios beyond the shipped config in one flight."""
    config = _scenario(directory, "remark1", {"scenario.carrier_mode": '"remark1"', "scenario.target": "[-18.0, 24.0, -8.0]",
                                              "carrier.max_speed_m_s": "2.5", "safety.carrier_max_speed_m_s": "2.5"})
    with px4_flight(directory / "f", config, build=build, speed_factor=SPEED_FACTOR) as f:
        return _flown(f, config)


@px4_job("killed")
def _fly_and_kill_the_controller(directory: Path, build: Path) -> None:
    with px4_flight(directory / "f", PX4_SITL, build=build, speed_factor=SPEED_FACTOR) as f:
        wait_for(lambda: "phase RIDING" in f.text("mission.out") or f.procs["mission"].poll() is not None, 60.0,
                 "the mission riding the carrier")
        assert f.procs["mission"].poll() is None, f.text("mission.out")
        mark = f.gcs.mark()
        assert f.gcs.wait_for("HEARTBEAT", _px4_in("OFFBOARD"), timeout_s=3.0) is not None
        f.procs["mission"].send_signal(signal.SIGKILL)  # no Hold, no goodbye: the setpoint stream just stops
        f.procs["mission"].wait()
        mark = f.gcs.mark()
        left = f.gcs.wait_for("HEARTBEAT", lambda m: _px4(m) and px4.mode_name(m.custom_mode) != "OFFBOARD", timeout_s=5.0,
                              after=mark)
        assert left is not None, "PX4 stayed in OFFBOARD after its setpoint stream stopped"
        mode = px4.mode_name(left.custom_mode)
        print(f"PX4 switched to {mode} (system_status {left.system_status}); STATUSTEXT:",
              [m.text for m in f.gcs.messages("STATUSTEXT", after=mark)])
        assert left.base_mode & px4.MAV_MODE_FLAG_SAFETY_ARMED, "PX4 disarmed in the air"
        lp = f.gcs.wait_for("LOCAL_POSITION_NED", timeout_s=2.0, after=f.gcs.mark())
        assert lp is not None and lp.z < -0.5, "the vehicle is not in the air under PX4's failsafe"
        texts = " ".join(m.text.lower() for m in f.gcs.messages("STATUSTEXT", after=mark))
        assert "offboard" in texts or "failsafe" in texts, texts
        _check_clock(f.log_dir)


@pytest.mark.px4_job("config")
def test_px4_sitl_config_holds_the_dock_and_the_target(px4_jobs) -> None:
    px4_jobs["config"].result()


@pytest.mark.px4_job("remark1")
def test_a_remark1_carrier_at_2_5_m_s_and_another_bearing_and_height(px4_jobs) -> None:
    s = px4_jobs["remark1"].result()
    assert s["min_carrier_target_distance_m"] > 0.0  # the carrier kept its plan, never at the target


@pytest.mark.px4_job("killed")
def test_controller_killed_while_riding_px4_offboard_loss_failsafe_takes_over(px4_jobs) -> None:
    px4_jobs["killed"].result()
