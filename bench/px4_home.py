"""What a real PX4 SITL does with a home that moves, a controller that dies, and its battery: the
facts behind docs/recovery.md ("PX4's home", "The battery") and docs/flying-px4.md.

Each scenario is a fresh SIH quadrotor (real PX4 SITL, a network namespace of its own) flown by
a pymavlink peer on the offboard link (``sim.testing.probe``), printed as one JSON line:

- ``battery``: SYS_STATUS and BATTERY_STATUS disarmed and for 12 s armed (PX4's battery simulator,
  ``SIM_BAT_DRAIN`` / ``SIM_BAT_MIN_PCT``), PX4's low-battery parameters, and how often
  BATTERY_STATUS, HOME_POSITION and GPS_GLOBAL_ORIGIN arrive on the offboard link;
- ``home``: DO_SET_HOME as COMMAND_LONG and as COMMAND_INT, disarmed and in flight, at 5 a
  second; HOME_POSITION read back; then RTL, and the home moved 4 s into the return;
- ``kill-position`` / ``kill-return``: hovering in OFFBOARD with the home moved 11 m away, the
  controller "killed" (setpoints and heartbeats stop) with COM_OBL_RC_ACT 0 (PX4's default) or 3
  (Return): the modes PX4 goes through and where it lands.

Usage: ``python -m bench.px4_home [--scenario NAME]...`` (all by default; about 45-70 s each).
Needs root and ``MARSUPIAL_PX4_SITL``. Run it under ``flock /tmp/marsupial-px4.lock`` on a shared
machine.
"""
from __future__ import annotations

import json
import math
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import click

from mission.core import geodesy
from mission.mavlink import px4
from mission.mavlink.env import mavlink
from sim.sitl.px4 import NetNamespace, Px4Sitl, build_dir, unavailable_reason, wait_armable
from sim.testing.probe import Probe, SetpointStream

HOVER = {"type_mask": 0b110111111000, "position_ned_m": (0.0, 0.0, -5.0)}  # position only: hold 5 m up
PARAMS = ("COM_LOW_BAT_ACT", "BAT_LOW_THR", "BAT_CRIT_THR", "BAT_EMERGEN_THR", "SIM_BAT_DRAIN", "SIM_BAT_MIN_PCT",
          "COM_OBL_RC_ACT", "NAV_RCL_ACT", "COM_RC_IN_MODE", "COM_FAIL_ACT_T", "COM_HOME_IN_AIR", "RTL_RETURN_ALT",
          "RTL_DESCEND_ALT", "RTL_CONE_ANG", "RTL_MIN_DIST", "NAV_ACC_RAD", "BAT1_N_CELLS", "BAT1_CAPACITY")


@contextmanager
def sitl(directory: Path, params: dict[str, float] | None = None) -> Iterator[tuple[Probe, threading.Event]]:
    """A fresh PX4 SITL, armable, and a probe on its offboard link with its heartbeats (2 Hz;
    set the event to stop them)."""
    ns = NetNamespace()
    px4_proc = Px4Sitl(build_dir() or Path("."), directory / "rootfs", ns, speed_factor=1.03, out_dir=directory,
                       params=params or {})
    probe: Probe | None = None
    try:
        px4_proc.start()
        probe = ns.inside(lambda: Probe(bind="127.0.0.1:14540", vehicle=("127.0.0.1", 14580)))
        beats = probe.start_heartbeats(0.5)
        wait_armable(probe, 60.0)
        yield probe, beats
    finally:
        if probe is not None:
            probe.close()
        px4_proc.stop()
        ns.close()


def param(probe: Probe, name: str) -> float | None:
    mark = probe.mark()
    probe.send(mavlink.MAVLink_param_request_read_message(1, 1, name.encode(), -1))
    msg = probe.wait_for("PARAM_VALUE", lambda m: m.param_id == name, 2.0, mark)
    return None if msg is None else px4.decode_param(msg.param_value, msg.param_type)


