"""The carrier robots ``marsupial carrier`` drives, by the name ``carrier.backend`` gives.

Each backend is a module of this package with ``open_backend(cfg, clock, session)`` (the backend,
a :class:`~mission.carrier.controller.CarrierBackend`) and ``describe(cfg)`` (one line for the
start-up message). :data:`KINDS` is the one list: the configuration's choices, ``--backend``'s
choices and the configuration reference derive from it. Adding a backend is its module, its entry
here, and its ``[carrier.<name>]`` section in :mod:`mission.config.carrier` if it has settings.
Loading this package imports no backend (and nothing of I/O): a backend is imported when opened.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import zenoh

    from mission.carrier.controller import CarrierBackend
    from mission.config.schema import Config
    from mission.time.clock import Clock


@dataclass(frozen=True)
class BackendKind:
    """A kind of carrier robot: its name, what it is (``--help``, the configuration reference),
    whether it is a real vehicle (its response delay, ``REAL_DELAY_S``, is allowed for by the P3
    guard), and the module that drives it."""

    name: str
    summary: str
    real: bool
    module: str


KINDS: dict[str, BackendKind] = {k.name: k for k in (
    BackendKind("sim", "built-in kinematic robot", False, "mission.carrier.backends.sim"),
    BackendKind("mavlink", "PX4 rover/boat over MAVLink", True, "mission.carrier.backends.mavlink"),
    BackendKind("ros2", "ROS 2 robot over Zenoh", True, "mission.carrier.backends.ros2"),
)}


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
