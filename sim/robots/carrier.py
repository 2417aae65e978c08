"""The simulated carrier: :class:`mission.carrier.controller.CarrierController` driving the
built-in kinematic robot (:class:`mission.carrier.backends.sim.SimRobot`).

Kept for the simulator's tests and tools; the program is ``marsupial carrier`` in
:mod:`mission.carrier.cli` (backend ``sim`` is this).
"""
from __future__ import annotations

import zenoh

from mission.carrier.controller import CarrierController, carrier_model
from mission.carrier.modes import CarrierMode
from mission.carrier.backends.sim import SimRobot
from mission.time.clock import Clock
from mission.config.schema import Config

__all__ = ["CarrierSim", "CarrierMode", "carrier_model"]


class CarrierSim(CarrierController):
    """The carrier controller on its own kinematic robot (see :class:`CarrierController`)."""

    def __init__(self, cfg: Config, clock: Clock, session: zenoh.Session, *, pair: str | None = None,
                 encoding: str | None = None) -> None:
        self.robot = SimRobot(cfg, clock)
        super().__init__(cfg, clock, session, self.robot, pair=pair, encoding=encoding)

    @property
    def position_m(self):  # type: ignore[no-untyped-def]
        """The robot's true position [m] (scenario dimension)."""
        return self.robot.position_m