def origin(probe: Probe) -> tuple[float, float, float]:
    msg = probe.latest("GPS_GLOBAL_ORIGIN")
    if msg is None:  # PX4 sends it once, when its origin is set: ask
        probe.command(mavlink.MAV_CMD_REQUEST_MESSAGE, (float(mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN),))
        msg = probe.wait_for("GPS_GLOBAL_ORIGIN", timeout_s=2.0)
    return msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3


def set_home(probe: Probe, ned: tuple[float, float, float], as_int: bool = True) -> int | None:
    """DO_SET_HOME at a local point; the ACK's result (None: no ACK)."""
    lat0, lon0, alt0 = origin(probe)
    lat, lon = geodesy.reproject(ned[0], ned[1], lat0, lon0)
    mark, command = probe.mark(), mavlink.MAV_CMD_DO_SET_HOME
    if as_int:
        probe.send(mavlink.MAVLink_command_int_message(1, 1, mavlink.MAV_FRAME_GLOBAL, command, 0, 0, 0.0, 0.0, 0.0,
                                                       math.nan, round(lat * 1e7), round(lon * 1e7), alt0 - ned[2]))
    else:
        probe.send(mavlink.MAVLink_command_long_message(1, 1, command, 0, 0.0, 0.0, 0.0, math.nan, lat, lon, alt0 - ned[2]))
    ack = probe.wait_for("COMMAND_ACK", lambda m: m.command == command, 2.0, mark)
    return None if ack is None else int(ack.result)


def home_after(probe: Probe, mark: int) -> list[float] | None:
    """The first HOME_POSITION after ``mark`` (local x, y, z [m]); it streams at 0.5 Hz."""
    msg = probe.wait_for("HOME_POSITION", None, 4.0, mark)
    return None if msg is None else [round(msg.x, 3), round(msg.y, 3), round(msg.z, 3)]


def take_off(probe: Probe) -> SetpointStream:
    stream = SetpointStream(probe, 0.05, **HOVER)
    time.sleep(1.0)  # setpoints before OFFBOARD, as PX4 needs
    probe.set_mode("OFFBOARD")
    probe.arm()
    probe.wait_for("LOCAL_POSITION_NED", lambda m: m.z < -4.5, 20.0, probe.mark())
    return stream


def track(probe: Probe, seconds: float, every_s: float = 1.0, until: Callable[[], bool] = lambda: False) -> dict[str, Any]:
    """Modes (with the time they began) and positions over ``seconds`` of wall time."""
    t0, modes, points = time.monotonic(), [], []
    while (t := time.monotonic() - t0) < seconds and not until():
        hb, lp = probe.latest("HEARTBEAT"), probe.latest("LOCAL_POSITION_NED")
        mode = px4.mode_name(hb.custom_mode)
        if not modes or modes[-1][1] != mode:
            modes.append((round(t, 1), mode, int(hb.system_status)))
        points.append((round(t, 1), round(lp.x, 1), round(lp.y, 1), round(lp.z, 1)))
        time.sleep(every_s)
    return {"modes": modes, "track": points}


def rate_hz(probe: Probe, kinds: tuple[str, ...], seconds: float = 10.0) -> dict[str, float]:
    mark = probe.mark()
    time.sleep(seconds)
    return {k: round(len(probe.messages(k, mark)) / seconds, 2) for k in kinds}


def battery(directory: Path) -> dict[str, Any]:
    with sitl(directory) as (probe, _):
        out: dict[str, Any] = {"params": {name: param(probe, name) for name in PARAMS}}
        status = probe.latest("SYS_STATUS")
        out["disarmed"] = {"voltage_mv": status.voltage_battery, "current_ca": status.current_battery,
                           "remaining_pct": status.battery_remaining,
                           "battery_status_pct": getattr(probe.latest("BATTERY_STATUS"), "battery_remaining", None)}
        out["rates_hz"] = rate_hz(probe, ("SYS_STATUS", "BATTERY_STATUS", "HOME_POSITION", "GPS_GLOBAL_ORIGIN"))
        stream = take_off(probe)
        t0, seen = time.monotonic(), []
        while (t := time.monotonic() - t0) < 12.0:
            seen.append((round(t, 1), probe.latest("SYS_STATUS").battery_remaining))
            time.sleep(1.0)
        out["armed_remaining_pct"] = seen
        stream.stop()
        return out


