"""Fly the team on real PX4 SITL: two SIH quadrotor passengers and the SIH rover carrier (docs/team.md, "On real PX4").

One flight per call of :func:`fly_team`: three fresh PX4s in one network namespace of their own
(:mod:`sim.sitl.px4`), each passenger's on the instance its system id names (instance
``system_id - 1``: its offboard link on 14540 + instance, its GCS link on 18570 + instance) and the
rover on ``carrier.mavlink.target_system - 1`` (its speed loop closed, :data:`sim.sitl.px4.ROVER_PARAMS`);
then ``marsupial carrier FILE`` (the ``mavlink`` backend: the rover) and one ``marsupial run FILE
--passenger NAME --mavlink udpin:127.0.0.1:<14540 + instance>`` per passenger, all in the namespace.
Each quadrotor gets a 10-minute battery (``SIM_BAT_DRAIN`` 600 s, as ``bench.px4_flights --rover``).

While it flies it prints every phase change of every passenger and the carrier's hand-overs.
Afterwards, per passenger leg (``bench.px4_flights.dockings`` on its summary): docked or not,
approaches, the contact error by the estimates and in truth, P1-P3, the relative command jump at
separation, the carrier's closest approach to the leg's target; per flight: the pairwise minimum
TRUE distance between the passengers against what the barrier keeps, the carrier's closest
approach to each target (its own ``closest_each_target_m``), each PX4's clock against wall time,
the longest stall, the machine's load.

Truth: SIH's ground truth (HIL_STATE_QUATERNION) of every PX4, asked on the GCS links
(:func:`sim.sitl.ground_truth.ask`) and received on one socket, so on one clock (the bench's
``time.monotonic``), every vehicle's projected about alpha's EKF origin (one frame; all three SIHs
start at one home). A passenger's phases come from its ``record.csv`` (mission clock), put on the
same clock through its flight log's epoch (``flight.mcap``'s ``clock`` metadata: Unix time at the
mission clock's zero) and the bench's Unix-minus-monotonic offset; ``map_check_m`` is the median
distance between the passenger's estimate as its record has it and as the GCS link had it at the
mapped time (a wrong mapping shows as metres).

*True contact error*: at the contact's time, the passenger's true horizontal position against the
rover's true position plus its slot's offset. The rover's timing is checked as the passengers'
are: the positions the carrier published (``carrier.mcap``, stamped on its own receipt of the
rover's estimate on the offboard link, with its alignment shift) match the rover's estimate on the
GCS link best shifted by ``rover_gcs_delay_s`` (:func:`gcs_delay_s`: -0.02 s in each of nine
flights); ``true_error_shifted_m`` is the figure with the rover's truth moved by that shift. The
passengers' timing is checked (``map_check_m``); ``estimates_apart_m`` is how far the two PX4s'
estimate errors alone (each estimate minus its truth; the rover's with the carrier's alignment
shift onto alpha at the start, :func:`carrier_alignment_m`) put the pair apart then: the mission docks on
estimates, and GPS-based EKFs err by decimetres. *Pairwise*: while both passengers fly (``FLYING``)
and neither is in JOIN (the three SIHs start at one home, so both quadrotors take off from one
point; on a real deck each stands on its slot), the least true distance, and the shortfall against what the barrier keeps (docs/team.md, "The
recovery queue"): ``team.passenger_span_m`` while either is seated on its slot
(``mission.phases.queue.SEATED``), otherwise ``safety.passenger_separation_m``, or the largest
distance the pair has had since both left their slots if they have not yet been that far apart
(bench/pairwise_mc.py's rule); a violation is a shortfall over 0.01 m.

*With a camera* (``--camera``, ``configs/px4_sitl_team_relnav.toml``: relative navigation, each
slot its own marker, the carrier's published state carrying the world's GNSS errors drawn by
``--seed``): one camera node renders every passenger's downward camera from SIH's truth
(``python -m sim.sitl.camera FILE --passenger NAME ...``, :mod:`sim.sitl.camera`) and records the
truth of every vehicle (``truth-NAME.csv``) in place of the bench's GCS probe (the PX4s' GCS links
share one port). The missions are stopped :data:`HOME_S` after the last passenger entered HOME
if they have not ended by then (bench/px4_relnav.py says how HOME ends on a noisy carrier
velocity); until then the others ride their slots. The rover's timing check
(``rover_gcs_delay_s``) is skipped: its published positions carry the world's GNSS errors (late
fixes, metres of bias). The carrier's true closest approach to each target (3D, as its own
``closest_each_target_m``, which is in its biased frame) comes from the rover's truth.

Usage (root, ``MARSUPIAL_PX4_SITL``; about 2 min of wall time a flight, 90 s of it flying; one flight per call so
that another user of the PX4 lock can fly between):
``flock /work/wt/px4.lock nice -n 15 python -m bench.px4_team --out DIR [--config configs/px4_sitl_team.toml]``;
with a camera: ``... python -m bench.px4_team --camera --seed N --out DIR`` (its config ``configs/px4_sitl_team_relnav.toml``).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import click
import numpy as np

from bench.px4_flights import CLOCK_OK, ROVER_BATTERY, STALL_S, dockings, stall_s
from mission.config.passenger import passenger_config
from mission.config.schema import Config, load_config
from mission.flightdata.read import read_messages
from mission.phases.phase import FLYING, Phase
from mission.phases.queue import SEATED
from mission.record.table import read_record
from sim.net import stop_process, wait_for
from sim.sitl import ground_truth
from sim.sitl.px4 import (GCS_LISTEN_PORT, QUAD_AIRFRAME, ROVER_AIRFRAME, ROVER_PARAMS, NetNamespace, Px4Sitl, build_dir,
                          clock_ratio, clock_ratio_of, gcs_probe, patched_config, unavailable_reason)

ROOT = Path(__file__).resolve().parents[1]
STATUS_TOPIC = "/pair0/carrier/status"  # the carrier's own log of each state it published (carrier.mcap)
HOME_S = 30.0  # [s] of HOME after a relnav flight's last dock, then the bench stops the mission (bench/px4_relnav.py)
TRUTH_HZ = 20.0  # [Hz] each PX4's truth and estimate on the GCS link (three PX4s: 120 messages a second)
OFFBOARD_PORT = 14540  # + instance: where PX4 SITL sends its offboard link
VIOLATION_M = 0.01  # [m] a shortfall over this is a violation (bench/pairwise_mc.py)
FLYING_NAMES = frozenset(p.value for p in FLYING)
# Left out of the pairwise figures: the three SIHs start at one home (SIH has no collisions), so
# both quadrotors take off from one point and JOIN their slots 1.8 m apart; on a real deck each
# stands on its own slot.
JOIN = Phase.JOIN.value


def instance_of(system_id: int) -> int:
    """PX4 SITL instance ``i`` has MAVLink system id ``i + 1``."""
    return system_id - 1


def _popen(ns: NetNamespace, directory: Path, name: str, args: list[str], stack: ExitStack,
           module: str = "mission.cli") -> subprocess.Popen[bytes]:
    out, err = open(directory / f"{name}.out", "ab"), open(directory / f"{name}.err", "ab")
    stack.callback(err.close)
    stack.callback(out.close)
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    proc = subprocess.Popen(ns.command([sys.executable, "-m", module, *args]), stdout=out, stderr=err, env=env,
                            cwd=ROOT, stdin=subprocess.DEVNULL)
    stack.callback(stop_process, proc)
    return proc


class Progress:
    """Prints every new phase line of each passenger's output and the carrier's hand-overs."""

    def __init__(self, directory: Path, names: list[str], t0: float) -> None:
        self.files = {n: directory / f"{n}.out" for n in names} | {"carrier": directory / "carrier.err"}
        self.pos = dict.fromkeys(self.files, 0)
        self.t0 = t0

    def poll(self) -> None:
        for name, path in self.files.items():
            if not path.exists():
                continue
            with open(path, "rb") as f:
                f.seek(self.pos[name])
                data = f.read()
            end = data.rfind(b"\n") + 1
            self.pos[name] += end
            for line in data[:end].decode(errors="replace").splitlines():
                if "] phase " in line or (name == "carrier" and ("hand" in line or "stopped" in line or "in control" in line)):
                    click.echo(f"  +{time.monotonic() - self.t0:6.1f} s {name}: {line.strip()[-110:]}")



def start_px4s(stack: ExitStack, build: Path, vehicles: list[tuple[str, int, int, Any]], speed_factor: float,
               directory: Path) -> NetNamespace:
    """Start one PX4 SITL per ``(name, instance, airframe, params)`` of ``vehicles`` in a new
    network namespace, their root folders under ``/var/tmp`` (not under ``/tmp``: PX4 gets a
    private one) and their output in ``directory``; ``stack`` stops them and removes both.
    Returns the namespace."""
    ns = NetNamespace()
    stack.callback(ns.close)
    rootfs = Path(f"/var/tmp/{ns.name}")
    stack.callback(shutil.rmtree, rootfs, True)
    for name, instance, airframe, params in vehicles:
        px4 = Px4Sitl(build, rootfs / f"rootfs{instance}", ns, instance=instance, airframe=airframe,
                      speed_factor=speed_factor, out_dir=directory, params=dict(params))
        px4.start()
        stack.callback(px4.stop)
        click.echo(f"  PX4 instance {instance} ({name}, airframe {airframe}) pid {px4.pid}")
    return ns

def _home_set(px4_out: Path) -> bool:
    """Whether a PX4's output says its estimator has a home (armable soon after)."""
    return "home set" in px4_out.read_text(errors="replace")


