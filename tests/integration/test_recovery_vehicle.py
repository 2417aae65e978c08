"""The recovery against the mock vehicle's battery, in lockstep (the vehicle, the carrier simulator
and the mission in one process over real UDP and Zenoh): a battery that drains early recalls the
passenger from its task at the target, it docks, and PX4's own low-battery failsafe never acts."""
from __future__ import annotations

import json

import pytest

from mission.phases import Phase
from tests.support.mission_harness import flying_pair

pytestmark = pytest.mark.slow

TASK_S = 60.0  # far longer than the battery allows
# PX4 SITL's battery simulator, draining fully in 90 s armed and with no floor
BATTERY = {"SIM_BAT_ENABLE": 1, "SIM_BAT_DRAIN": 90.0, "SIM_BAT_MIN_PCT": 0.0}


def test_battery_drained_early_recalls_from_the_target_and_docks(tmp_path):
    with flying_pair(tmp_path, config="recovery.toml", overrides={"mission.at_target_s": TASK_S},
                     vehicle={"params": BATTERY}) as pair:
        out = pair.finish(timeout_s=120.0)
        events = pair.vehicle.events()
    assert out.phase == Phase.DONE, (out.reason, out.detail)
    s = json.loads((pair.log_dir / "summary.json").read_text())
    rec = pair.controller.state.recovery
    assert rec is not None and rec.why.startswith("battery"), rec
    # recalled from its task at the target, long before the task was done
    arrived = next(t for t, text in pair.events if text == "phase ARRIVED")
    returning = next(t for t, text in pair.events if text == "phase RETURNING")
    assert [text for _, text in pair.events].index("phase RETURNING") == \
        [text for _, text in pair.events].index("phase ARRIVED") + 1
    print(json.dumps({"arrived_s": arrived, "returning_s": returning, "why": rec.why, "contact": s["contact"]}))
    assert returning - arrived < TASK_S / 2
    assert s["docked_again"] and s["recovery_outcome"] == "docked" and s["contact"]["attempts"] == 1
    # home with the reserve: the battery at docking, as the vehicle reported it
    assert s["contact"]["battery_pct"] >= pair.cfg.recovery.battery_reserve_pct, s["contact"]
    # the recall came before PX4's own battery reaction (BAT_LOW_THR 15 %: not even its warning)
    assert not [text for _, _, text in events if "battery" in text.lower()], events
    assert s["px4_params"]["COM_OBL_RC_ACT"] == {"was": 0.0, "set": 3.0, "restored": 0.0}
