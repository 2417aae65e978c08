"""PX4's home kept at the carrier, on a real PX4 SITL (SIH quadrotor) with the carrier simulator:
the controller killed during the approach, and PX4's own failsafe flies the passenger to the
moving home - the carrier - not to the take-off point.

A recovery mission (``configs/px4_sitl.toml`` with ``final_action = "return"``): the controller
keeps PX4's home at the carrier and, for the recovery, sets PX4's offboard-loss action to Return
(``recovery.offboard_loss_return``). Killed (SIGKILL) once it prints ``phase APPROACH``, it
leaves both behind: PX4's offboard-loss failsafe returns to that home and lands there. Afterwards
our own link, in the flight's namespace, reads back what the dead controller left on the vehicle:
the home, the offboard-loss action (Return: never put back) and the battery. About 80 s of wall
time. docs/recovery.md, "PX4's home".
"""
from __future__ import annotations

import json
import math
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from mission.mavlink import px4
from mission.mavlink.link import VehicleLink
from mission.record.table import read_record
from mission.time.clock import ScaledClock
from sim.net import wait_for
from sim.sitl.px4 import px4_flight
from tests.px4_sitl.conftest import TEN_MINUTE_BATTERY, px4_job, px4_return_config

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]
SPEED_FACTOR = 1.03


def _px4_heartbeat(m) -> bool:
    return m.get_srcComponent() == 1 and m.autopilot == px4.MAV_AUTOPILOT_PX4


def _read_back(f) -> dict:
    """What our own link reads from the vehicle the dead controller left (in the flight's namespace,
    on the offboard link's port the controller held)."""
    def read() -> dict:
        with VehicleLink("udpin:127.0.0.1:14540", ScaledClock(1.0), target_system=1) as link:
            s = link.wait_until(lambda s: s.home_ned_m is not None and s.battery_pct is not None, 10.0,
                                "HOME_POSITION and the battery")
            return {"home_ned_m": s.home_ned_m.tolist(), "battery_pct": s.battery_pct,
                    "COM_OBL_RC_ACT": link.get_param("COM_OBL_RC_ACT")}
    return f.ns.inside(read)


@px4_job("home")
def _kill_during_the_approach(directory: Path, build: Path) -> dict:
    config = px4_return_config(directory)
    with px4_flight(directory / "f", config, build=build, speed_factor=SPEED_FACTOR, px4_params=TEN_MINUTE_BATTERY) as f:
        mission = f.procs["mission"]
        wait_for(lambda: "phase APPROACH" in f.text("mission.out") or mission.poll() is not None, 150.0,
                 "the mission on the approach")
        assert mission.poll() is None, f.text("mission.out")[-2000:] + f.text("mission.err")[-2000:]
        mission.send_signal(signal.SIGKILL)  # no goodbye: the setpoints and the home updates just stop
        mission.wait()
        mark, t_kill = f.gcs.mark(), time.monotonic()
        rec = read_record(f.log_dir)
        carrier, passenger = rec.vec("x_c")[-1], rec.vec("x_p")[-1]
        seen = rec.vec("x_p")
        takeoff = seen[np.isfinite(seen).all(axis=1)][0]  # the first row the vehicle's position was known
        rtl = f.gcs.wait_for("HEARTBEAT", lambda m: _px4_heartbeat(m) and px4.mode_name(m.custom_mode) == "AUTO.RTL",
                             timeout_s=6.0, after=mark)
        assert rtl is not None, [px4.mode_name(m.custom_mode) for m in f.gcs.messages("HEARTBEAT", after=mark)]
        t_rtl = time.monotonic() - t_kill
        home = f.gcs.wait_for("HOME_POSITION", timeout_s=5.0, after=mark)
        assert home is not None
        landed = f.gcs.wait_for("EXTENDED_SYS_STATE", lambda m: m.landed_state == px4.LANDED_ON_GROUND,
                                timeout_s=45.0, after=mark)
        track = np.array([(m.x, m.y, m.z) for m in f.gcs.messages("LOCAL_POSITION_NED", after=mark)])
        texts = [m.text for m in f.gcs.messages("STATUSTEXT", after=mark)]
        back = _read_back(f)
    out = {"carrier_ned_m": carrier.tolist(), "passenger_at_kill_ned_m": passenger.tolist(),
           "takeoff_ned_m": takeoff.tolist(), "home_ned_m": [home.x, home.y, home.z], "rtl_after_s": round(t_rtl, 2),
           "landed": landed is not None, "landed_ned_m": track[-1].tolist(), "highest_m": float(-track[:, 2].min()),
           "track": track[::30].round(2).tolist(),
           "modes": [px4.mode_name(m.custom_mode) for m in f.gcs.messages("HEARTBEAT", after=mark) if _px4_heartbeat(m)][::2],
           "closest_to_takeoff_m": float(np.linalg.norm(track[:, :2] - takeoff[:2], axis=1).min()),
           "statustext": texts, "read_back": back}
    print(json.dumps(out))
    return out


