"""The carrier's truth on the bus, for the simulators only: what ``marsupial carrier`` flies when
the configuration asks for the world's carrier GNSS errors (``world.carrier_gnss.enabled``).

The carrier then steers on and publishes its robot's state as an erring GNSS gives it
(:class:`sim.gnss.ErringCarrier`, seeded by ``world.carrier_gnss.seed`` as the in-process
simulation's carrier fixes are), and the robot's true state goes out on the sim-only key
:func:`truth_key` (``marsupial/<pair>/sim/carrier_truth``, a :class:`~mission.bus.wire.CarrierState`
in JSON, local NED). Only the world reads it: the mock vehicle's deck (``mock-vehicle --deck PAIR
--deck-truth``) and the demo's figures against the truth. The controller never subscribes to it
(nothing under ``mission/`` names the key: ``tests/unit/relnav/test_carrier_truth.py``).

:class:`TruthTrack` is the other side: the mock vehicle's true position and the carrier's (as its
deck knows it) over a flight, sampled on the vehicle's simulated time (``mock-vehicle --summary``'s
``track``), for the demo's figures against the truth.

``marsupial carrier`` finds :func:`wrap` through the entry point ``carrier_gnss`` of the group
``marsupial.world`` (``pyproject.toml``), so the product names no simulator module.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import zenoh

from mission.bus.encodings import encode_carrier
from mission.bus.session import congestion_for, declare, keys, undeclare
from mission.bus.wire import CarrierState
from mission.carrier.backends import CarrierBackend, OwnState
from mission.config.schema import Config
from mission.time.clock import Clock
from sim.gnss import ErringCarrier
from sim.vehicle.physics.deck import DeckMotion


def truth_key(pair: str) -> str:
    """The sim-only key of pair ``pair``'s carrier truth (``pair`` checked as :func:`keys` does)."""
    root = keys(pair).carrier_state.rsplit("/", 2)[0]
    return f"{root}/sim/carrier_truth"


class TruthPublisher:
    """Puts the carrier's true :class:`OwnState` on :func:`truth_key` (JSON, local NED; each new
    sample once). Unsigned: only the simulators read it, never the controller."""

    def __init__(self, session: zenoh.Session, pair: str, clock: Clock) -> None:
        self.key = truth_key(pair)
        self._pub = declare(f"publisher on {self.key}", lambda: session.declare_publisher(
            self.key, encoding=zenoh.Encoding.APPLICATION_JSON, congestion_control=congestion_for(clock), express=True))
        self.seq = 0
        self._last_t_s: float | None = None

    def __call__(self, truth: OwnState) -> None:
        if self._last_t_s is not None and truth.t_s <= self._last_t_s:
            return
        self._last_t_s = truth.t_s
        state = CarrierState(truth.t_s, self.seq, "local_ned", np.asarray(truth.position_ned_m, dtype=float),
                             np.asarray(truth.velocity_ned_m_s, dtype=float), truth.yaw_rad)
        self.seq += 1
        try:
            self._pub.put(encode_carrier(state, "json"))
        except zenoh.ZError:
            pass  # the session is closing; the world's truth is best effort, the flight goes on

    def close(self) -> None:
        undeclare(self._pub)


class TruthfulErringCarrier(ErringCarrier):
    """:class:`ErringCarrier` that also publishes the wrapped robot's truth (:class:`TruthPublisher`)
    each time the controller reads its own state."""

    def __init__(self, inner: CarrierBackend, cfg: Config, session: zenoh.Session, clock: Clock) -> None:
        super().__init__(inner, cfg.world.carrier_gnss)
        self.truth_publisher = TruthPublisher(session, cfg.zenoh.pair, clock)

    def own_state(self) -> OwnState | None:
        truth = self.inner.own_state()
        if truth is not None:
            self.truth_publisher(truth)
        return super().own_state()

    def close(self) -> None:
        self.truth_publisher.close()
        super().close()


def wrap(cfg: Config, backend: CarrierBackend, session: Any, clock: Clock) -> CarrierBackend:
    """``backend`` under the world's carrier GNSS errors of ``cfg`` (``world.carrier_gnss``), its
    truth published on :func:`truth_key` (the entry point ``marsupial.world:carrier_gnss``)."""
    return TruthfulErringCarrier(backend, cfg, session, clock)


