"""Reading a flight's MCAP back, whole or cut short (a killed process leaves no summary, no
footer and an unfinished last chunk): records are read in file order up to the first that cannot
be read, with the ``mcap`` package's stream reader.
"""
from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

from mission.errors import ConfigError

RECORD_SCHEMA = "marsupial.FlightRecord"


@dataclass
class McapContent:
    """What a (possibly cut) MCAP holds: ``messages`` as (topic, schema name, log time [ns],
    data bytes) in file order, ``metadata`` by record name, and whether the file was complete
    (its footer read)."""

    messages: list[tuple[str, str, int, bytes]] = field(default_factory=list)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    complete: bool = False

    @property
    def epoch_ns(self) -> int:
        """The epoch of the log times [ns since the Unix epoch]: a log time minus it is the
        mission clock's time (0 for a file without one)."""
        try:
            return int(self.metadata.get("clock", {}).get("epoch_ns", 0))
        except ValueError:
            return 0


def read_messages(path: str | Path, topics: set[str] | None = None) -> McapContent:
    """Every message (of ``topics``, if given) and metadata record of the MCAP at ``path``, in
    file order, up to the end of the file or the first record that cannot be read."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Footer, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

    out = McapContent()
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}
    with open(path, "rb") as f:
        records: Iterator[Any] = StreamReader(f, record_size_limit=1 << 30).records
        try:
            for record in records:
                if isinstance(record, Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, Channel):
                    channels[record.id] = (record.topic, schemas.get(record.schema_id, ""))
                elif isinstance(record, Message):
                    topic, schema = channels.get(record.channel_id, ("", ""))
                    if topics is None or topic in topics:
                        out.messages.append((topic, schema, record.log_time, record.data))
                elif isinstance(record, Metadata):
                    out.metadata[record.name] = dict(record.metadata)
                elif isinstance(record, Footer):
                    out.complete = True
        except (McapError, EOFError, struct.error, ValueError):
            pass  # the end of what a killed writer left (mcap's EndOfFile is an McapError)
    return out


def read_mcap_record(path: str | Path) -> tuple[list[str], list[list[Any]], dict[str, Any]]:
    """The flight record of a ``flight.mcap`` (its ``marsupial.FlightRecord`` channel): header,
    columns (values per column, None for a missing value) and ``mission.json``'s content (the
    ``mission`` metadata, updated by ``mission_end`` when the flight ended normally)."""
    content = read_messages(path)
    rows = [json.loads(data) for _, schema, _, data in content.messages if schema == RECORD_SCHEMA]
    if not rows:
        raise ConfigError("LOG", str(path), "holds no flight record (no marsupial.FlightRecord messages): "
                          "give a flight.mcap written by `marsupial run`")
    header = list(rows[0])
    columns = [[row.get(name) for row in rows] for name in header]
    info: dict[str, Any] = {}
    for name in ("mission", "mission_end"):
        info.update({k: json.loads(v) for k, v in content.metadata.get(name, {}).items()})
    return header, columns, info


def _varint(data: bytes, i: int) -> tuple[int, int]:
    value, shift = 0, 0
    while True:
        b = data[i]
        i += 1
        value |= (b & 0x7F) << shift
        shift += 7
        if not b & 0x80:
            return value, i


def _fields(data: bytes) -> Iterator[tuple[int, int | bytes]]:
    """(field number, value) of a protobuf message: varints as int, length-delimited as bytes
    (fixed-size fields skipped)."""
    i = 0
    while i < len(data):
        key, i = _varint(data, i)
        number, wire = key >> 3, key & 7
        if wire == 0:
            value, i = _varint(data, i)
            yield number, value
        elif wire == 2:
            size, i = _varint(data, i)
            yield number, data[i:i + size]
            i += size
        elif wire in (1, 5):
            i += 8 if wire == 1 else 4
        else:
            raise ValueError(f"protobuf wire type {wire} not expected in foxglove.Log")


def log_lines(content: McapContent, topic: str) -> list[tuple[float, int, str]]:
    """The ``foxglove.Log`` messages of ``topic``: (mission-clock time [s], level, text). The Log schema is
    small and fixed (timestamp = 1 {sec = 1, nsec = 2}, level = 2, message = 3): read by hand,
    so reading needs no protobuf runtime."""
    out = []
    for t, schema, log_time, data in content.messages:
        if t != topic or schema != "foxglove.Log":
            continue
        level, text = 0, ""
        for number, value in _fields(data):
            if number == 2 and isinstance(value, int):
                level = value
            elif number == 3 and isinstance(value, bytes):
                text = value.decode("utf-8", errors="replace")
        out.append(((log_time - content.epoch_ns) / 1e9, level, text))
    return out


TEAM_SCHEMA = "marsupial.Team"
STATUS_SCHEMA = "marsupial.CarrierStatus"


@dataclass(frozen=True)
class TeamRecord:
    """A team's ``carrier.mcap`` read back (its ``marsupial.Team`` and ``marsupial.CarrierStatus``
    messages, its ``team`` metadata), as arrays on the carrier's clock [s] (the mission clock: a log
    time minus the file's epoch).

    names: the passengers, the team's order; t [s] (K,) the team messages' times; positions [m]
    (K, m, 3) NED each passenger's reported position as heard (NaN: not heard); phases (K, m) their
    phase names (None: not heard); pairs: the pairs' names (a, b), the file's order; distances [m]
    (K, P) each pair's distance at the carrier's clock (NaN: none); counted (K, P) whether it
    counts for the closest pair; carrier_t [s] (J,) and carrier [m] (J, 3) the carrier's own
    position from its status (NaN: no own state); targets [m] (T, 3) NED and owners (T,) each
    target's passenger; bc_m [m] b c; separation_m [m] ``safety.passenger_separation_m``."""

    names: list[str]
    t: Any
    positions: Any
    phases: Any
    pairs: list[tuple[str, str]]
    distances: Any
    counted: Any
    carrier_t: Any
    carrier: Any
    targets: Any
    owners: list[str]
    bc_m: float
    separation_m: float

    def closest(self) -> tuple[float, float, int] | None:
        """(distance [m], t [s], pair index) of the least counted distance; None: none counts."""
        import numpy as np

        d = np.where(self.counted, self.distances, np.inf)
        if not np.isfinite(d).any():
            return None
        k, p = np.unravel_index(int(np.argmin(d)), d.shape)
        return float(d[k, p]), float(self.t[k]), int(p)


