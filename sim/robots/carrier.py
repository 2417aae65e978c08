"""The simulated carrier: :class:`mission.carrier.controller.CarrierController` driving the
built-in kinematic robot (:class:`mission.carrier.backends.sim.SimRobot`); with
``world.carrier_gnss.enabled`` the carrier steers on and publishes its robot's state as an erring
GNSS gives it (:class:`sim.gnss.ErringCarrier`).

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
from sim.gnss import ErringCarrier

__all__ = ["CarrierSim", "CarrierMode", "carrier_model"]


class CarrierSim(CarrierController):
    """The carrier controller on its own kinematic robot (see :class:`CarrierController`)."""

    def __init__(self, cfg: Config, clock: Clock, session: zenoh.Session, *, pair: str | None = None,
                 encoding: str | None = None) -> None:
        self.robot = SimRobot(cfg, clock)
        gnss = cfg.world.carrier_gnss
        backend = ErringCarrier(self.robot, gnss) if gnss.enabled else self.robot
        super().__init__(cfg, clock, session, backend, pair=pair, encoding=encoding)

    @property
    def position_m(self):  # type: ignore[no-untyped-def]
        """The robot's true position [m] (scenario dimension)."""
        return self.robot.position_m
