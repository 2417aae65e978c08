"""The carrier robot simulator (``marsupial carrier``): a planar robot that runs the paper's
carrier law and publishes its state over Zenoh.

Every period ``1 / carrier.rate_hz`` [s] of the injected clock (so ``--speed`` scales it like the
mock vehicle) the simulator advances its position by the command held over the last period,
reads the passenger's newest status, decides its command with :func:`mission.tick.carrier_tick`
(paper eq. 4 with the CBF filter and the speed/acceleration limits) and publishes a
:class:`~mission.wire.CarrierState` in local NED (yaw = heading of travel).

Mode of the carrier (transitions evaluated at each step, from the passenger's published phase,
its age on the local clock and its liveliness token)::

    WAITING     --phase RIDING, fresh------------------------> APPROACHING
    APPROACHING --status older than passenger_timeout_s,
                  or passenger token gone--------------------> PAUSED     (stop; a safe reaction)
    PAUSED      --phase RIDING, fresh, token not gone--------> APPROACHING
    any but SEPARATED --phase SEPARATED or later (or the
                  status says separated)---------------------> SEPARATED  (latched)
    WAITING/APPROACHING/PAUSED --phase ABORT-----------------> STOPPED    (latched)

- WAITING (before the passenger has joined: phases PREFLIGHT..JOIN, or no status yet): stationary.
- APPROACHING: ``u_c = k_c e_tc`` (planar), filtered.
- PAUSED / STOPPED: command zero (through the filter, so an acceleration limit still applies).
- SEPARATED: ``scenario.carrier_mode = "stop"``: zero; ``"remark1"``: the velocity commanded at
  the instant of separation (the carrier's own plan), still filtered (obstacles, target keep-out).
  Passenger silence no longer matters once separated: the passenger has left.
"""
from __future__ import annotations

import dataclasses
import enum
import logging
import math
import signal
import threading
from types import FrameType
from typing import Any

import click
import numpy as np
import zenoh

from mission.carrier_bridge import CarrierPublisher, PassengerFeed, describe_endpoints, keys, open_session
from mission.clock import Clock, Periodic, ScaledClock
from mission.config import Config, load_config, with_overrides
from mission.tick import TickModel, carrier_tick
from mission.wire import CarrierState
from sim.closed_loop import model_from_config

log = logging.getLogger(__name__)

#: Phases during which the passenger is on (or joining) the carrier before it rides.
BEFORE_RIDING = frozenset({"PREFLIGHT", "STREAMING", "ARMING", "OFFBOARD", "JOIN"})
#: Phases after the separation event.
AFTER_SEPARATION = frozenset({"SEPARATED", "NAVIGATING", "ARRIVED", "HOLD", "LAND", "DONE"})


class CarrierMode(enum.Enum):
    """What the simulated carrier is doing (see the module docstring for transitions)."""

    WAITING = "waiting"
    APPROACHING = "approaching"
    PAUSED = "paused"
    SEPARATED = "separated"
    STOPPED = "stopped"


def carrier_model(cfg: Config) -> TickModel:
    """The tick model of the carrier: the config's, with the carrier's speed limit
    ``min(carrier.max_speed_m_s, safety.carrier_max_speed_m_s)`` [m/s]."""
    model = model_from_config(cfg)
    limit = cfg.carrier.max_speed_m_s
    if model.carrier_safety.max_speed_m_s is not None:
        limit = min(limit, model.carrier_safety.max_speed_m_s)
    return dataclasses.replace(model, carrier_safety=dataclasses.replace(model.carrier_safety, max_speed_m_s=limit))


def _pad3(v: np.ndarray) -> np.ndarray:
    """A (2,) or (3,) vector as (3,) (a 2D scenario's carrier sits at down = 0)."""
    return np.concatenate([v, np.zeros(3 - v.shape[0])]) if v.shape[0] < 3 else v


