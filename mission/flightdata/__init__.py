"""Flight data where robotics tools read it: MCAP flight logs and a live Foxglove view.

A :class:`~mission.flightdata.mission_log.MissionLog` is a sink of the flight record
(:class:`mission.record.table.TickRow`): the rows the CSV gets also become Foxglove messages
(transforms, a 3D scene, a log, JSON channels) in ``flight.mcap`` and, with ``--live``, on the
foxglove-sdk's WebSocket server. :class:`~mission.flightdata.carrier_log.CarrierLog` does the same
for ``marsupial carrier``. The control loop only queues a row; messages are made and written on
a worker thread (:class:`~mission.flightdata.writer.DataLog`), which finishes an MCAP chunk every
second of the mission clock so that a killed process leaves a readable file up to its last
second. Topics, frames and schemas: :mod:`mission.flightdata.topics`; reading back:
:mod:`mission.flightdata.read`; the Foxglove layout: :mod:`mission.flightdata.layout`.
"""
