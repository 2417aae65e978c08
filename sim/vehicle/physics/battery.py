"""PX4 SITL's battery as the mock vehicle simulates it: its battery simulator, the battery
library's estimate, and the low-battery levels PX4's failsafe acts on. Pure; times in simulated
seconds [s].

PX4 (``src/modules/simulation/battery_simulator``, ``src/lib/battery``), and what a PX4 SITL
showed (docs/flying-px4.md):

- the simulator's state of charge starts at 1 and, while armed, falls by ``dt / SIM_BAT_DRAIN``
  per step, never below ``SIM_BAT_MIN_PCT`` / 100; disarmed it is 1 again;
- it reports the voltage ``BAT1_N_CELLS`` x (``BAT1_V_EMPTY`` + charge x (``BAT1_V_CHARGED`` -
  ``BAT1_V_EMPTY``)) and no current (-1 A);
- the battery library low-passes the cell voltage (time constant 1 s) and, with no capacity
  (``BAT1_CAPACITY`` -1) and no current, its remaining is that filtered voltage mapped back
  linearly between empty and charged: the simulator's charge, 1 s late;
- SYS_STATUS and BATTERY_STATUS carry ``battery_remaining`` = ceil(remaining x 100) [%]. On a
  SITL at PX4's defaults (60 s, 50 %) it read 100 disarmed, 99 two seconds after arming, 83
  after 11.2 s, and fell no further than 50;
- the warning levels: below ``BAT_LOW_THR`` low, ``BAT_CRIT_THR`` critical, ``BAT_EMERGEN_THR``
  emergency (fractions).

*The mock's one departure: ``SIM_BAT_ENABLE`` is 0 unless asked (PX4 SITL: 1), so a flight
that does not ask reports no battery (remaining -1), as before; PX4's default drain would
recall any recovery mission within a minute of flight.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from sim.vehicle.params import ParamTable

FILTER_TAU_S = 1.0  # PX4's battery library: low-pass of the cell voltage [s]


class BatteryWarning(enum.IntEnum):
    """PX4's battery warning (battery_status.warning), ordered by severity."""

    NONE = 0
    LOW = 1
    CRITICAL = 2
    EMERGENCY = 3


@dataclass(frozen=True)
class BatteryParams:
    """The parameters that shape it: drain time [s], floor [%], cells, cell voltages [V],
    warning thresholds [fraction]."""

    drain_s: float = 60.0
    min_pct: float = 50.0
    cells: int = 4
    v_charged: float = 4.05
    v_empty: float = 3.6
    low_thr: float = 0.15
    crit_thr: float = 0.07
    emergen_thr: float = 0.05


@dataclass(frozen=True)
class BatteryState:
    """The simulator's charge [0..1] and the estimate's filtered cell voltage [V]."""

    charge: float = 1.0
    cell_v: float | None = None  # None: the filter starts at the first step


def step(state: BatteryState, dt_s: float, armed: bool, p: BatteryParams) -> BatteryState:
    """The battery after ``dt_s`` [s]: drained while armed, full again when disarmed."""
    charge = max(state.charge - dt_s / p.drain_s, p.min_pct / 100.0) if armed else 1.0
    cell = p.v_empty + charge * (p.v_charged - p.v_empty)
    if state.cell_v is None:
        return BatteryState(charge, cell)
    alpha = 1.0 - math.exp(-dt_s / FILTER_TAU_S)
    return BatteryState(charge, state.cell_v + (cell - state.cell_v) * alpha)


def remaining(state: BatteryState, p: BatteryParams) -> float:
    """The estimate's remaining [0..1]: the filtered cell voltage between empty and charged."""
    cell = p.v_empty + state.charge * (p.v_charged - p.v_empty) if state.cell_v is None else state.cell_v
    return min(max((cell - p.v_empty) / (p.v_charged - p.v_empty), 0.0), 1.0)


def remaining_pct(state: BatteryState, p: BatteryParams) -> int:
    """``battery_remaining`` [%] as PX4's SYS_STATUS carries it: rounded up."""
    return int(math.ceil(remaining(state, p) * 100.0 - 1e-6))


def voltage_mv(state: BatteryState, p: BatteryParams) -> int:
    """The pack's (filtered) voltage [mV] as SYS_STATUS carries it."""
    cell = p.v_empty + state.charge * (p.v_charged - p.v_empty) if state.cell_v is None else state.cell_v
    return int(round(cell * p.cells * 1000.0))


def warning(state: BatteryState, p: BatteryParams) -> BatteryWarning:
    """PX4's warning level for the estimate (``determineWarning``)."""
    left = remaining(state, p)
    if left < p.emergen_thr:
        return BatteryWarning.EMERGENCY
    if left < p.crit_thr:
        return BatteryWarning.CRITICAL
    if left < p.low_thr:
        return BatteryWarning.LOW
    return BatteryWarning.NONE


def params_of(table: ParamTable) -> BatteryParams | None:
    """The battery's parameters from the vehicle's table; None: not simulated (SIM_BAT_ENABLE 0)."""
    p = table.get
    if not p("SIM_BAT_ENABLE"):
        return None
    return BatteryParams(max(p("SIM_BAT_DRAIN"), 1.0), p("SIM_BAT_MIN_PCT"), int(p("BAT1_N_CELLS")),  # PX4's minimum: 1 s
                         p("BAT1_V_CHARGED"), p("BAT1_V_EMPTY"), p("BAT_LOW_THR"), p("BAT_CRIT_THR"), p("BAT_EMERGEN_THR"))


class Battery:
    """A vehicle's simulated battery, stepped with its commander at every physics step; its
    parameters come from ``table`` (derived again only after a change)."""

    def __init__(self, table: ParamTable) -> None:
        self.table = table
        self.state = BatteryState()
        self.level = BatteryWarning.NONE
        self._t_s = 0.0
        self._params: tuple[int, BatteryParams | None] | None = None

    @property
    def params(self) -> BatteryParams | None:
        cached = self._params
        if cached is None or cached[0] != self.table.version:
            cached = self._params = (self.table.version, params_of(self.table))
        return cached[1]

    def update(self, t_s: float, armed: bool) -> BatteryWarning | None:
        """Step to ``t_s`` [s]; the warning level newly reached while armed, else None."""
        p, dt_s = self.params, t_s - self._t_s
        self._t_s = t_s
        if p is None or dt_s <= 0:
            return None
        self.state = step(self.state, dt_s, armed, p)
        level, before = warning(self.state, p), self.level
        self.level = level
        return level if armed and level > before else None

    def reading(self) -> tuple[int, int] | None:
        """(battery_remaining [%], voltage [mV]) as SYS_STATUS carries them; None: not simulated."""
        p = self.params
        return None if p is None else (remaining_pct(self.state, p), voltage_mv(self.state, p))
