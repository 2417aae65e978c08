"""What a real PX4 SITL does when a ground station force-disarms it in the air (docs/flying-px4.md).

A fresh PX4 (SIH quadrotor) in its own network namespace (:mod:`sim.sitl.px4`). An offboard peer
on the onboard link (14540, sysid 1 compid 191, as ``marsupial run``) climbs to 3 m and hovers
on zero-velocity setpoints; a "rogue" ground station on the GCS link (14550) sends
MAV_CMD_COMPONENT_ARM_DISARM(0, 21196) while the stream goes on. Per trial, seen on the onboard
link [s after the ACK, wall clock, PX4's clock measured beside]: the first HEARTBEAT without
SAFETY_ARMED, the first EXTENDED_SYS_STATE ON_GROUND, the STATUSTEXTs, the mode, when the
vehicle reached the ground; and when the mission's reducer (:mod:`mission.mavlink.telemetry`, an
unsigned link: no single sample decides) first believes it disarmed or landed, replayed on the
same messages (``believed_s``). EXTENDED_SYS_STATE is asked at the mission's 10 Hz. After the
trials: the HEARTBEAT and EXTENDED_SYS_STATE rates, and whether an external *forced* arm skips
the checks that refuse a plain one.

Usage (root, real time, one PX4 user at a time)::

    flock /tmp/marsupial-px4.lock env MARSUPIAL_PX4_SITL=../shared/px4_sitl \\
        python -m bench.px4_forced_disarm [--trials 3] [--out DIR] [--json F]
"""
from __future__ import annotations

import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import click

from mission.mavlink.requests import EXTENDED_SYS_STATE_ID, LANDED_STATE_RATE_HZ
from mission.mavlink import px4, telemetry
from sim.net import wait_for
from sim.sitl.px4 import NetNamespace, Px4Sitl, build_dir, gcs_probe, unavailable_reason, wait_armable
from sim.testing.probe import Probe, SetpointStream

ARMED = px4.MAV_MODE_FLAG_SAFETY_ARMED
HOVER_D_M = -3.0


def _autopilot(msg: Any) -> bool:
    """From PX4's autopilot component (other components of the system send HEARTBEATs too)."""
    return bool(msg.get_srcComponent() == 1 and (msg.get_type() != "HEARTBEAT" or msg.autopilot == px4.MAV_AUTOPILOT_PX4))


def _first(probe: Probe, kind: str, after: int, predicate: Any) -> tuple[float, Any] | None:
    """(wall receive time, message) of the first ``kind`` from the autopilot after index ``after``
    that satisfies ``predicate``."""
    with probe._cond:
        for index, t_wall, msg in probe.history.get(kind, ()):
            if index > after and _autopilot(msg) and predicate(msg):
                return t_wall, msg
    return None


def _believed(probe: Probe, after: int) -> float | None:
    """Wall time the mission's reducer first believes the vehicle disarmed or landed, replaying the
    autopilot's HEARTBEATs and EXTENDED_SYS_STATEs (up to index ``after`` only to start from, armed
    in the air) in the order received."""
    with probe._cond:
        msgs = sorted((i, t, m) for kind in ("HEARTBEAT", "EXTENDED_SYS_STATE")
                      for i, t, m in probe.history.get(kind, ()) if _autopilot(m))
    tm = telemetry.Telemetry()
    for i, t, m in msgs:
        tm = telemetry.reduce(tm, m, t)
        if i > after and (not tm.believed_armed or tm.believed_on_ground):
            return t
    return None


def _autopilot_heartbeat(probe: Probe) -> Any:
    with probe._cond:
        return next(m for _, _, m in reversed(probe.history["HEARTBEAT"]) if _autopilot(m))


def _rate_hz(probe: Probe, kind: str) -> float:
    with probe._cond:
        stamps = [t for _, t, m in probe.history.get(kind, ()) if _autopilot(m)]
    return (len(stamps) - 1) / (stamps[-1] - stamps[0]) if len(stamps) > 2 else float("nan")


