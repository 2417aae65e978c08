"""The flight record as a table: its columns, one controller tick's row, and the table read back.

:data:`COLUMNS` are ``record.csv``'s columns (and those of ``flight.mcap``'s record channel); a
:class:`TickRow` is what one tick did, as the recorder (:mod:`mission.record.recorder`) and its
sinks receive it; :func:`read_record` reads a log directory (or an MCAP file) back as a
:class:`FlightRecord` of arrays, which :meth:`FlightRecord.legs` cuts into its :class:`Leg` s.
Frames: local NED [m], [m/s]; time [s] on the mission clock (the controller's).
"""
from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mission.core.setpoint import Setpoint
from mission.phases.types import RelativeView

VEC = ("n", "e", "d")
COLUMNS = (
    ["t_s", "phase"]
    + [f"x_p_{a}" for a in VEC] + [f"v_p_{a}" for a in VEC]
    + [f"x_c_{a}" for a in VEC] + [f"v_c_{a}" for a in VEC]
    + [f"dock_{a}" for a in VEC] + [f"x_ref_{a}" for a in VEC]
    + ["P"] + [f"relative_{a}" for a in VEC] + [f"desired_{a}" for a in VEC] + [f"u_cmd_{a}" for a in VEC]
    + ["safety_acted", "carrier_age_s", "mode", "armed", "vehicle_age_s"]
)


def _vec(v: np.ndarray | None) -> list[float]:
    if v is None:
        return [float("nan")] * 3
    return v.tolist() if isinstance(v, np.ndarray) and v.dtype == np.float64 else [float(x) for x in v]


@dataclass(frozen=True)
class TickRow:
    """What one controller tick did: the flight record's row, as every sink receives it.

    t_s [s] mission clock; phase (a :class:`~mission.phases.Phase` value) after the tick;
    x_p, v_p the vehicle and x_c, v_c the carrier sample used [m], [m/s] NED (None: none seen);
    dock the dock point the law treats as the carrier [m]; x_ref, u_ref the reference [m], [m/s];
    P the law's potential gradient (NaN outside riding and navigation); relative the law's
    ``u_p - u_c`` and desired its command [m/s]; setpoint the :class:`~mission.core.setpoint.Setpoint`
    sent (None: nothing sent; its velocity is the CSV's u_cmd); safety_acted whether a filter
    changed the command; carrier_age_s [s] the sample's age (since the carrier measured it once
    its clock offset is known, else since it arrived); mode, armed the vehicle's; vehicle_age_s [s]
    since its newest LOCAL_POSITION_NED arrived (NaN: none); anchor the
    latched separation point [m] (None before); course the carrier's course (horizontal unit
    vector NED) while a recovery brings the passenger home (None otherwise); events what
    happened on this tick (phase change first), as text; yaw_c, yaw_p the carrier's and the
    vehicle's heading [rad] from north (None: not known; the flight data's transforms, not the
    CSV); relnav the relative estimator's view of this tick (``[relnav]`` enabled and the
    estimate begun; None otherwise: the flight data's relnav channel, not the CSV). The CSV holds
    the columns of :data:`COLUMNS`; the arrays are never written to after the row is made (a sink
    may read them on another thread).
    """

    t_s: float
    phase: str
    x_p: np.ndarray | None
    v_p: np.ndarray | None
    x_c: np.ndarray | None
    v_c: np.ndarray | None
    dock: np.ndarray | None
    x_ref: np.ndarray | None
    P: float
    relative: np.ndarray | None
    desired: np.ndarray | None
    setpoint: Setpoint | None
    safety_acted: bool
    carrier_age_s: float
    mode: str
    armed: bool
    u_ref: np.ndarray | None = None
    anchor: np.ndarray | None = None
    course: np.ndarray | None = None
    events: tuple[str, ...] = ()
    yaw_c: float | None = None
    yaw_p: float | None = None
    vehicle_age_s: float = float("nan")
    relnav: RelativeView | None = None

    def values(self) -> list[Any]:
        """The row's values in the order of :data:`COLUMNS` (vectors flattened, NaN for None)."""
        return [self.t_s, self.phase, *_vec(self.x_p), *_vec(self.v_p), *_vec(self.x_c), *_vec(self.v_c),
                *_vec(self.dock), *_vec(self.x_ref), self.P, *_vec(self.relative), *_vec(self.desired),
                *_vec(self.u_cmd), int(self.safety_acted), self.carrier_age_s, self.mode, int(self.armed),
                self.vehicle_age_s]

    @property
    def u_cmd(self) -> np.ndarray | None:
        """The velocity sent [m/s] NED (None: nothing sent)."""
        return None if self.setpoint is None else self.setpoint.velocity_ned_m_s

