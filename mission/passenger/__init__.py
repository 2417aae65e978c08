"""The passenger's whole tick as one pure step: raw observations in, setpoint, request and
decision out (:mod:`.step`), from the pure input records the I/O sides and the simulator produce
(:mod:`.inputs`; the measurement feeds' readings among them, :mod:`mission.phases.measurements`). The realtime loop (:class:`mission.controller.MissionController`) and the
in-process simulation (:class:`sim.batch.recovery.World`) call the same step."""
