"""A rogue ground station moves PX4's settings during a recovery mission, then the controller is
killed: the fault matrix's harness (tests/faults/procs.py: carrier, ``marsupial run`` and the
mock PX4 as subprocesses, in lockstep) with the rogue on the vehicle's GCS link.

The rogue sends DO_SET_HOME at the target and sets the offboard-loss action COM_OBL_RC_ACT to 7
(Disarm). The mission reads both back (HOME_POSITION, PARAM_VALUE), sets them again, and once
it has, is killed (SIGKILL): PX4's offboard-loss failsafe then returns to the carrier and lands
there, never disarming in the air. On main the home stayed at the target and the kill disarmed
the passenger in the air. With the link signed (as ``marsupial demo`` flies) the rogue's
unsigned commands are refused outright. docs/security.md, "Attacks tried".
"""
from __future__ import annotations

import math
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from mission.mavlink import px4
from mission.mavlink.env import mavlink
from tests.conftest import CONFIGS
from tests.faults.procs import assert_safe_end, flight, wait_for
from tests.faults.test_matrix import PACED, assert_never_disarmed_in_the_air, concurrently
from tests.integration.vehicle.test_vehicle_home_battery import set_home

pytestmark = [pytest.mark.slow, pytest.mark.timeout(200)]

TARGET = (24.0, 18.0, -5.0)


KEY = bytes.fromhex("a1" * 32)


def _rogue_then_kill(tmp_path: Path, signed: bool) -> None:
    tmp_path.mkdir(parents=True, exist_ok=True)
    key = tmp_path / "mav.key"
    key.write_text(KEY.hex())
    signing = ("--signing-key", str(key)) if signed else ()
    # The task at the target lasts long enough for the rogue's commands, the read-back and the
    # kill (200 s of the paced clock, 40 s of wall): with recovery.toml's 5 s the signed mission,
    # whose refused commands each wait out a 3 s ACK, had docked and ended before the kill.
    text = (CONFIGS / "recovery.toml").read_text()
    assert "at_target_s = 5.0 " in text
    config = tmp_path / "rogue.toml"
    config.write_text(text.replace("at_target_s = 5.0 ", "at_target_s = 200.0 "))
    with flight(tmp_path, "rogue-home-signed" if signed else "rogue-home", config=config,
                lockstep=True, vehicle_args=(*signing, *PACED), mission_args=signing) as f:
        f.wait_phase("ARRIVED", 90.0)
        assert f.gcs is not None
        disarm = mavlink.MAVLink_param_set_message(1, 1, b"COM_OBL_RC_ACT", px4.encode_param(7, mavlink.MAV_PARAM_TYPE_INT32),
                                                   mavlink.MAV_PARAM_TYPE_INT32)
        if signed:  # refused outright: an unsigned command is no command
            # the set first, then the home: each one's 3 s without an answer counts from its own send,
            # the two at once (the paced flight runs on while the test waits: 15 s of it less)
            mark, sent = f.gcs.mark(), time.monotonic()
            f.gcs.send(disarm)
            assert set_home(f.gcs, TARGET[0], TARGET[1]) is None  # the rogue's home, under the target: no ACK in 3 s
            left_s = max(3.0 - (time.monotonic() - sent), 0.0)
            assert f.gcs.wait_for("PARAM_VALUE", lambda m: m.param_id == "COM_OBL_RC_ACT", left_s, mark) is None
        else:
            result = set_home(f.gcs, TARGET[0], TARGET[1])  # the rogue's home, under the target
            f.gcs.send(disarm)
            assert result == px4.MAV_RESULT_ACCEPTED
            wait_for(lambda: "PX4's home was moved by someone else" in f.text("mission.err"), 30.0, "the home restored")
            wait_for(lambda: "PX4's COM_OBL_RC_ACT was changed by someone else to 7" in f.text("mission.err"), 30.0,
                     "COM_OBL_RC_ACT restored")
        home = f.gcs.wait_for("HOME_POSITION", lambda m: math.hypot(m.x - TARGET[0], m.y - TARGET[1]) > 5.0, 10.0,
                              f.gcs.mark())
        assert home is not None  # the vehicle shows our home
        carrier = next(r for r in reversed(f.record()) if r.get("x_c_n") not in (None, "", "nan"))
        carrier_ne = np.array([float(carrier["x_c_n"]), float(carrier["x_c_e"])])
        assert f.procs["mission"].poll() is None and f.phases()[-1] == "ARRIVED", f.phases()  # still at the target
        f.procs["mission"].send_signal(signal.SIGKILL)
        f.procs["mission"].wait(10.0)
        assert wait_for(lambda: "AUTO.RTL" in f.modes_seen(), 30.0, "PX4's Return")
        v = assert_safe_end(f, modes=("landed",), timeout_s=90.0)
        landed = np.array(v["ned"][:2])
        # at the carrier's home (the carrier waits about b c from the target), not on the target
        assert float(np.linalg.norm(landed - carrier_ne)) < 3.0, (landed, carrier_ne)
        assert float(np.linalg.norm(landed - np.array(TARGET[:2]))) > 5.0, landed
        print(f"{'signed' if signed else 'unsigned'}: landed {float(np.linalg.norm(landed - carrier_ne)):.2f} m from "
              f"the carrier, {float(np.linalg.norm(landed - np.array(TARGET[:2]))):.2f} m from the target")
        assert_never_disarmed_in_the_air(f)


def test_a_rogue_home_and_offboard_loss_action_are_restored_before_a_controller_kill(tmp_path: Path) -> None:
    """Unsigned: the mission restores both, then is killed; signed (as the demo flies): the
    rogue's unsigned commands are refused."""
    concurrently(lambda: _rogue_then_kill(tmp_path, signed=False), lambda: _rogue_then_kill(tmp_path / "s", signed=True))
