"""What a real PX4 SITL does with LANDING_TARGET when our controller dies: the facts behind
docs/px4-precland.md.

Each scenario is a fresh SIH quadrotor (real PX4 SITL, a network namespace of its own) flown by a
pymavlink peer on the offboard link (``sim.testing.probe``, through :mod:`bench.px4_home`'s
helpers): take off in OFFBOARD to 5 m, fly to ``HOVER`` and hold it, PX4's home moved to ``HOME``
(where our mission's home keeper would have put it: the carrier's GNSS position, here 3.6 m off
the true deck), and LANDING_TARGET streamed at 10 Hz at the deck's *true* position ``DECK``
(:func:`mission.mavlink.px4.encode_landing_target`, as the mission loop sends it; there is no
rendered camera on PX4 SITL, so the bench gives PX4 the truth a converged estimate would). Then
the controller is "killed": its setpoints and heartbeats stop. Per scenario, one JSON line: the
parameters, the modes PX4 went through (with the time after the kill), the track, where it
landed (and its distance from the deck and from the home), the STATUSTEXTs, and PX4's own
console lines about precision landing (``Precland: switching to ...``).

- ``offboard``: 8 s hover in OFFBOARD with the stream on (does PX4 do anything with it there?),
  then kill with COM_OBL_RC_ACT 3 (Return) and RTL_PLD_MD 0 (precision landing off);
- ``return-required`` / ``return-opportunistic``: COM_OBL_RC_ACT 3, RTL_PLD_MD 2 / 1, the
  stream going on after the kill (another process than the controller sends it);
- ``return-silent`` / ``return-silent-opportunistic``: COM_OBL_RC_ACT 3, RTL_PLD_MD 2 / 1, the
  stream stopping with the controller (what happens when the mission loop itself is the only sender);
- ``return-silent-rtl-defaults`` (``-btout``): as ``return-silent-opportunistic`` with PX4's own
  RTL altitudes (no ``FAST_RTL``), and PLD_BTOUT 30 s;
- ``land``: COM_OBL_RC_ACT 4 (Land), RTL_PLD_MD 2, the stream going on;
- ``precland-mode``: no kill: AUTO.PRECLAND commanded (DO_SET_MODE 4/9) with the stream on.

Usage: ``python -m bench.px4_precland [--scenario NAME]...`` (all by default; about 60-90 s each).
Needs root and ``MARSUPIAL_PX4_SITL``; run it under ``flock /tmp/marsupial-px4.lock``.
"""
from __future__ import annotations

import math
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any


from bench.px4_home import param, scenario_command, set_home, sitl, take_off, track
from mission.mavlink import px4
from mission.passenger.target import LandingTarget

HOVER = (10.0, 5.0, -5.0)  # [m] local NED: where the passenger holds when the controller dies
DECK = (6.0, 8.0, 0.0)  # [m] the deck's landing point (its truth; the ground is z = 0 here)
HOME = (9.0, 6.0, 0.0)  # [m] PX4's home: the deck as the carrier's GNSS has it, 3.6 m off
RATE_S = 0.1  # LANDING_TARGET period [s]
FAST_RTL = {"RTL_RETURN_ALT": 5.0, "RTL_DESCEND_ALT": 5.0}  # no climb to 60 m first (PX4's defaults)
SHOWN = ("RTL_RETURN_ALT", "RTL_DESCEND_ALT", "RTL_CONE_ANG", "RTL_MIN_DIST", "COM_OBL_RC_ACT", "COM_OF_LOSS_T", "NAV_RCL_ACT", "RTL_PLD_MD", "RTL_TYPE", "RTL_LAND_DELAY", "PLD_BTOUT",
         "PLD_HACC_RAD", "PLD_FAPPR_ALT", "PLD_SRCH_ALT", "PLD_SRCH_TOUT", "PLD_MAX_SRCH", "MPC_LAND_SPEED")


def _landed(probe: Any) -> bool:
    return not probe.armed() or getattr(probe.latest("EXTENDED_SYS_STATE"), "landed_state", 0) == px4.LANDED_ON_GROUND


def _fly_to(probe: Any, stream: Any, point: tuple[float, float, float]) -> None:
    stream.set(type_mask=0b110111111000, position_ned_m=point)
    probe.wait_for("LOCAL_POSITION_NED", lambda m: math.dist((m.x, m.y), point[:2]) < 0.3, 20.0, probe.mark())
    time.sleep(2.0)