@dataclass(frozen=True)
class FlightRecord:
    """A ``record.csv`` read back as arrays: t (K,); phase (K,) str; vectors (K, 3)."""

    t: np.ndarray
    phase: np.ndarray
    cols: dict[str, np.ndarray]
    info: dict[str, Any]

    def vec(self, name: str) -> np.ndarray:
        return np.stack([self.cols[f"{name}_{a}"] for a in VEC], axis=-1)

    def between(self, start_s: float, end_s: float, info: dict[str, Any]) -> FlightRecord:
        """The ticks with ``start_s < t <= end_s`` [s, mission clock], with ``info`` as its mission info."""
        keep = (self.t > start_s) & (self.t <= end_s)
        return FlightRecord(t=self.t[keep], phase=self.phase[keep], cols={k: v[keep] for k, v in self.cols.items()},
                            info=info)

    def legs(self) -> list[Leg]:
        """The record cut into its legs, one per target of ``info["targets"]`` (one leg for a
        one-target flight): each flown leg's ticks with its own target (and, once done, its
        separation, anchor, contact and outcome) in its info; a leg not flown has no record."""
        done = self.info.get("legs_done") or []
        targets = self.info.get("targets") or [self.info["target_ned_m"]]
        out: list[Leg] = []
        start = -np.inf
        for k, target in enumerate(targets):
            if k < len(done):
                leg = done[k]
                info = {**self.info, "target_ned_m": target, "separation_time_s": leg["separation_time_s"],
                        "anchor_ned_m": leg["anchor_ned_m"], "recovered": {"contact": leg["contact"], "fallback": None}}
                end = leg["end_s"] if k + 1 < len(targets) else np.inf
                out.append(Leg(k, list(target), self.between(start, end, info), leg["outcome"]))
                start = leg["end_s"]
            elif k == len(done) and self.info.get("legs_skipped") is None and len(self.t) and self.t[-1] > start:
                out.append(Leg(k, list(target), self.between(start, np.inf, {**self.info, "target_ned_m": target}),
                               "unfinished"))
            else:
                out.append(Leg(k, list(target), None, f"skipped: {self.info.get('legs_skipped') or 'not reached'}"))
        return out


@dataclass(frozen=True)
class Leg:
    """One leg of a flight record: its index k (from 0), its target [m] NED, its ticks (None: not
    flown) and its outcome ("docked", "unfinished", "skipped: ...", ...)."""

    k: int
    target_ned_m: list[float]
    record: FlightRecord | None
    outcome: str


def read_record(path: str | Path) -> FlightRecord:
    """A flight record read back: a log directory's ``record.csv`` with its ``mission.json``;
    a log directory with no ``record.csv`` but a ``flight.mcap``, or an MCAP file itself, through
    :func:`mission.flightdata.read.read_mcap_record` (the same columns, same values)."""
    path = Path(path)
    mcap = path if path.is_file() else path / "flight.mcap"
    if path.is_file() or (not (path / "record.csv").is_file() and mcap.is_file()):
        from mission.flightdata.read import read_mcap_record

        header, columns, info = read_mcap_record(mcap)
    else:
        info = json.loads((path / "mission.json").read_text())
        with open(path / "record.csv", newline="") as f:
            reader = csv.reader(f)
            header = next(reader, list(COLUMNS))
            columns = [[] for _ in header]
            for row in reader:  # column lists, not a dict per row: a long flight stays small
                if len(row) == len(header):
                    for column, value in zip(columns, row):
                        column.append(value)
    text = {"phase", "mode"}
    cols = {name: np.array(values, dtype=float) for name, values in zip(header, columns) if name not in text}
    phase = np.array(columns[header.index("phase")], dtype=str)
    return FlightRecord(t=cols["t_s"], phase=phase, cols=cols, info=info)
