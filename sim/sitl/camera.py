"""The passenger's downward camera on PX4 SITL (``marsupial sitl-camera CONFIG`` or
``python -m sim.sitl.camera CONFIG``): frames rendered from SIH's truth of the passenger and of the
carrier, published on the pair's camera key for the controller's marker feed, which runs the
detector on the pixels as it does on the mock vehicle's frames (:mod:`mission.cli.marker`).

- **Truth.** Every PX4 SITL's GCS link sends to 127.0.0.1:14550; the node binds that port (so it
  runs in the PX4s' network namespace, and no other GCS client may hold the port) and asks each
  PX4 (``--vehicle-sysid``, ``--carrier-sysid``: instance ``sysid - 1``, its GCS link listening on
  18570 + instance) for HIL_STATE_QUATERNION, SIH's ground truth (true latitude, longitude,
  altitude, attitude body -> NED and NED velocity), at ``--truth-hz``, as
  :func:`sim.sitl.ground_truth.ask` does. The carrier is the SIH rover: its own truth.
- **Frames.** At every passenger truth received, the carrier's newest truth is moved on by its
  velocity to that receive time, both projected about the passenger's position
  (:func:`sim.camera.render.poses_from_ground_truth`: the camera needs only the relative vector),
  and :class:`sim.camera.publisher.CameraPublisher` (the mock's publisher: the same renderer,
  sensor, grid and wire) captures when a slot of ``vision.rate_hz`` is due, with the passenger's
  true attitude. A carrier truth older than :data:`CARRIER_MAX_AGE_S` is no deck (a time mark).
- **Time.** A frame's capture time is on the mission's clock (the wire's ``t``): the node reads the
  passenger's published status (its ``stamp`` on the mission's clock) and keeps the offset from
  its own ``CLOCK_MONOTONIC``, ``max(stamp - receive time)`` (the loopback's delay below a
  millisecond). Until the first status no frame goes out. The mission runs at speed 1 against
  PX4 (wall time), so one offset holds for the flight.
- **Truth for the bench.** ``--truth-dir DIR``: on exit (SIGTERM) each vehicle's estimate
  (LOCAL_POSITION_NED) and truth as received, ``truth-passenger.csv`` and ``truth-rover.csv``
  (:func:`sim.sitl.ground_truth.write_csv`; receive times on ``CLOCK_MONOTONIC``), both truths
  projected about the passenger's EKF origin, and ``camera.json`` (counts, the clock offset).

- **A team** (``--passenger NAME``, repeated, of a file with a ``[team]``): one camera a named
  passenger, on its own vehicle (its ``team.passengers[].system_id``) and its own key
  (:func:`mission.bus.frames.camera_key`), clocked by its own status; each frame shows every
  named passenger's slot's marker (the deck's other markers too, so its detector must keep to its
  own ids). One node renders them all: the PX4s' GCS links share one port. The truth files are
  then ``truth-NAME.csv`` per passenger and ``truth-rover.csv``, about the first one's EKF origin.

No noisy truth goes to the controller: it gets pixels.
"""
from __future__ import annotations

import json
import logging
import math
import socket
import threading
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click
import numpy as np

from mission.bus.session import close_session, declare, keys, open_session, undeclare
from mission.bus.wire import decode_passenger_json
from mission.config.passenger import has_team, passenger_config, team_link
from mission.config.schema import Config, ZenohSection, load_config
from mission.lifetime import on_stop_signals
from mission.mavlink import px4
from mission.mavlink.codec import new_codec, reset_parser
from mission.mavlink.env import mavlink
from sim.camera.publisher import BodyTruth, CameraPublisher, DeckTruth
from sim.camera.render import poses_from_ground_truth
from sim.sitl import ground_truth
from sim.sitl.px4 import GCS_LISTEN_PORT, GCS_PORT

log = logging.getLogger("sim.sitl.camera")

CARRIER_MAX_AGE_S = 0.5  # [s] a carrier truth older than this at a passenger truth: no deck
ASK_PERIOD_S = 1.0  # [s] the streams are asked again until they arrive