class CarrierSim:
    """Simulated carrier of the pair ``cfg.zenoh.pair`` on an open Zenoh ``session``.

    ``clock``: the injected clock (ScaledClock for ``--speed``, ManualClock in tests). ``pair``
    and ``encoding`` default to ``cfg.zenoh``. The caller owns the session; :meth:`close` (or
    leaving the ``with`` block) undeclares what the simulator declared on it. The state goes to
    ``cfg.zenoh.carrier_key`` if set (e.g. a ROS 2 odom key with encoding "cdr").
    """

    def __init__(
        self,
        cfg: Config,
        clock: Clock,
        session: zenoh.Session,
        *,
        pair: str | None = None,
        encoding: str | None = None,
    ) -> None:
        self.cfg, self.clock = cfg, clock
        self.pair = pair or cfg.zenoh.pair
        self.model = carrier_model(cfg)
        self.period_s = 1.0 / cfg.carrier.rate_hz
        self.position_m = np.array(cfg.scenario.carrier_start, dtype=float)  # [m] local NED (or 2D)
        self.velocity_m_s = np.zeros_like(self.position_m)  # [m/s] command held over the period
        self.mode = CarrierMode.WAITING
        self.seq = 0
        self._plan_velocity = np.zeros_like(self.position_m)
        e_tc = self.model.target - self.position_m
        self._yaw_rad = math.atan2(e_tc[1], e_tc[0])
        self.passenger = PassengerFeed(session, self.pair, clock, max_age_s=cfg.carrier.passenger_timeout_s)
        try:
            self.publisher = CarrierPublisher(session, self.pair, encoding or cfg.zenoh.encoding,  # type: ignore[arg-type]
                                              key=cfg.zenoh.carrier_key)
        except Exception:
            self.passenger.close()
            raise

    # ------------------------------------------------------------------ decisions
    def _passenger_lost(self) -> str | None:
        """Why the passenger counts as lost (None if it does not)."""
        if self.passenger.alive is False:
            return "its liveliness token is gone"
        rx = self.passenger.latest()
        if rx is None:
            return "no status received"
        if rx.stale:
            return f"its status is {rx.age_s:.2f} s old (> {self.passenger.max_age_s} s)"
        return None

    def _set_mode(self, mode: CarrierMode, why: str) -> None:
        if mode is self.mode:
            return
        level = logging.WARNING if mode in (CarrierMode.PAUSED, CarrierMode.STOPPED) else logging.INFO
        log.log(level, "carrier %s: %s -> %s (%s) at %s", self.pair, self.mode.value, mode.value, why,
                np.round(self.position_m, 3).tolist())
        if mode is CarrierMode.SEPARATED:
            self._plan_velocity = self.velocity_m_s.copy() if self.mode is CarrierMode.APPROACHING else np.zeros_like(self.velocity_m_s)
        self.mode = mode

    def _update_mode(self) -> None:
        if self.mode in (CarrierMode.SEPARATED, CarrierMode.STOPPED):
            return
        rx = self.passenger.latest()
        if rx is not None and (rx.status.phase in AFTER_SEPARATION or rx.status.separated):
            self._set_mode(CarrierMode.SEPARATED, f"passenger phase {rx.status.phase}")
            return
        if rx is not None and rx.status.phase == "ABORT":
            self._set_mode(CarrierMode.STOPPED, "passenger aborted")
            return
        lost = self._passenger_lost()
        riding = rx is not None and rx.status.phase == "RIDING"
        if self.mode is CarrierMode.APPROACHING and lost:
            self._set_mode(CarrierMode.PAUSED, f"passenger lost: {lost}")
        elif self.mode in (CarrierMode.WAITING, CarrierMode.PAUSED) and riding and not lost:
            self._set_mode(CarrierMode.APPROACHING, "passenger riding")

    def _command(self, dt_s: float) -> np.ndarray:
        # Separated with no own plan gives a zero command in both carrier modes; the filter
        # still runs (an acceleration limit brakes instead of stopping dead).
        separated = self.mode is not CarrierMode.APPROACHING
        plan = self._plan_velocity if self.mode is CarrierMode.SEPARATED else None
        res = carrier_tick(self.position_m, separated, self.model, own_plan_velocity=plan,
                           u_prev=self.velocity_m_s, dt_s=dt_s if dt_s > 0 else None)
        if not bool(np.all(res.feasible)):
            log.warning("carrier %s: CBF filter infeasible at %s; holding still", self.pair, self.position_m.tolist())
        return np.asarray(res.u, dtype=float)

    # ------------------------------------------------------------------ stepping
    def step(self, dt_s: float) -> CarrierState:
        """Advance ``dt_s`` [s] under the held command, decide the next command, publish and
        return the state published (position after the step, new command as velocity)."""
        if dt_s < 0:
            raise ValueError(f"dt_s must be >= 0, got {dt_s!r}")
        self.position_m = self.position_m + self.velocity_m_s * dt_s
        self._update_mode()
        self.velocity_m_s = self._command(dt_s)
        speed_xy = math.hypot(self.velocity_m_s[0], self.velocity_m_s[1])
        if speed_xy > 1e-6:
            self._yaw_rad = math.atan2(self.velocity_m_s[1], self.velocity_m_s[0])
        state = CarrierState(self.clock.now(), self.seq, "local_ned", _pad3(self.position_m),
                             _pad3(self.velocity_m_s), self._yaw_rad)
        self.publisher.publish(state)
        self.seq += 1
        return state

    def run(self, stop_event: threading.Event, duration_s: float | None = None) -> None:
        """Step at ``carrier.rate_hz`` on the clock until ``stop_event`` is set or ``duration_s``
        [s] of clock time has passed. Publishes the initial state at once."""
        t0 = last = self.clock.now()
        periodic = Periodic(self.clock, self.period_s)
        self.step(0.0)
        log.info("carrier %s publishing on %s at %.1f Hz (clock speed %g)", self.pair, self.publisher.key,
                 self.cfg.carrier.rate_hz, self.clock.speed)
        while not stop_event.is_set():
            tick = periodic.wait()
            if duration_s is not None and tick - t0 >= duration_s:
                break
            self.step(tick - last)
            last = tick
        if periodic.overruns:
            log.warning("carrier %s: %d overruns of the %.1f ms period", self.pair, periodic.overruns, 1e3 * self.period_s)

    def close(self) -> None:
        """Undeclare the publisher, the liveliness token and the passenger subscribers."""
        self.publisher.close()
        self.passenger.close()

    def __enter__(self) -> "CarrierSim":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def main(cfg: Config, speed: float = 1.0, duration_s: float | None = None, stop_event: threading.Event | None = None) -> int:
    """Open the session of ``cfg.zenoh``, run the simulator until stopped; returns exit code 0.

    SIGINT/SIGTERM set the stop event when called from the main thread. Raises
    :class:`~mission.errors.BusError` if Zenoh cannot open.
    """
    stop = stop_event or threading.Event()
    restore: dict[int, Any] = {}
    if threading.current_thread() is threading.main_thread():
        def _stop(signum: int, _frame: FrameType | None) -> None:
            log.info("carrier: %s, stopping", signal.Signals(signum).name)
            stop.set()

        for sig in (signal.SIGINT, signal.SIGTERM):
            restore[sig] = signal.signal(sig, _stop)
    try:
        clock = ScaledClock(speed)
        with open_session(cfg.zenoh) as session:
            with CarrierSim(cfg, clock, session) as sim:
                sim.run(stop, duration_s)
                log.info("carrier %s stopped in mode %s at %s", sim.pair, sim.mode.value,
                         np.round(sim.position_m, 3).tolist())
    finally:
        for sig, handler in restore.items():
            signal.signal(sig, handler)
    return 0


