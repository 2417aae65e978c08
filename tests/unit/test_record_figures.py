"""Flight-record figures of a leg that never separated: no separation figures, no crash."""

import numpy as np

from mission.phases.phase import Phase
from mission.record.figures import figures
from mission.record.table import COLUMNS, FlightRecord


def _record(phases: list[Phase], info: dict) -> FlightRecord:
    n = len(phases)
    cols = {c: np.zeros(n) for c in COLUMNS if c not in ("t_s", "phase", "mode")}
    cols["x_p_d"] = np.full(n, -1.0)
    return FlightRecord(t=np.arange(n) * 0.02, phase=np.array(phases, dtype=object), cols=cols, info=info)


def test_a_leg_that_aborted_before_separating_has_no_separation_figures():
    """A leg that aborts while riding and falls back: the mission reports ``separation_time_s``
    as None. The record's fallback ticks are not a separation, and the figures do not raise."""
    info = {"target_ned_m": [30.0, 0.0, -5.0], "separation_time_s": None}
    out = figures(_record([Phase.RIDING] * 20 + [Phase.FALLBACK] * 10, info))
    assert out["separation_time_s"] is None
    assert out["relative_input_jump_m_s"] is None


def test_a_separated_leg_counts_from_the_missions_separation_time():
    info = {"target_ned_m": [30.0, 0.0, -5.0], "separation_time_s": 0.30}
    out = figures(_record([Phase.RIDING] * 20 + [Phase.SEPARATED] * 10, info))
    assert out["separation_time_s"] == 0.30
    info.pop("separation_time_s")
    assert abs(figures(_record([Phase.RIDING] * 20 + [Phase.SEPARATED] * 10, info))["separation_time_s"] - 0.40) < 1e-9