@pytest.mark.px4_job("home")
def test_controller_killed_during_the_approach_px4_returns_to_the_moving_home_not_the_takeoff_point(px4_jobs) -> None:
    r = px4_jobs["home"].result()
    carrier, home, takeoff = (np.asarray(r[k]) for k in ("carrier_ned_m", "home_ned_m", "takeoff_ned_m"))
    assert np.linalg.norm(carrier[:2] - takeoff[:2]) > 10.0  # the carrier drove on: the two are far apart
    # the home the dead controller left: at the carrier (moved at most 0.5 m ago, within PX4's estimate)
    assert np.linalg.norm(home[:2] - carrier[:2]) < 1.0, r
    assert r["rtl_after_s"] < 4.0  # COM_OF_LOSS_T 1 s, then the offboard-loss action: Return
    assert any("RTL" in text for text in r["statustext"]), r["statustext"]
    assert r["landed"], "PX4's return did not land within 45 s"
    landed = np.asarray(r["landed_ned_m"])
    assert np.linalg.norm(landed[:2] - home[:2]) < 1.5, r  # PX4 landed at the carrier ...
    assert r["closest_to_takeoff_m"] > 10.0  # ... and never headed for the take-off point
    back = r["read_back"]
    assert back["COM_OBL_RC_ACT"] == 3.0  # set for the recovery; the dead controller never put it back
    assert np.allclose(back["home_ned_m"][:2], home[:2], atol=0.05)
    assert 0.0 <= back["battery_pct"] <= 100.0 and math.isfinite(back["battery_pct"])


@px4_job("rogue_home")
def _rogue_home_then_kill(directory: Path, build: Path) -> dict:
    """A rogue ground station (the GCS link) moves PX4's home under the target and sets
    COM_OBL_RC_ACT to 7 (Disarm) on the approach; once the vehicle shows our home again and the
    mission has put the parameter back, the controller is killed."""
    from mission.mavlink.env import mavlink
    from tests.integration.vehicle.test_vehicle_home_battery import set_home

    config = px4_return_config(directory)
    target = (24.0, 18.0)
    with px4_flight(directory / "f", config, build=build, speed_factor=SPEED_FACTOR, px4_params=TEN_MINUTE_BATTERY) as f:
        mission = f.procs["mission"]
        wait_for(lambda: "phase APPROACH" in f.text("mission.out") or mission.poll() is not None, 150.0,
                 "the mission on the approach")
        assert mission.poll() is None, f.text("mission.out")[-2000:] + f.text("mission.err")[-2000:]
        rogue = set_home(f.gcs, *target)
        f.gcs.send(mavlink.MAVLink_param_set_message(1, 1, b"COM_OBL_RC_ACT", px4.encode_param(7, mavlink.MAV_PARAM_TYPE_INT32),
                                                     mavlink.MAV_PARAM_TYPE_INT32))
        t_rogue = time.monotonic()
        wait_for(lambda: "COM_OBL_RC_ACT was changed by someone else to 7" in f.text("mission.err"), 15.0,
                 "COM_OBL_RC_ACT restored")
        mark = f.gcs.mark()
        ours = f.gcs.wait_for("HOME_POSITION", lambda m: math.hypot(m.x - target[0], m.y - target[1]) > 5.0, 5.0, mark)
        t_restored = time.monotonic() - t_rogue
        mission.send_signal(signal.SIGKILL)
        mission.wait()
        mark = f.gcs.mark()
        rec = read_record(f.log_dir)
        carrier = rec.vec("x_c")[-1]
        landed = f.gcs.wait_for("EXTENDED_SYS_STATE", lambda m: m.landed_state == px4.LANDED_ON_GROUND,
                                timeout_s=60.0, after=mark)
        track = np.array([(m.x, m.y, m.z) for m in f.gcs.messages("LOCAL_POSITION_NED", after=mark)])
        texts = [m.text for m in f.gcs.messages("STATUSTEXT", after=mark)]
    out = {"rogue_ack": rogue, "restored_after_s": round(t_restored, 2), "home_shown": ours is not None,
           "carrier_ned_m": carrier.tolist(), "landed": landed is not None, "landed_ned_m": track[-1].tolist(),
           "closest_to_target_m": float(np.linalg.norm(track[:, :2] - np.array(target), axis=1).min()),
           "lowest_disarm_text": [t for t in texts if "isarm" in t], "statustext": texts}
    print(json.dumps(out))
    return out


@pytest.mark.px4_job("rogue_home")
def test_a_rogue_home_and_offboard_loss_action_are_put_back_and_px4_returns_to_the_carrier(px4_jobs) -> None:
    r = px4_jobs["rogue_home"].result()
    assert r["rogue_ack"] == px4.MAV_RESULT_ACCEPTED and r["home_shown"], r  # unsigned: PX4 took the rogue's home
    assert r["landed"], r
    landed, carrier = np.asarray(r["landed_ned_m"]), np.asarray(r["carrier_ned_m"])
    assert np.linalg.norm(landed[:2] - carrier[:2]) < 2.0, r  # PX4's Return landed at the carrier ...
    assert not any("failsafe" in t.lower() and "disarm" in t.lower() for t in r["statustext"]), r  # ... not disarmed by 7