@click.command("carrier", context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--speed", type=click.FloatRange(min=0, min_open=True), default=1.0, show_default=True,
              help="Clock speed factor (like PX4's SIH speed factor); use the mock vehicle's.")
@click.option("--pair", default=None, help="Pair name: keys marsupial/<pair>/... [default: zenoh.pair]")
@click.option("--zenoh-listen", "listen", multiple=True, metavar="ENDPOINT",
              help="Zenoh listen endpoint, e.g. tcp/127.0.0.1:7448 (repeatable; replaces zenoh.listen).")
@click.option("--zenoh-connect", "connect", multiple=True, metavar="ENDPOINT",
              help="Zenoh endpoint to connect to (repeatable; replaces zenoh.connect).")
@click.option("--encoding", type=click.Choice(["json", "cdr"]), default=None,
              help="Carrier state encoding: JSON or ROS 2 nav_msgs/Odometry CDR [default: zenoh.encoding].")
@click.option("--rate", type=click.FloatRange(min=0, min_open=True, max=1000), default=None, metavar="HZ",
              help="Publish/integration rate in simulated Hz [default: carrier.rate_hz, 30].")
@click.option("--duration", type=click.FloatRange(min=0, min_open=True), default=None, metavar="S",
              help="Stop after this many simulated seconds [default: run until SIGINT/SIGTERM].")
def carrier_command(config: str, speed: float, pair: str | None, listen: tuple[str, ...], connect: tuple[str, ...],
                    encoding: str | None, rate: float | None, duration: float | None) -> int:
    """Run the carrier robot simulator of CONFIG (a TOML file).

    The carrier starts at scenario.carrier_start, waits until the passenger's published phase
    is RIDING, then drives towards scenario.target with the paper's law u_c = k_c e_tc (planar,
    CBF obstacle filter, carrier.max_speed_m_s), and stops when the phase says SEPARATED or later
    (scenario.carrier_mode = "remark1": keeps its velocity of that instant). If the passenger
    goes silent or its liveliness token disappears while the carrier approaches, it stops.

    It publishes its state (local NED) on marsupial/<pair>/carrier/state at --rate and holds
    the token marsupial/<pair>/carrier/alive. Exit 0 on SIGINT/SIGTERM or after --duration;
    2 on a configuration error; 4 if Zenoh cannot start.
    """
    cfg = load_config(config)
    cfg = with_overrides(cfg, {
        "zenoh.pair": pair,
        "zenoh.listen": list(listen) if listen else None,
        "zenoh.connect": list(connect) if connect else None,
        "zenoh.encoding": encoding,
        "carrier.rate_hz": rate,
    })
    click.echo(startup_line(cfg, speed), err=True)
    return main(cfg, speed, duration)


def startup_line(cfg: Config, speed: float) -> str:
    """What ``marsupial carrier`` says at start-up: pair, endpoint, mode, what it waits for."""
    k = keys(cfg.zenoh.pair)
    plan = {"stop": "stops at separation", "remark1": "keeps its own plan after separation (Remark 1)"}
    start = np.round(np.asarray(cfg.scenario.carrier_start, dtype=float), 2).tolist()
    return (f"carrier {cfg.zenoh.pair}: publishing {k.carrier_state} ({cfg.zenoh.encoding}, {cfg.carrier.rate_hz:g} Hz) "
            f"on {describe_endpoints(cfg.zenoh)}; mode {cfg.scenario.carrier_mode} ({plan[cfg.scenario.carrier_mode]}); "
            f"at {start} NED [m], waiting for the passenger to ride (phase RIDING on {k.passenger_phase}); "
            f"clock x{speed:g}")