def _until(action: Any, done: Any, timeout_s: float, what: str) -> None:
    """Repeat ``action()`` every 0.5 s until ``done()``; TimeoutError naming ``what``."""
    deadline = time.monotonic() + timeout_s
    while not done():
        if time.monotonic() > deadline:
            raise TimeoutError(what)
        action()
        time.sleep(0.5)


def _take_off(onboard: Probe, stream: SetpointStream) -> None:
    stream.set(velocity_ned_m_s=(0.0, 0.0, 0.0))
    _until(lambda: onboard.set_mode("OFFBOARD", 1.0),
           lambda: px4.mode_name(_autopilot_heartbeat(onboard).custom_mode) == "OFFBOARD", 20.0, "OFFBOARD")
    _until(lambda: onboard.arm(timeout_s=1.0), lambda: bool(_autopilot_heartbeat(onboard).base_mode & ARMED), 30.0, "armed")
    stream.set(velocity_ned_m_s=(0.0, 0.0, -1.0))
    wait_for(lambda: (lp := onboard.latest("LOCAL_POSITION_NED")) is not None and lp.z < HOVER_D_M, 30.0, "at 3 m")
    stream.set(velocity_ned_m_s=(0.0, 0.0, 0.0))
    time.sleep(3.0)


def _trial(onboard: Probe, gcs: Probe, stream: SetpointStream) -> dict[str, Any]:
    _take_off(onboard, stream)
    assert onboard.latest("EXTENDED_SYS_STATE").landed_state == px4.LANDED_IN_AIR
    mark = onboard.mark()
    height_m = -onboard.latest("LOCAL_POSITION_NED").z
    t0 = time.monotonic()
    ack = gcs.arm(False, force=True, timeout_s=2.0)
    t_ack = time.monotonic()
    time.sleep(5.0)  # falls 3 m in well under 1 s
    believed = _believed(onboard, mark)
    hb = _first(onboard, "HEARTBEAT", mark, lambda m: not m.base_mode & ARMED)
    ess = _first(onboard, "EXTENDED_SYS_STATE", mark, lambda m: m.landed_state == px4.LANDED_ON_GROUND)
    with onboard._cond:  # on the ground: the first sample of the lowest point reached
        fall = [(t, m) for i, t, m in onboard.history["LOCAL_POSITION_NED"] if i > mark]
    bottom = max(m.z for _, m in fall)
    ground = next(((t, m) for t, m in fall if m.z >= bottom - 0.05), None)
    first_lp = _first(onboard, "LOCAL_POSITION_NED", mark, lambda m: True)
    texts = [str(m.text).rstrip() for m in onboard.messages("STATUSTEXT", after=mark)]
    last = _autopilot_heartbeat(onboard)
    row = {
        "height_m": round(height_m, 2), "ack": None if ack is None else ack.result,
        "ack_s": round(t_ack - t0, 3),
        "heartbeat_disarmed_s": None if hb is None else round(hb[0] - t_ack, 3),
        "landed_on_ground_s": None if ess is None else round(ess[0] - t_ack, 3),
        "believed_s": None if believed is None else round(believed - t_ack, 3),
        "landed_height_m": None,
        "ground_s": None if ground is None else round(ground[0] - t_ack, 3),
        "ground_z_m": round(bottom, 2), "mode_after": px4.mode_name(last.custom_mode), "armed_after": bool(last.base_mode & ARMED),
        "statustexts": texts,
    }
    if ess is not None and first_lp is not None:  # height when PX4 first said ON_GROUND
        with onboard._cond:
            before = [m for i, t, m in onboard.history["LOCAL_POSITION_NED"] if i > mark and t <= ess[0]]
        row["landed_height_m"] = round(-before[-1].z, 2) if before else None
    return row