def _on_monotonic(log_dir: Path, offset_s: float) -> tuple[Any, float] | None:
    """A passenger's record and the shift [s] that puts its mission clock on the bench's monotonic clock."""
    if not (log_dir / "record.csv").exists() or not (log_dir / "flight.mcap").exists():
        return None
    epoch_ns = read_messages(log_dir / "flight.mcap", topics=set()).epoch_ns
    return read_record(log_dir), epoch_ns * 1e-9 - offset_s


def _at(series: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``series`` (rows t, _, x, y, z, ...) interpolated at times ``t``: (len(t), 3) positions."""
    return np.column_stack([np.interp(t, series[:, 0], series[:, k]) for k in (2, 3, 4)])


def true_offset_m(passenger: np.ndarray, carrier: np.ndarray, slot: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The horizontal distance [m] of the passenger from the dock point (``carrier`` plus ``slot`` [m]
    NED) at times ``t``, both ``series`` rows as :func:`_at` reads them (e.g. SIH's truths)."""
    rel = _at(passenger, t) - (_at(carrier, t) + slot)
    return np.hypot(rel[:, 0], rel[:, 1])


def _phase_at(rec: Any, shift_s: float, t: np.ndarray) -> np.ndarray:
    """The passenger's phase (its record's, the last tick at or before each time) at monotonic times ``t``."""
    i = np.searchsorted(rec.t + shift_s, t, side="right") - 1
    return np.where(i >= 0, rec.phase[np.clip(i, 0, None)], "")


def pairwise(t: np.ndarray, dist: np.ndarray, phases: tuple[np.ndarray, np.ndarray], separation_m: float,
             span_m: float) -> dict[str, Any]:
    """The pair's least true distance while both fly, and its largest shortfall against what the
    barrier keeps (module docstring) [m]; ``t`` [s], ``dist`` [m] and each one's phase per sample."""
    a, b = phases
    both = np.array([x in FLYING_NAMES and y in FLYING_NAMES and JOIN not in (x, y) for x, y in zip(a, b)], dtype=bool)
    seated = np.array([x in SEATED or y in SEATED for x, y in zip(a, b)], dtype=bool)
    worst, widest, at = 0.0, 0.0, None
    for k in np.flatnonzero(both):
        if seated[k]:
            widest, kept = 0.0, span_m
        else:
            widest = max(widest, float(dist[k]))
            kept = min(separation_m, widest)
        if kept - float(dist[k]) > worst:
            worst, at = kept - float(dist[k]), k
    free = both & ~seated
    k_min = int(np.flatnonzero(both)[np.argmin(dist[both])]) if both.any() else None
    k_free = int(np.flatnonzero(free)[np.argmin(dist[free])]) if free.any() else None
    return {"min_m": None if k_min is None else round(float(dist[k_min]), 3),
            "min_phases": None if k_min is None else [str(a[k_min]), str(b[k_min])],
            "min_both_off_slots_m": None if k_free is None else round(float(dist[k_free]), 3),
            "min_both_off_slots_phases": None if k_free is None else [str(a[k_free]), str(b[k_free])],
            "shortfall_m": round(worst, 3), "shortfall_phases": None if at is None else [str(a[at]), str(b[at])],
            "violation": worst > VIOLATION_M}


def record_truth(cfg: Config, directory: Path, gcs: Any, rover_sysid: int) -> None:
    """Write each vehicle's estimate and truth as the GCS link received them (``truth-NAME.csv``,
    :func:`sim.sitl.ground_truth.write_csv`), every truth about the first passenger's EKF origin."""
    with gcs._cond:
        origins = [m for _, _, m in gcs.history.get("GPS_GLOBAL_ORIGIN", ())
                   if m.get_srcSystem() == cfg.team.passengers[0].system_id]
    origin = None if not origins else (origins[-1].latitude * 1e-7, origins[-1].longitude * 1e-7, origins[-1].altitude * 1e-3)
    for name, sysid in [*[(p.name, p.system_id) for p in cfg.team.passengers], ("rover", rover_sysid)]:
        if origin is None:
            est, truth = ground_truth.series(gcs, sysid, (0.0, 0.0, 0.0))[0], np.zeros((0, 8))
        else:
            est, truth = ground_truth.series(gcs, sysid, origin)
        ground_truth.write_csv(directory / f"truth-{name}.csv", est, truth)


def _read_truth(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """A ``truth-NAME.csv`` back as (estimate, truth) rows ``t, boot, x, y, z`` (truth: at the estimate's times)."""
    c = ground_truth.read_csv(path)
    est = np.column_stack([c["t_rx_s"], c["boot_s"], c["x"], c["y"], c["z"]])
    truth = np.column_stack([c["t_rx_s"], c["boot_s"], c["true_x"], c["true_y"], c["true_z"]])
    return est, truth[np.isfinite(truth[:, 2:]).all(axis=1)]


def carrier_alignment_m(directory: Path) -> np.ndarray:
    """The shift [m] NED the carrier added to the rover's estimate once, aligning it onto the first
    passenger standing on the deck (``carrier.align_on_deck_m``; its log says it), zeros without one."""
    path = directory / "carrier.err"
    text = path.read_text(errors="replace") if path.exists() else ""
    match = re.search(r"aligned on the passenger standing on the deck: shift \[([^\]]*)\]", text)
    return np.array([float(v) for v in match.group(1).split(",")]) if match else np.zeros(3)


def gcs_delay_s(directory: Path, offset_s: float, rover_est: np.ndarray, moving_m_s: float = 0.8) -> float | None:
    """How much later [s] the rover's estimate arrived on the GCS link than the carrier process
    received it on the offboard link: the shift of the GCS series that best matches (least median
    horizontal distance) the positions the carrier published (``carrier.mcap``'s status, its own
    receive-time copy of the same LOCAL_POSITION_NED, plus its small alignment shift) while it
    drove faster than ``moving_m_s``. Positive: the bench's receipt was the later (its truth of
    the rover is as late); negative: the carrier's. None without a log."""
    path = directory / "carrier.mcap"
    if not path.exists() or len(rover_est) < 2:
        return None
    content = read_messages(path, topics={STATUS_TOPIC})
    rows = []
    for _, _, log_ns, data in content.messages:
        st = json.loads(data)
        if st.get("published") and st.get("position") and st.get("velocity"):
            p, v = st["position"], st["velocity"]
            rows.append((log_ns * 1e-9 - offset_s, p["n"], p["e"], v["n"], v["e"]))
    r = np.asarray(rows).reshape(-1, 5)
    r = r[np.hypot(r[:, 3], r[:, 4]) > moving_m_s]
    if len(r) < 30:
        return None
    shifts = np.arange(-0.2, 0.6, 0.01)
    cost = [float(np.median(np.hypot(*(r[:, 1:3] - _at(rover_est, r[:, 0] + tau)[:, :2]).T))) for tau in shifts]
    return round(float(shifts[int(np.argmin(cost))]), 2)


def analyse(cfg: Config, directory: Path, offset_s: float) -> dict[str, Any]:
    """The flight's figures (module docstring) from its logs and ``truth-*.csv``; ``offset_s`` [s]
    Unix time minus the bench's monotonic clock during the flight."""
    names = [p.name for p in cfg.team.passengers]
    est, truth = {}, {}
    for name in [*names, "rover"]:
        est[name], truth[name] = _read_truth(directory / f"truth-{name}.csv")
    est["rover"][:, 2:5] += carrier_alignment_m(directory)  # the carrier's frame: its estimate as it published it
    # the carrier's published positions carry the world's GNSS errors (a fix 0.2 s late, metres of bias): no timing check
    rover_delay = None if cfg.world.carrier_gnss.enabled else gcs_delay_s(directory, offset_s, est["rover"])
    # the rover's truth moved onto the carrier's receive times (module docstring: which clock is late is not known)
    shifted = truth["rover"].copy()
    shifted[:, 0] -= rover_delay or 0.0
    clocks = {n: round(clock_ratio_of(e[:, 0], e[:, 1]), 3) if len(e) > 10 else None for n, e in est.items()}
    law = cfg.law
    carrier_path = directory / "carrier.json"
    carrier = json.loads(carrier_path.read_text()) if carrier_path.exists() else {}
    legs, recs = [], {}
    for p in cfg.team.passengers:
        log_dir = directory / p.name
        s = json.loads((log_dir / "summary.json").read_text()) if (log_dir / "summary.json").exists() else {}
        rec = _on_monotonic(log_dir, offset_s)
        if rec is not None:
            recs[p.name] = rec
        own = passenger_config(cfg, p.name)
        slot = np.asarray(own.mission.dock_offset_ned_m, dtype=float)
        tlog = clock_ratio(log_dir / "flight.tlog") if (log_dir / "flight.tlog").exists() else None
        leg_records = {leg.k: leg.record for leg in rec[0].legs()} if rec is not None else {}
        for d, leg in zip(dockings(s, law.b * law.c), s.get("legs") or [s]):
            contact = leg.get("contact") or {}
            true_err = true_shifted = frames = riding = None
            lr = leg_records.get(d["leg"])
            if lr is not None and rec is not None and len(truth[p.name]) > 1 and len(truth["rover"]) > 1:
                t = lr.t[lr.phase == "RIDING"] + rec[1]  # the true riding offset before this leg's separation
                if len(t):
                    riding = round(float(true_offset_m(truth[p.name], truth["rover"], slot, t).max()), 3)
            if contact and rec is not None and len(truth[p.name]) > 1 and len(truth["rover"]) > 1:
                tc = np.array([contact["time_s"] + rec[1]])
                true_err = round(float(true_offset_m(truth[p.name], truth["rover"], slot, tc)[0]), 3)
                true_shifted = (None if rover_delay is None
                                else round(float(true_offset_m(truth[p.name], shifted, slot, tc)[0]), 3))
                # what the two estimates' errors alone put between estimate and truth at contact
                off = (_at(est[p.name], tc)[0] - _at(truth[p.name], tc)[0]) - (_at(est["rover"], tc)[0] - _at(truth["rover"], tc)[0])
                frames = round(float(np.hypot(off[0], off[1])), 3)
            target_k = p.targets[int(d["leg"] or 0)] if d["leg"] is not None and int(d["leg"]) < len(p.targets) else None
            legs.append({"passenger": p.name, "target": target_k, **d, "true_error_m": true_err, "true_error_shifted_m": true_shifted,
                         "estimates_apart_m": frames, "true_riding_m": riding,
                         "stall_s": stall_s(log_dir), "mission_clock": None if tlog is None else round(tlog["ratio"], 3)})
    map_check = {}
    for name, (rec, shift) in recs.items():
        x = rec.vec("x_p")
        ok = np.isfinite(x).all(axis=1)
        if ok.sum() and len(est[name]):
            map_check[name] = round(float(np.median(np.linalg.norm(x[ok] - _at(est[name], rec.t[ok] + shift), axis=1))), 3)
    pair = None
    if len(names) == 2 and all(n in recs for n in names) and all(len(truth[n]) > 1 for n in names):
        t = truth[names[0]][:, 0]
        dist = np.linalg.norm(truth[names[0]][:, 2:5] - _at(truth[names[1]], t), axis=1)
        phases = (_phase_at(*recs[names[0]], t), _phase_at(*recs[names[1]], t))
        pair = pairwise(t, dist, phases, cfg.safety.passenger_separation_m, cfg.team.passenger_span_m)
    rover = truth["rover"]  # the carrier's true closest approach to each target (its own figure: in its frame)
    true_closest = [round(float(np.min(np.linalg.norm(rover[:, 2:5] - np.asarray(t, float), axis=1))), 3)
                    if len(rover) else None for t in cfg.scenario.legs()]
    return {"legs": legs, "pair": pair, "carrier_true_closest_each_target_m": true_closest, "separation_m": cfg.safety.passenger_separation_m,
            "span_m": cfg.team.passenger_span_m, "carrier_closest_each_target_m": carrier.get("closest_each_target_m"),
            "carrier_closest_pair_heard": carrier.get("closest_pair"), "hand_overs": carrier.get("hand_overs"),
            "clocks": clocks, "map_check_m": map_check, "rover_gcs_delay_s": rover_delay}


def fly_team(config: Path, directory: Path, speed_factor: float = 1.08, timeout_s: float | None = None,
             camera: bool = False, seed: int = 0) -> dict[str, Any]:
    """One flight of ``config``'s team on three fresh PX4s; its figures (:func:`analyse`) with the
    exit codes, the wall time and the load. ``camera``: with the camera node (module docstring),
    the flown configuration ``config.toml`` in ``directory`` with ``world.carrier_gnss.seed`` ``seed``."""
    directory.mkdir(parents=True, exist_ok=True)
    if camera:
        flown = directory / "config.toml"
        flown.write_text(patched_config(config.read_text(), {"world.carrier_gnss.seed": str(seed)}))
        config = flown
    cfg = load_config(config)
    build = build_dir()
    assert build is not None
    rover_sysid = cfg.carrier.mavlink.target_system
    if rover_sysid is None:
        raise click.ClickException("carrier.mavlink.target_system is not set: the rover's PX4 instance is target_system - 1")
    rover_instance = instance_of(rover_sysid)
    expected = f"udpin:127.0.0.1:{OFFBOARD_PORT + rover_instance}"
    if cfg.carrier.mavlink.url != expected:
        raise click.ClickException(f"carrier.mavlink.url is {cfg.carrier.mavlink.url}: the rover (sysid {rover_sysid}) "
                                   f"sends to {expected}")
    directory.mkdir(parents=True, exist_ok=True)
    timeout_s = timeout_s or cfg.mission.max_duration_s + 120.0
    load = os.getloadavg()
    t0 = time.monotonic()
    codes: dict[str, int | None] = {}
    with ExitStack() as stack:
        vehicles = [(p.name, instance_of(p.system_id), QUAD_AIRFRAME, ROVER_BATTERY) for p in cfg.team.passengers]
        vehicles.append(("rover", rover_instance, ROVER_AIRFRAME, ROVER_PARAMS))
        ns = start_px4s(stack, build, vehicles, speed_factor, directory)
        gcs = None
        if not camera:  # with a camera its node holds the GCS port and records the truth
            gcs = gcs_probe(ns, history_len=200_000)
            stack.callback(gcs.close)
            from sim.testing.probe import connect

            connect(gcs, timeout_s=30.0, heartbeat_period_s=0.5)
        for _, instance, _, _ in vehicles:
            path = directory / f"px4-{instance}.out"
            wait_for(lambda: _home_set(path), 90.0, f"'home set' in {path.name}")
        for name, instance, _, _ in vehicles:
            if gcs is not None:
                acks = ground_truth.ask(gcs, TRUTH_HZ, system_id=instance + 1, gcs_port=GCS_LISTEN_PORT + instance)
                click.echo(f"  {name}: truth asked, acks {acks}")
        armable_s = time.monotonic() - t0
        offset_s = time.time() - time.monotonic()
        endpoint = "tcp/127.0.0.1:7450"
        carrier = _popen(ns, directory, "carrier", ["-v", "carrier", str(config), "--zenoh-listen", endpoint, "--summary",
                                                     str(directory / "carrier.json"), "--mcap", str(directory / "carrier.mcap")],
                         stack)
        node = None
        if camera:
            node = _popen(ns, directory, "camera", [
                str(config), *[a for p in cfg.team.passengers for a in ("--passenger", p.name)], "--carrier-sysid",
                str(rover_sysid), "--seed", str(seed), "--truth-dir", str(directory),
                "--zenoh-connect", endpoint], stack, module="sim.sitl.camera")
        missions = {}
        for p in cfg.team.passengers:
            missions[p.name] = _popen(ns, directory, p.name, [
                "-v", "run", str(config), "--passenger", p.name, "--mavlink",
                f"udpin:127.0.0.1:{OFFBOARD_PORT + instance_of(p.system_id)}", "--zenoh-connect", endpoint,
                "--log-dir", str(directory / p.name)], stack)
        progress = Progress(directory, list(missions), t0)
        deadline = time.monotonic() + timeout_s
        home_since: dict[str, float] = {}
        while any(m.poll() is None for m in missions.values()) and time.monotonic() < deadline:
            progress.poll()
            for name in missions if camera else ():
                if name not in home_since and "] phase HOME" in (directory / f"{name}.out").read_text(errors="replace"):
                    home_since[name] = time.monotonic()
            if len(home_since) == len(missions) and time.monotonic() - max(home_since.values()) > HOME_S:
                click.echo(f"  every passenger {HOME_S:g} s in HOME after its last dock: the missions are stopped (module docstring)")
                for m in missions.values():
                    stop_process(m, 30.0)
                break
            time.sleep(1.0)
        progress.poll()
        for name, m in missions.items():
            if m.poll() is None:
                click.echo(f"  {name}: still running after {timeout_s:.0f} s: stopped")
                stop_process(m, 30.0)
            codes[name] = m.returncode
        stop_process(carrier, 10.0)  # writes carrier.json
        codes["carrier"] = carrier.returncode
        if node is not None:
            stop_process(node, 20.0)  # writes the truth and camera.json
            codes["camera"] = node.returncode
        if gcs is not None:
            record_truth(cfg, directory, gcs, rover_sysid)
    (directory / "clock_offset.json").write_text(json.dumps({"unix_minus_monotonic_s": offset_s}) + "\n")
    figures = analyse(cfg, directory, offset_s)
    if camera:
        figures["camera"] = json.loads((directory / "camera.json").read_text()) if (directory / "camera.json").exists() else {}
        figures["seed"] = seed
    return {**figures, "exit_codes": codes, "armable_after_s": round(armable_s, 1),
            "wall_s": round(time.monotonic() - t0, 1), "load_before": [round(x, 2) for x in load],
            "load_after": [round(x, 2) for x in os.getloadavg()], "dir": str(directory)}


def flags(row: dict[str, Any]) -> list[str]:
    """Why a flight is not a clean measurement (``bench.px4_flights``' rules): ``clock`` when a PX4's
    clock ran outside ``CLOCK_OK`` times wall time, ``stall`` when a passenger's controller or the
    carrier state it used was held up over ``STALL_S`` while flying."""
    out = []
    if any(c is None or not CLOCK_OK[0] <= c <= CLOCK_OK[1] for c in row["clocks"].values()):
        out.append("clock")
    if any(leg["stall_s"] is not None and leg["stall_s"] > STALL_S for leg in row["legs"]):
        out.append("stall")
    return out


def _fmt(v: Any) -> str:
    return f"{v:.3f}" if isinstance(v, float) else "-" if v is None else str(v)


LEG_COLUMNS = ("passenger", "target", "outcome", "attempts", "error_m", "true_error_m", "true_error_shifted_m", "estimates_apart_m", "h_speed_m_s",
               "p1", "p2", "p3", "riding_offset_m", "true_riding_m", "jump_m_s", "closest_m", "stall_s", "mission_clock")


def report(row: dict[str, Any]) -> list[str]:
    """The flight's lines: one per leg, the pair, the carrier, the clocks."""
    lines = ["  " + " ".join(f"{c:>13}" for c in LEG_COLUMNS)]
    for leg in row["legs"]:
        lines.append("  " + " ".join(f"{_fmt(leg.get(c)):>13}" for c in LEG_COLUMNS))
    pair = row.get("pair") or {}
    lines.append(f"  pair (truth, both flying): min {_fmt(pair.get('min_m'))} m {pair.get('min_phases')}; both off their slots "
                 f"min {_fmt(pair.get('min_both_off_slots_m'))} m {pair.get('min_both_off_slots_phases')} against "
                 f"safety.passenger_separation_m {row['separation_m']:g} m; shortfall {_fmt(pair.get('shortfall_m'))} m "
                 f"{pair.get('shortfall_phases')} (span {row['span_m']:g} m beside a seated one): "
                 f"{'VIOLATION' if pair.get('violation') else 'no violation' if pair else 'not measured'}")
    heard = row.get("carrier_closest_pair_heard") or {}
    lines.append(f"  carrier: closest approach to each target {row.get('carrier_closest_each_target_m')} m as it knew itself, "
                 f"{row.get('carrier_true_closest_each_target_m')} m in truth; closest pair heard "
                 f"{heard.get('distance_m')} m {heard.get('phases')}; hand-overs {row.get('hand_overs')}")
    lines.append(f"  PX4 clocks {row['clocks']}; record-to-GCS map check {row['map_check_m']} m; the rover's GCS link "
                 f"{row.get('rover_gcs_delay_s')} s later than the carrier's receipt; exit codes "
                 f"{row['exit_codes']}; load {row['load_before']} -> {row['load_after']}; {row['wall_s']} s")
    return lines


CONTACT_M = 0.2  # [m] the team's PX4 target for the contact error (docs/team.md, "On real PX4")
ATTEMPTS = 2  # ... and for the approaches


def leg_meets(leg: dict[str, Any], error: str = "error_m") -> bool:
    """The team's PX4 target for one leg: docked within 2 approaches at <= 0.2 m, with P1-P3;
    ``error`` the contact error judged: ``error_m`` (the mission's, on the estimates, as
    docs/recovery.md's PX4 target) or ``true`` (SIH's truth: both timings of the rover's within it,
    the one without a timing check when the carrier publishes GNSS). A leg that touched but fell
    back after (its outcome ``fallback: ...``: it went around from DOCKED) has a contact, and is
    not docked."""
    shifted = [] if leg["true_error_shifted_m"] is None else [leg["true_error_shifted_m"]]
    errors = [leg["true_error_m"], *shifted] if error == "true" else [leg[error]]
    stayed = not str(leg.get("outcome") or "").startswith("fallback")
    return bool(leg["docked"] and stayed and leg["attempts"] is not None and leg["attempts"] <= ATTEMPTS
                and None not in errors and max(errors) <= CONTACT_M and leg["p1"] and leg["p2"] and leg["p3"])


@click.command()
@click.option("--config", type=click.Path(dir_okay=False, exists=True), default=None,
              help="[default: configs/px4_sitl_team.toml; with --camera configs/px4_sitl_team_relnav.toml]")
@click.option("--out", type=click.Path(file_okay=False), required=True, help="The flight's logs and its row (row.json).")
@click.option("--speed-factor", type=float, default=1.08, show_default=True, help="PX4_SIM_SPEED_FACTOR of every PX4")
@click.option("--analyse", "again", is_flag=True, help="Do not fly: analyse the flight already in --out again (its "
              "row.json's run figures kept).")
@click.option("--camera", is_flag=True, help="Relative navigation: a camera per passenger (module docstring); --config "
              "defaults to configs/px4_sitl_team_relnav.toml.")
@click.option("--seed", type=int, default=0, show_default=True, help="With --camera: world.carrier_gnss.seed and the cameras' noise.")
def main(config: str | None, out: str, speed_factor: float, again: bool, camera: bool, seed: int) -> None:
    """Fly CONFIG's team once on real PX4 SITL and print its legs."""
    directory = Path(out)
    default = "px4_sitl_team_relnav.toml" if camera else "px4_sitl_team.toml"
    cfg_path = Path(config).resolve() if config else ROOT / "configs" / default
    if again and (directory / "config.toml").exists():
        cfg_path = (directory / "config.toml").resolve()  # a camera flight's, as flown
    if again:
        row = json.loads((directory / "row.json").read_text())
        offset_path = directory / "clock_offset.json"
        offset_s = (json.loads(offset_path.read_text())["unix_minus_monotonic_s"] if offset_path.exists()
                    else time.time() - time.monotonic())  # the same machine since: the same offset within ms
        row.update(analyse(load_config(cfg_path), directory, offset_s))
    else:
        why = unavailable_reason()
        if why:
            raise click.ClickException(why)
        click.echo(f"PX4 build {build_dir()}, config {cfg_path}, PX4_SIM_SPEED_FACTOR {speed_factor}, load {os.getloadavg()}")
        row = fly_team(cfg_path, directory, speed_factor, camera=camera, seed=seed)
    (directory / "row.json").write_text(json.dumps(row, indent=1, default=str) + "\n")
    for line in report(row):
        click.echo(line)
    pair = row.get("pair") or {}
    click.echo(f"{sum(leg_meets(leg) for leg in row['legs'])}/{len(row['legs'])} legs docked within {ATTEMPTS} approaches at "
               f"<= {CONTACT_M} m with P1-P3 ({sum(leg_meets(leg, 'true') for leg in row['legs'])} by the true "
               f"error, either timing); pairwise: {'VIOLATION' if pair.get('violation') else 'none' if pair else 'not measured'}; "
               f"flagged: {', '.join(flags(row)) or 'no'} (PX4 clocks within {CLOCK_OK}, no stall over {STALL_S} s); logs in {out}")


if __name__ == "__main__":
    main()