class Px4Truths:
    """SIH's truth (HIL_STATE_QUATERNION), the estimate (LOCAL_POSITION_NED) and the EKF origin of
    several PX4 SITLs, received on their GCS links' one port; each stamped with its receive time
    on ``time.monotonic`` [s]. :meth:`newest` the newest truth of a system; :meth:`wait_newer`
    blocks until one of several systems' is newer than its given time."""

    def __init__(self, sysids: list[int], rate_hz: float, bind: tuple[str, int] = ("127.0.0.1", GCS_PORT)) -> None:
        self.sysids, self.rate_hz = list(sysids), rate_hz
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self.sock.bind(bind)
        self.sock.settimeout(0.2)
        self.mav = new_codec(255, 191)
        self._cond = threading.Condition()
        self.truth: dict[int, list[tuple[float, Any]]] = defaultdict(list)
        self.estimate: dict[int, list[tuple[float, Any]]] = defaultdict(list)
        self.origin: dict[int, Any] = {}
        self.received = 0
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._receive, name="sitl-camera-rx", daemon=True),
                         threading.Thread(target=self._ask, name="sitl-camera-ask", daemon=True)]
        for t in self._threads:
            t.start()

    def _send(self, sysid: int, msg: Any) -> None:
        try:
            self.sock.sendto(msg.pack(self.mav), ("127.0.0.1", GCS_LISTEN_PORT + sysid - 1))
        except OSError:
            pass

    def _ask(self) -> None:
        """A GCS heartbeat to each PX4 every period, and the streams asked until each has arrived."""
        while not self._stop.is_set():
            for sysid in self.sysids:
                self._send(sysid, mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID,
                                                                     0, 0, 0, 3))
                with self._cond:
                    has_truth, has_est, has_origin = bool(self.truth[sysid]), bool(self.estimate[sysid]), sysid in self.origin
                for msg_id, has in ((ground_truth.HIL_STATE_QUATERNION_ID, has_truth),
                                    (ground_truth.LOCAL_POSITION_NED_ID, has_est)):
                    if not has:
                        self._send(sysid, mavlink.MAVLink_command_long_message(
                            sysid, 1, px4.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, 1e6 / self.rate_hz, 0, 0, 0, 0, 0))
                if not has_origin:
                    self._send(sysid, mavlink.MAVLink_command_long_message(
                        sysid, 1, px4.MAV_CMD_REQUEST_MESSAGE, 0, ground_truth.GPS_GLOBAL_ORIGIN_ID, 0, 0, 0, 0, 0, 0))
            self._stop.wait(ASK_PERIOD_S)

    def _receive(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.sock.recv(65535)
            except socket.timeout:
                continue
            except OSError:
                return
            t = time.monotonic()
            try:
                msgs = self.mav.parse_buffer(data) or []
            except Exception:  # a bad datagram: dropped
                msgs = []
            reset_parser(self.mav)
            with self._cond:
                for m in msgs:
                    name, src = m.get_type(), m.get_srcSystem()
                    if src not in self.sysids:
                        continue
                    self.received += 1
                    if name == "HIL_STATE_QUATERNION":
                        self.truth[src].append((t, m))
                    elif name == "LOCAL_POSITION_NED":
                        self.estimate[src].append((t, m))
                    elif name == "GPS_GLOBAL_ORIGIN":
                        self.origin[src] = m
                self._cond.notify_all()

    def newest(self, sysid: int) -> tuple[float, Any] | None:
        with self._cond:
            got = self.truth.get(sysid)
            return got[-1] if got else None

    def wait_newer(self, after_s: dict[int, float], timeout_s: float) -> dict[int, tuple[float, Any]]:
        """The newest truth of each system of ``after_s`` received after its time [s, monotonic],
        waiting at most ``timeout_s`` [s] for one of them; empty if none came."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while True:
                got = {sysid: self.truth[sysid][-1] for sysid, t in after_s.items()
                       if self.truth.get(sysid) and self.truth[sysid][-1][0] > t}
                left = deadline - time.monotonic()
                if got or left <= 0 or self._stop.is_set():
                    return got
                self._cond.wait(left)

    def write_csv(self, directory: Path, names: dict[str, int], origin_sysid: int) -> None:
        """``truth-NAME.csv`` of each ``names`` entry (module docstring), projected about
        ``origin_sysid``'s EKF origin (none heard: about latitude 0, longitude 0, altitude 0)."""
        with self._cond:
            o = self.origin.get(origin_sysid)
            copies = {n: (list(self.estimate[s]), list(self.truth[s])) for n, s in names.items()}
        origin = (0.0, 0.0, 0.0) if o is None else (o.latitude * 1e-7, o.longitude * 1e-7, o.altitude * 1e-3)
        for name, (est, truth) in copies.items():
            e, tr = ground_truth.rows(est, truth, origin)
            ground_truth.write_csv(directory / f"truth-{name}.csv", e, tr)

    def close(self) -> None:
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        for t in self._threads:
            t.join(timeout=2.0)
        self.sock.close()


class MissionClock:
    """The mission's clock from the passenger's published status (module docstring): :meth:`at`
    maps a ``time.monotonic`` time to it, None until a status was heard."""

    def __init__(self, session: Any, pair: str, passenger: str | None = None) -> None:
        self.offset_s: float | None = None
        self.heard = 0
        self._lock = threading.Lock()
        key = keys(pair, passenger).passenger_state  # a team passenger's: its own status
        self._sub = declare(f"subscriber on {key}", lambda: session.declare_subscriber(key, self._on_sample))

    def _on_sample(self, sample: Any) -> None:
        t = time.monotonic()
        try:
            stamp = float(decode_passenger_json(sample.payload.to_bytes()).stamp_s)
        except Exception:  # not a status: ignored (the controller checks its own wire)
            return
        with self._lock:
            self.heard += 1
            self.offset_s = stamp - t if self.offset_s is None else max(self.offset_s, stamp - t)

    def at(self, t_monotonic_s: float) -> float | None:
        with self._lock:
            return None if self.offset_s is None else t_monotonic_s + self.offset_s

    def close(self) -> None:
        undeclare(self._sub)


def deck_truth(vehicle: tuple[float, Any], carrier: tuple[float, Any] | None) -> tuple[BodyTruth, DeckTruth | None]:
    """The passenger's and the carrier's true state at the passenger truth's receive time, about
    the passenger's position (the carrier's moved on by its velocity over the receive times'
    difference; None when older than :data:`CARRIER_MAX_AGE_S`)."""
    t_v, v = vehicle
    body = BodyTruth(np.zeros(3), np.asarray(v.attitude_quaternion, float), np.array([v.vx, v.vy, v.vz]) * 0.01)
    if carrier is None or abs(t_v - carrier[0]) > CARRIER_MAX_AGE_S:
        return body, None
    t_c, c = carrier
    poses = poses_from_ground_truth(v, c)
    velocity = np.array([c.vx, c.vy, c.vz]) * 0.01
    return body, DeckTruth(poses.deck_ned_m + velocity * (t_v - t_c), velocity, poses.deck_yaw_rad)


@dataclass
class Eye:
    """One passenger's camera: its truth file's ``name``, its vehicle's ``sysid``, its configuration
    ``cfg`` (its marker), its team name ``passenger`` (None: the pair's keys) and the configurations
    of the deck's other markers' passengers ``others``."""

    name: str
    sysid: int
    cfg: Config
    passenger: str | None = None
    others: tuple[Config, ...] = ()


def team_eyes(cfg: Config, names: list[str]) -> list[Eye]:
    """The cameras of ``cfg``'s team passengers ``names`` (module docstring): each on its own
    vehicle and keys, its frames showing every other passenger's slot's marker too."""
    every = [p.name for p in cfg.team.passengers]
    own = {n: passenger_config(cfg, n) for n in every}
    return [Eye(n, int(own[n].mavlink.target_system or 0), own[n], n if team_link(cfg, n) is not None else None,
                tuple(own[o] for o in every if o != n)) for n in names]


def run_camera(eyes: list[Eye], zenoh: ZenohSection, carrier_sysid: int, seed: int, truth_hz: float,
               truth_dir: Path | None, stop: threading.Event) -> dict[str, Any]:
    """Render and publish every camera of ``eyes`` until ``stop`` is set; the counts (``camera.json``;
    a team's: per passenger)."""
    truths = Px4Truths([*[e.sysid for e in eyes], carrier_sysid], truth_hz)
    session = open_session(zenoh)
    publishers: list[CameraPublisher] = []
    clocks: list[MissionClock] = []
    counts = [{"truths_unstamped": 0, "no_deck": 0} for _ in eyes]
    try:
        for k, e in enumerate(eyes):
            publishers.append(CameraPublisher(e.cfg, session, e.cfg.zenoh.pair, seed + 101 * k, lockstep=False,
                                              passenger=e.passenger, others=e.others))
            clocks.append(MissionClock(session, e.cfg.zenoh.pair, e.passenger))
        last = {e.sysid: -math.inf for e in eyes}
        while not stop.is_set():
            got = truths.wait_newer(last, 0.5)
            for e, publisher, mission_clock, n in zip(eyes, publishers, clocks, counts):
                if e.sysid not in got:
                    continue
                last[e.sysid] = got[e.sysid][0]
                t_mission = mission_clock.at(got[e.sysid][0])
                if t_mission is None:
                    n["truths_unstamped"] += 1
                    continue
                body, deck = deck_truth(got[e.sysid], truths.newest(carrier_sysid))
                n["no_deck"] += deck is None
                publisher.sample(t_mission, body, deck)
        each = {e.name: {"captured": p.captured, "frames_sent": p.sent, **n, "statuses_heard": c.heard,
                         "mission_minus_monotonic_s": c.offset_s} for e, p, c, n in zip(eyes, publishers, clocks, counts)}
        out: dict[str, Any] = {"mavlink_received": truths.received}
        return {**out, **each[eyes[0].name]} if len(eyes) == 1 and eyes[0].passenger is None else {**out, "cameras": each}
    finally:
        for c in clocks:
            c.close()
        for p in publishers:
            p.close()
        close_session(session)
        truths.close()
        if truth_dir is not None:
            truth_dir.mkdir(parents=True, exist_ok=True)
            truths.write_csv(truth_dir, {**{e.name: e.sysid for e in eyes}, "rover": carrier_sysid}, eyes[0].sysid)


@click.command("sitl-camera", context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("config", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--vehicle-sysid", type=click.IntRange(1, 255), default=1, show_default=True,
              help="The passenger's PX4 (instance sysid - 1).")
@click.option("--carrier-sysid", type=click.IntRange(1, 255), default=None,
              help="The carrier's PX4, the SIH rover (instance sysid - 1) [default: carrier.mavlink.target_system, else 2].")
@click.option("--passenger", "passengers", multiple=True, metavar="NAME",
              help="A team passenger whose camera to render (repeat for each; its own system id and keys): "
                   "the file's [team] (module docstring). Not with --vehicle-sysid.")
@click.option("--seed", type=int, default=0, show_default=True, help="The sensor's noise and dropouts.")
@click.option("--truth-hz", type=click.FloatRange(1.0, 250.0), default=50.0, show_default=True,
              help="HIL_STATE_QUATERNION and LOCAL_POSITION_NED asked of each PX4 [Hz].")
@click.option("--truth-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="On exit write truth-passenger.csv, truth-rover.csv and camera.json here.")
@click.option("--zenoh-connect", "connect", multiple=True, metavar="ENDPOINT")
@click.option("--zenoh-listen", "listen", multiple=True, metavar="ENDPOINT")
def sitl_camera(config: Path, vehicle_sysid: int, carrier_sysid: int | None, passengers: tuple[str, ...], seed: int,
                truth_hz: float, truth_dir: Path | None, connect: tuple[str, ...], listen: tuple[str, ...]) -> None:
    """Render the passenger's downward camera from PX4 SITL's SIH truth and publish its frames (module docstring)."""
    cfg = load_config(config)
    endpoints: dict[str, Any] = {"connect": list(connect), "listen": list(listen)}
    if connect or listen:
        endpoints["rendezvous"] = None  # not the other processes' loopback rendezvous
    zenoh = ZenohSection(**endpoints)
    stop = threading.Event()
    if passengers and not has_team(cfg):
        raise click.BadParameter("the file has no [team]", param_hint="--passenger")
    eyes = team_eyes(cfg, list(passengers)) if passengers else [Eye("passenger", vehicle_sysid, cfg)]
    if carrier_sysid is None:
        carrier_sysid = cfg.carrier.mavlink.target_system or 2
    with on_stop_signals(lambda _signum: stop.set()):
        counts = run_camera(eyes, zenoh, carrier_sysid, seed, truth_hz, truth_dir, stop)
    log.info("camera: %s", counts)
    if truth_dir is not None:
        (truth_dir / "camera.json").write_text(json.dumps(counts, indent=1) + "\n")


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    sitl_camera()
