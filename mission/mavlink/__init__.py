"""MAVLink 2 to one PX4 vehicle, one concept per module.

* link URLs are parsed by :mod:`mission.config.urls` (the one parser: the configuration and the
  mock vehicle use it too);
* :mod:`~mission.mavlink.transport`: bytes in and out (UDP listen/send, TCP, serial) behind one
  small interface;
* :mod:`~mission.mavlink.codec`: pymavlink codecs, datagram-safe parsing and MAVLink 2 signing;
* :mod:`~mission.mavlink.telemetry`: the vehicle's state as a pure reducer of received
  messages, the STATUSTEXT assembler and the immutable :class:`VehicleState` snapshot;
* :mod:`~mission.mavlink.commands`: COMMAND_LONG's ACK / IN_PROGRESS / retry cycle and the
  HEARTBEAT confirmation of a mode or arming change, as state machines on the injected clock;
* :mod:`~mission.mavlink.setpoints`: the one encoding of a :class:`~mission.core.setpoint.Setpoint`
  (SET_POSITION_TARGET_LOCAL_NED, type masks) and its decoding, which the mock vehicle reads through;
* :mod:`mission.mavlink.link`: the thin facade a mission uses (threads, identity, send, tlog).
"""