class TruthTrack:
    """The truth over a flight, sampled at most every ``period_s`` [s] of the mock vehicle's
    simulated time: (t [s], the vehicle's true position [m] NED, the carrier's reference point
    [m] NED as the deck follows it: its truth with ``--deck-truth``, else its published state). :meth:`sample` runs inside the vehicle's
    physics pass (its lock held), so it reads the state directly."""

    def __init__(self, period_s: float = 0.1) -> None:
        self.period_s = period_s
        self.t_s: list[float] = []
        self.vehicle_ned_m: list[list[float]] = []
        self.carrier_ned_m: list[list[float]] = []

    def sample(self, vehicle: Any, motion: DeckMotion | None) -> None:
        """Add the state of ``vehicle`` (a :class:`sim.vehicle.mock.MockVehicle` in its physics
        pass) and the carrier of ``motion`` (None: not heard yet, nothing added), if due."""
        if motion is None:
            return
        t = float(vehicle._t_s)
        if self.t_s and t < self.t_s[-1] + self.period_s:
            return
        k = vehicle._kin
        self.t_s.append(round(t, 4))
        self.vehicle_ned_m.append([round(float(v), 4) for v in (k.n_m, k.e_m, k.d_m)])
        self.carrier_ned_m.append([round(float(v), 4) for v in motion.centre(t, 0.0)])

    def as_dict(self) -> dict[str, Any]:
        """The samples so far (the vehicle may still be adding one: only whole ones)."""
        n = min(len(self.t_s), len(self.vehicle_ned_m), len(self.carrier_ned_m))
        return {"period_s": self.period_s, "t_s": self.t_s[:n], "vehicle_ned_m": self.vehicle_ned_m[:n],
                "carrier_ned_m": self.carrier_ned_m[:n]}


def demo_truth(cfg: Config, log_dir: Path) -> dict[str, Any]:
    """A demo pair's figures against the world's truth, from the mock vehicle's ``track``
    (``vehicle.json``) and the mission's record (its phases and legs, on the same lockstep clock):
    per leg (``legs``, in order) the true contact error, horizontal and vertical [m] (the vehicle
    less the carrier's true dock point, ``mission.dock_offset_ned_m`` from its reference point;
    vertical negative: above it) at the contact's time, and the true riding offset, horizontal
    median and max [m], over that leg's RIDING ticks. {} without a track or a record."""
    path = log_dir / "vehicle.json"
    track = json.loads(path.read_text()).get("track") if path.exists() else None
    if not track or len(track["t_s"]) < 2 or not (log_dir / "record.csv").exists():
        return {}
    from mission.record.table import read_record

    n = min(len(track["t_s"]), len(track["vehicle_ned_m"]), len(track["carrier_ned_m"]))
    t = np.asarray(track["t_s"][:n], float)
    off = np.asarray(track["vehicle_ned_m"][:n], float) - np.asarray(track["carrier_ned_m"][:n], float) \
        - np.asarray(cfg.mission.dock_offset_ned_m, float)

    def at(times: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(times, t, off[:, a]) for a in range(3)], axis=1)

    rec = read_record(log_dir)
    summary = json.loads((log_dir / "summary.json").read_text()) if (log_dir / "summary.json").exists() else {}
    riding = np.flatnonzero(rec.phase == "RIDING")
    runs = np.split(riding, np.flatnonzero(np.diff(riding) > 1) + 1) if riding.size else []
    legs = []
    for i, leg in enumerate(summary.get("legs") or [summary]):
        row: dict[str, Any] = {}
        contact = leg.get("contact")
        if contact and "time_s" in contact:
            o = at(np.array([contact["time_s"]]))[0]
            row.update(true_contact_horizontal_m=round(float(np.hypot(o[0], o[1])), 4),
                       true_contact_vertical_m=round(float(o[2]), 4))
        if i < len(runs):
            h = np.hypot(*at(rec.t[runs[i]])[:, :2].T)
            row.update(true_riding_horizontal_median_m=round(float(np.median(h)), 4),
                       true_riding_horizontal_max_m=round(float(np.max(h)), 4))
        legs.append(row)
    return {"truth_legs": legs, "truth_carrier": "published state" if not cfg.world.carrier_gnss.enabled else "truth"}
