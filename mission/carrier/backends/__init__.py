"""The carrier robots ``marsupial carrier`` drives, by the name ``carrier.backend`` gives.

Each backend is a module of this package with ``open_backend(cfg, clock, session)`` (the backend,
a :class:`CarrierBackend`, whose own state is an :class:`OwnState`) and ``describe(cfg)`` (one
line for the start-up message). :data:`~mission.config.carrier.KINDS` is the one list of them:
the configuration's choices, ``--backend``'s choices and the configuration reference derive from
it. Adding a backend is its module, and its entry in :data:`~mission.config.carrier.KINDS` with
its ``[carrier.<name>]`` section in :mod:`mission.config.carrier` if it has settings. Loading
this package imports no backend (and nothing of I/O): a backend is imported when opened.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from mission.config.carrier import KINDS, BackendKind

if TYPE_CHECKING:
    import zenoh

    from mission.carrier.tracking import Tracked
    from mission.config.schema import Config
    from mission.time.clock import Clock, Downstream

__all__ = ["KINDS", "BackendKind", "CarrierBackend", "OwnState", "describe", "open_backend"]


@dataclass(frozen=True)
class OwnState:
    """The carrier's own state: t_s [s] clock time of the measurement; position_ned_m (3,) [m]
    and velocity_ned_m_s (3,) [m/s] in the shared local NED frame; yaw_rad [rad] or None.

    inertial: where the state is a GNSS fix (the simulators' world errors,
    :class:`sim.gnss.ErringCarrier`), the robot's own navigation state now, as its autopilot's
    inertial estimate has it (timely, no fix's latency or noise; a velocity has no frame origin to
    be off by), the carrier's measured acceleration is taken from (``carrier.acceleration_tau_s``);
    None: the state is that estimate already (every real backend)."""

    t_s: float
    position_ned_m: np.ndarray
    velocity_ned_m_s: np.ndarray
    yaw_rad: float | None
    inertial: OwnState | None = None


class CarrierBackend(Protocol):
    """What the controller needs of a carrier robot (the kinds: :mod:`mission.carrier.backends`)."""

    name: str
    brakes_itself: bool  # a real vehicle brakes with its own limits: "stop" is sent at once, not ramped

    def advance(self, dt_s: float) -> None:
        """Move ``dt_s`` [s] under the held command (the built-in robot; no-op for real ones)."""

    def own_state(self) -> OwnState | None:
        """The newest own state, or None before the first."""

    def engage(self) -> None:
        """The carrier has to move now: take control of the vehicle (arm, OFFBOARD) if needed."""

    def control_fault(self) -> str | None:
        """Why the vehicle does not take our commands now (None: it does)."""

    def command(self, cmd: Tracked) -> None:
        """Send (or hold) the command: a setpoint velocity, or forward speed and yaw rate."""

    def park(self) -> None:
        """The carrier is stopped for good: hand the vehicle to its own position hold, if it has one."""

    def lockstep_relay(self, session: zenoh.Session) -> Downstream | None:
        """In lockstep, how the carrier brings its robot along if that robot is simulated in a
        process of its own (None: it is not, or it cannot step)."""

    def close(self) -> None:
        """Leave the vehicle safe and release what was opened."""


def _module(cfg: Config) -> Any:
    return importlib.import_module(KINDS[cfg.carrier.backend].module)


def open_backend(cfg: Config, clock: Clock, session: zenoh.Session) -> CarrierBackend:
    """The backend ``cfg.carrier.backend`` names, opened on ``clock`` (and ``session``, for one
    that talks over Zenoh); the caller closes it."""
    backend: CarrierBackend = _module(cfg).open_backend(cfg, clock, session)
    return backend


def describe(cfg: Config) -> str:
    """What the backend of ``cfg`` drives, in one phrase (the start-up line)."""
    text: str = _module(cfg).describe(cfg)
    return text