def _forced_arm_check(onboard: Probe, gcs: Probe, stream: SetpointStream) -> dict[str, Any]:
    """On the ground, disarmed, in OFFBOARD with the stream stopped: a plain arm from the GCS, then a
    forced one (21196): does an external force skip the checks that refused the plain one?"""
    stream.set(velocity_ned_m_s=(0.0, 0.0, 0.0))
    stream.stop()
    time.sleep(3.0)  # well past COM_OF_LOSS_T: no offboard signal
    mode = px4.mode_name(_autopilot_heartbeat(onboard).custom_mode)
    mark = onboard.mark()
    plain = gcs.arm(True, timeout_s=2.0)
    time.sleep(0.5)
    forced = gcs.arm(True, force=True, timeout_s=2.0) if plain is not None and plain.result != px4.MAV_RESULT_ACCEPTED else None
    time.sleep(1.0)
    texts = [str(m.text).rstrip() for m in onboard.messages("STATUSTEXT", after=mark)]
    armed = bool(_autopilot_heartbeat(onboard).base_mode & ARMED)
    if armed:
        gcs.arm(False, timeout_s=2.0)
    return {"mode": mode, "plain_arm": None if plain is None else plain.result,
            "forced_arm": None if forced is None else forced.result, "armed": armed, "statustexts": texts}


@click.command()
@click.option("--trials", default=3, show_default=True)
@click.option("--out", type=click.Path(path_type=Path), default=None, help="folder for PX4's rootfs and output")
@click.option("--json", "json_path", type=click.Path(path_type=Path), default=None)
def main(trials: int, out: Path | None, json_path: Path | None) -> None:
    why = unavailable_reason()
    if why:
        sys.exit(f"cannot fly PX4 here: {why}")
    build = build_dir()
    assert build is not None
    out = out or Path(tempfile.mkdtemp(prefix="px4-disarm-", dir=Path.home()))
    out.mkdir(parents=True, exist_ok=True)
    result: dict[str, Any] = {"trials": []}
    with NetNamespace() as ns:
        sitl = Px4Sitl(build, out / "rootfs", ns, out_dir=out, speed_factor=1.1)
        sitl.start()
        onboard = ns.inside(lambda: Probe(bind="127.0.0.1:14540", vehicle=("127.0.0.1", 14580), sysid=1, compid=191))
        gcs = gcs_probe(ns)
        try:
            wait_for(lambda: onboard.latest("HEARTBEAT") is not None and gcs.latest("HEARTBEAT") is not None, 30.0,
                     "PX4 HEARTBEATs on both links")
            onboard.every(0.5, onboard.heartbeat)
            gcs.every(0.5, gcs.heartbeat)
            wait_armable(gcs, 60.0)
            onboard.command(px4.MAV_CMD_SET_MESSAGE_INTERVAL, (EXTENDED_SYS_STATE_ID, 1e6 / LANDED_STATE_RATE_HZ))
            stream = SetpointStream(onboard, 0.02)
            for k in range(trials):
                row = _trial(onboard, gcs, stream)
                print(json.dumps(row), flush=True)
                result["trials"].append(row)
                time.sleep(3.0)
            result["forced_arm"] = _forced_arm_check(onboard, gcs, stream)
            print(json.dumps(result["forced_arm"]), flush=True)
            result["rates_hz"] = {k: round(_rate_hz(onboard, k), 2) for k in ("HEARTBEAT", "EXTENDED_SYS_STATE",
                                                                             "LOCAL_POSITION_NED")}
            lp = onboard.latest("LOCAL_POSITION_NED")
            with onboard._cond:
                first = onboard.history["LOCAL_POSITION_NED"][0]
                last_t = onboard.history["LOCAL_POSITION_NED"][-1][1]
            result["px4_clock_ratio"] = round((lp.time_boot_ms - first[2].time_boot_ms) / 1000.0 / (last_t - first[1]), 3)
        finally:
            onboard.close()
            gcs.close()
            sitl.stop()
    rows = result["trials"]
    for key in ("heartbeat_disarmed_s", "landed_on_ground_s", "believed_s", "ground_s"):
        values = [r[key] for r in rows if r[key] is not None]
        if values:
            result[f"{key}_median"] = statistics.median(values)
            result[f"{key}_max"] = max(values)
    print(json.dumps({k: v for k, v in result.items() if k != "trials"}, indent=2))
    if json_path is not None:
        json_path.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
