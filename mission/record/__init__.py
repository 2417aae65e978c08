"""The flight record: the log directory a flight leaves, and the figures read from it.

A log directory holds ``record.csv`` (the controller's own record, one row per tick:
:mod:`mission.record.table`), ``summary.json`` (the same keys as ``marsupial simulate --json``,
computed from the record by :mod:`mission.record.figures`, plus how the mission ended and the
drop counters: ``carrier_feed`` = received, accepted, ``dropped`` per reason, ``bound_source``,
``rejected_sources`` per source, ``resyncs``; ``link`` = the MAVLink link's counters, e.g.
``rejected_foreign``, ``rx_unsigned``, ``rx_bad_signature``: :mod:`mission.record.info`),
``mission.json`` (target, obstacles, b c: what a plot needs; :mod:`mission.record.info`) and
``flight.tlog`` (every MAVLink packet, written by the link; readable by pymavlink's
``mavlogdump.py``). :class:`~mission.record.recorder.FlightRecorder` writes the directory;
``marsupial run`` adds ``flight.mcap`` (:mod:`mission.flightdata`): a
:class:`~mission.record.recorder.RecordSink` fed the same :class:`~mission.record.table.TickRow`
as the CSV. Frames: local NED [m], [m/s]; time [s] on the controller's clock.
"""