def _console(directory: Path, since: int) -> list[str]:
    """PX4's console lines about precision landing and the failsafe, after byte ``since``."""
    out = directory / "px4-0.out"
    text = out.read_bytes()[since:].decode(errors="replace") if out.exists() else ""
    return [line.strip() for line in text.splitlines() if re.search(r"(?i)precland|landing target|failsafe|search", line)]


def scenario(directory: Path, obl_rc_act: int, pld_md: int, *, stream_after: bool = True, kill: bool = True,
             offboard_s: float = 3.0, extra: dict[str, float] | None = None) -> dict[str, Any]:
    params = {"COM_OBL_RC_ACT": obl_rc_act, "RTL_PLD_MD": pld_md, **(FAST_RTL if extra is None else extra)}
    with sitl(directory, params) as (probe, beats):
        out: dict[str, Any] = {"params": {name: param(probe, name) for name in SHOWN}}
        stream = take_off(probe)
        _fly_to(probe, stream, HOVER)
        out["home_set"] = set_home(probe, HOME)
        sent = [0]

        def send_target() -> None:
            probe.send(px4.encode_landing_target(LandingTarget(DECK, int(time.monotonic() * 1e6))))
            sent[0] += 1

        target_stop = probe.every(RATE_S, send_target)
        time.sleep(offboard_s)
        lp = probe.latest("LOCAL_POSITION_NED")
        out["offboard_after_stream"] = {"mode": probe.mode(), "at": [round(lp.x, 2), round(lp.y, 2), round(lp.z, 2)]}
        console_from = (directory / "px4-0.out").stat().st_size
        mark = probe.mark()
        if kill:
            stream.stop()  # the controller killed: its setpoints and its heartbeats stop
            beats.set()
        else:
            ack = probe.command(px4.MAV_CMD_DO_SET_MODE, (px4.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | 128, int(px4.MainMode.AUTO),
                                                          int(px4.AutoSubMode.PRECLAND)))
            out["set_mode_result"] = getattr(ack, "result", None)
        if not stream_after:
            target_stop.set()
        seen = track(probe, 90.0, until=lambda: _landed(probe))
        precland = f"UNKNOWN(0x{px4.encode_custom_mode(px4.MainMode.AUTO, px4.AutoSubMode.PRECLAND):08x})"
        seen["modes"] = [(t, "AUTO.PRECLAND" if m == precland else m, s) for t, m, s in seen["modes"]]
        out.update(seen)
        time.sleep(2.0)
        target_stop.set()
        if not kill:
            stream.stop()
        lp = probe.latest("LOCAL_POSITION_NED")
        at = (lp.x, lp.y, lp.z)
        out["landed"] = {"at": [round(c, 2) for c in at], "from_deck_m": round(math.dist(at[:2], DECK[:2]), 2),
                         "from_home_m": round(math.dist(at[:2], HOME[:2]), 2), "armed": probe.armed()}
        out["landing_targets_sent"] = sent[0]
        out["statustext"] = [str(m.text).rstrip() for m in probe.messages("STATUSTEXT", mark)]
        out["console"] = _console(directory, console_from)
        return out


SCENARIOS: dict[str, Callable[[Path], dict[str, Any]]] = {
    "offboard": lambda d: scenario(d, 3, 0, offboard_s=8.0),
    "return-required": lambda d: scenario(d, 3, 2),
    "return-opportunistic": lambda d: scenario(d, 3, 1),
    "return-silent": lambda d: scenario(d, 3, 2, stream_after=False),
    "return-silent-opportunistic": lambda d: scenario(d, 3, 1, stream_after=False),
    "return-silent-rtl-defaults": lambda d: scenario(d, 3, 1, stream_after=False, extra={}),
    "return-silent-rtl-defaults-btout": lambda d: scenario(d, 3, 1, stream_after=False, extra={"PLD_BTOUT": 30.0}),
    "land": lambda d: scenario(d, 4, 2),
    "precland-mode": lambda d: scenario(d, 3, 2, kill=False),
}


main = scenario_command(SCENARIOS)


if __name__ == "__main__":
    main()
