"""Writing a log directory: :class:`FlightRecorder` writes ``record.csv``, one row per controller
tick (and hands each row to its :class:`RecordSink` s, e.g. ``flight.mcap``), ``mission.json``
at the start and, on closing, ``summary.json``: the record's figures (:mod:`mission.record.figures`)
with how the mission ended. Time [s] on the mission clock (:data:`CLOCK_NOTE`).
"""
from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any, Callable, Protocol, Sequence

from mission.core.setpoint import Setpoint
from mission.record.figures import summarise
from mission.record.table import COLUMNS, TickRow

CLOCK_NOTE = ("times here and in record.csv (t_s) are on the mission clock [s] since the controller started; "
              "summary.json counts from riding_start_s, the start of riding (t = 0 as in the paper)")


class RecordSink(Protocol):
    """Where a flight record goes besides ``record.csv`` (e.g. :class:`mission.flightdata.MissionLog`).

    ``tick`` runs in the control loop: it must return at once (queue the row, work elsewhere).
    ``counters`` gives the sink a way to read the feed's and link's counters when it wants them
    (off the loop). ``close`` gets ``mission.json``'s final content and the summary."""

    def tick(self, row: TickRow) -> None: ...

    def set_counters(self, counters: Callable[[], dict[str, Any]]) -> None: ...

    def close(self, info: dict[str, Any], summary: dict[str, Any]) -> None: ...


class FlightRecorder:
    """Writes one row per tick to ``record.csv`` (and to each of ``sinks``) and keeps the
    numbers for the summary."""

    def __init__(self, directory: str | Path, mission_info: dict[str, Any], sinks: Sequence[RecordSink] = ()) -> None:
        self.dir = Path(directory)
        self.dir.mkdir(parents=True, exist_ok=True)
        (self.dir / "mission.json").write_text(json.dumps(mission_info, indent=2))
        self._file = open(self.dir / "record.csv", "w", newline="")
        self._csv = csv.writer(self._file)
        self._csv.writerow(COLUMNS)
        self.sinks = list(sinks)
        self.rows = 0

    @property
    def tlog_path(self) -> Path:
        return self.dir / "flight.tlog"

    def set_counters(self, counters: Callable[[], dict[str, Any]]) -> None:
        """How the sinks read the drop and link counters (the controller's)."""
        for sink in self.sinks:
            sink.set_counters(counters)

    def record(self, t_s: float, phase: str, x_p, v_p, x_c, v_c, dock, x_ref, P: float, relative, desired, u_cmd,
               safety_acted: bool, carrier_age_s: float, mode: str, armed: bool) -> None:
        """Record a row given field by field (see :class:`TickRow`; ``u_cmd`` a velocity setpoint [m/s])."""
        self.record_row(TickRow(t_s, phase, x_p, v_p, x_c, v_c, dock, x_ref, P, relative, desired,
                                None if u_cmd is None else Setpoint(u_cmd), safety_acted, carrier_age_s, mode, armed))

    def record_row(self, row: TickRow) -> None:
        values = row.values()
        values[0] = f"{row.t_s:.4f}"
        self._csv.writerow(values)
        self.rows += 1
        self._file.flush()  # one write per tick: a killed controller leaves every tick it ran on disk
        for sink in self.sinks:
            sink.tick(row)

    def close(self, outcome: dict[str, Any] | None = None, info_update: dict[str, Any] | None = None) -> dict[str, Any]:
        """Close the CSV, add ``info_update`` (e.g. the latched anchor) to ``mission.json``,
        write ``summary.json`` (returned) and close the sinks."""
        self._file.close()
        info = json.loads((self.dir / "mission.json").read_text())
        info.update(info_update or {})
        (self.dir / "mission.json").write_text(json.dumps(info, indent=2))
        summary = summarise(self.dir)
        info["clock"] = CLOCK_NOTE
        info["riding_start_s"] = summary.get("riding_start_s")
        (self.dir / "mission.json").write_text(json.dumps(info, indent=2))
        if outcome:
            summary.update(outcome)
        (self.dir / "summary.json").write_text(json.dumps(summary, indent=2))
        for sink in self.sinks:
            sink.close(info, summary)
        return summary
