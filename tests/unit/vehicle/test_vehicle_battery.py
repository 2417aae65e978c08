"""The mock's battery against PX4 SITL's battery simulator and estimate (sim/vehicle/physics/battery.py):
the drain, the 1 s lag of the estimate, the floor, a full battery when disarmed, the warnings."""
from __future__ import annotations

import pytest

from sim.vehicle.physics import battery
from sim.vehicle.physics.battery import BatteryParams, BatteryState, BatteryWarning

DT_S = 0.01  # PX4's battery simulator runs at 100 Hz


def armed_for(seconds: float, p: BatteryParams, state: BatteryState | None = None) -> BatteryState:
    state = state or battery.step(BatteryState(), DT_S, False, p)
    for _ in range(round(seconds / DT_S)):
        state = battery.step(state, DT_S, True, p)
    return state


@pytest.mark.parametrize(("seconds", "seen_pct"), [(0.0, 100), (2.0, 99), (3.0, 97), (7.1, 90), (11.2, 83)])
def test_px4_defaults_drain_as_a_sitl_reported_it(seconds, seen_pct):
    """SYS_STATUS.battery_remaining of a PX4 SITL (defaults: 60 s, 50 %) seconds after arming
    (docs/flying-px4.md); the SITL's clock ran at about 1.08 x wall time, the samples +-0.1 s."""
    p = BatteryParams()
    assert battery.remaining_pct(armed_for(seconds, p), p) == pytest.approx(seen_pct, abs=1)


def test_voltage_floor_and_full_again_when_disarmed():
    p = BatteryParams()
    full = armed_for(0.0, p)
    assert battery.voltage_mv(full, p) == 16200  # 4 x 4.05 V, as the SITL sent it
    floored = armed_for(45.0, p)
    assert battery.remaining_pct(floored, p) == 50 and floored.charge == pytest.approx(0.5)
    assert battery.step(floored, DT_S, False, p).charge == 1.0


def test_warning_levels_on_the_way_down():
    p = BatteryParams(drain_s=100.0, min_pct=0.0)
    levels = []
    state = armed_for(0.0, p)
    for _ in range(100):
        state = armed_for(1.0, p, state)
        level = battery.warning(state, p)
        if not levels or levels[-1][1] != level:
            levels.append((battery.remaining_pct(state, p), level))
    assert [lv for _, lv in levels] == [BatteryWarning.NONE, BatteryWarning.LOW, BatteryWarning.CRITICAL,
                                        BatteryWarning.EMERGENCY]
    assert [pct for pct, _ in levels[1:]] == [15, 7, 5]  # the first reading under 0.15, 0.07, 0.05