def home(directory: Path) -> dict[str, Any]:
    with sitl(directory) as (probe, _):
        out: dict[str, Any] = {"disarmed_int": set_home(probe, (10.0, -4.0, 0.0)), "read_back": home_after(probe, probe.mark())}
        out["disarmed_long"] = set_home(probe, (3.0, 0.0, 0.0), as_int=False)
        out["read_back_long"] = home_after(probe, probe.mark())
        stream = take_off(probe)
        out["after_arming"] = home_after(probe, probe.mark())
        out["in_flight_int"] = set_home(probe, (10.0, 0.0, 0.0))
        out["read_back_in_flight"] = home_after(probe, probe.mark())
        t0, acks, mark = time.monotonic(), [], probe.mark()
        while (t := time.monotonic() - t0) < 5.0:
            acks.append(set_home(probe, (10.0, t, 0.0)))
            time.sleep(0.2)
        out["five_a_second"] = {"acks": acks, "home_positions": len(probe.messages("HOME_POSITION", mark))}
        set_home(probe, (10.0, 0.0, 0.0))
        mark = probe.mark()
        out["rtl"] = int(probe.set_mode("AUTO.RTL").result)
        time.sleep(4.0)
        out["moved_during_rtl"] = set_home(probe, (10.0, 10.0, 0.0))
        landed = track(probe, 40.0, until=lambda: getattr(probe.latest("EXTENDED_SYS_STATE"), "landed_state", 0)
                       == px4.LANDED_ON_GROUND)
        out["rtl_landed_at"] = landed["track"][-1]
        out["rtl_statustext"] = [m.text for m in probe.messages("STATUSTEXT", mark)]
        stream.stop()
        return out


def kill(directory: Path, obl_rc_act: int) -> dict[str, Any]:
    with sitl(directory, {"COM_OBL_RC_ACT": obl_rc_act}) as (probe, beats):
        stream = take_off(probe)
        time.sleep(5.0)
        out: dict[str, Any] = {"home_set": set_home(probe, (-10.0, 5.0, 0.0)), "home": home_after(probe, probe.mark())}
        mark = probe.mark()
        stream.stop()  # killed: its setpoints and its heartbeats stop
        beats.set()
        out.update(track(probe, 45.0, until=lambda: not probe.armed()))
        out["statustext"] = [m.text for m in probe.messages("STATUSTEXT", mark)]
        return out


SCENARIOS: dict[str, Callable[[Path], dict[str, Any]]] = {
    "battery": battery, "home": home,
    "kill-position": lambda d: kill(d, 0), "kill-return": lambda d: kill(d, 3),
}


def scenario_command(scenarios: dict[str, Callable[[Path], dict[str, Any]]]) -> click.Command:
    """A command that flies the ``--scenario`` s named (default all), each a fresh PX4 SITL in a
    folder of its own under /var/tmp, and prints one JSON line per scenario."""
    @click.command()
    @click.option("--scenario", "names", multiple=True, type=click.Choice(list(scenarios)), help="(repeatable; default all)")
    def command(names: tuple[str, ...]) -> None:
        why = unavailable_reason()
        if why:
            raise click.UsageError(why)
        for name in names or tuple(scenarios):
            with tempfile.TemporaryDirectory(dir="/var/tmp") as directory:
                print(json.dumps({"scenario": name, **scenarios[name](Path(directory))}), flush=True)
    return command


main = scenario_command(SCENARIOS)


if __name__ == "__main__":
    main()