def is_team_log(path: str | Path) -> bool:
    """Whether the MCAP at ``path`` is a team's ``carrier.mcap`` (it has the ``team`` metadata)."""
    return "team" in read_messages(path, topics=set()).metadata


def read_team(path: str | Path) -> TeamRecord:
    """The :class:`TeamRecord` of a team's ``carrier.mcap`` (:class:`ConfigError` naming ``LOG``
    when the file has no team: a single pair's carrier, or not a carrier's file)."""
    import numpy as np

    content = read_messages(path)
    meta = {k: json.loads(v) for k, v in content.metadata.get("team", {}).items()}
    if not meta:
        raise ConfigError("LOG", str(path), "is not a team's carrier.mcap (no `team` metadata): give the carrier.mcap "
                          "of `marsupial carrier` with a [team] of several (the team demo's log root)")
    names = list(meta["names"])
    team = [(log_time, json.loads(data)) for _, schema, log_time, data in content.messages if schema == TEAM_SCHEMA]
    status = [(log_time, json.loads(data)) for _, schema, log_time, data in content.messages if schema == STATUS_SCHEMA]
    epoch = content.epoch_ns

    def ned(v: Any) -> list[float]:
        return [math.nan] * 3 if v is None else [v["n"], v["e"], v["d"]]

    pairs = [(p["a"], p["b"]) for p in team[0][1]["pairs"]] if team else []
    return TeamRecord(
        names=names, t=np.array([(lt - epoch) / 1e9 for lt, _ in team]),
        positions=np.array([[ned(h["position"]) for h in m["passengers"]] for _, m in team]).reshape(-1, len(names), 3),
        phases=np.array([[h["phase"] for h in m["passengers"]] for _, m in team], dtype=object).reshape(-1, len(names)),
        pairs=pairs,
        distances=np.array([[math.nan if p["distance_m"] is None else p["distance_m"] for p in m["pairs"]]
                            for _, m in team], dtype=float).reshape(-1, len(pairs)),
        counted=np.array([[bool(p["counted"]) for p in m["pairs"]] for _, m in team], dtype=bool).reshape(-1, len(pairs)),
        carrier_t=np.array([(lt - epoch) / 1e9 for lt, _ in status]),
        carrier=np.array([ned(m["position"]) for _, m in status], dtype=float).reshape(-1, 3),
        targets=np.array(meta["targets"], dtype=float).reshape(-1, 3), owners=list(meta["owners"]),
        bc_m=float(meta["bc_m"]), separation_m=float(meta["separation_m"]))
