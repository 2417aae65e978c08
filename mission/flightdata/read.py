"""Reading a flight's MCAP back, whole or cut short (a killed process leaves no summary, no
footer and an unfinished last chunk): records are read in file order up to the first that cannot
be read, with the ``mcap`` package's stream reader.
"""
from __future__ import annotations

import json
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
