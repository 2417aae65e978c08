"""A real PX4 SITL (SIH quadrotor) in a network namespace of its own, and a mission flown on it.

For the tests (``tests/px4_sitl/``) and the bench (``bench/px4_flights.py``); never imported by
``mission/``. A PX4 build is a folder with ``bin/px4`` (and its ``px4-alias.sh``) and ``etc/``:
``../shared/px4_sitl`` here, a user's ``build/px4_sitl_default`` elsewhere, named by the
environment variable ``MARSUPIAL_PX4_SITL``.

Every PX4 is fresh (its ``ROOTFS`` is wiped: default parameters), runs in a network namespace
made for it (its fixed UDP ports 14540/14580/18570/14550 can never collide with another PX4 or a
test), and is stopped by its own pid. Everything that talks to it (carrier, mission) runs in the
same namespace with ``ip netns exec``; the GCS-link observer's socket is made inside the
namespace by a thread that entered it (``setns`` acts on the calling thread only).

Needs root (``ip netns``). PX4's clock is not wall time (SIH steps it from a sleep-paced loop):
:func:`clock_ratio` measures it from a flight's tlog.
"""
from __future__ import annotations

import contextlib
import ctypes
import itertools
import json
import os
import shlex
import shutil
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from sim.net import stop_process

ENV_VAR = "MARSUPIAL_PX4_SITL"
# The tree this module is in: the flight's processes run its mission code, not whatever is installed (parents[1]
# was sim/, so a worktree's flights with a relative PYTHONPATH flew the editable install's code)
REPO_ROOT = Path(__file__).resolve().parents[2]
QUAD_AIRFRAME = 10040  # sihsim_quadx
ROVER_AIRFRAME = 10045  # SIH Ackermann rover: a carrier
# The rover's speed loop, tuned (PX4's rover tuning: RO_MAX_THR_SPEED, then RO_SPEED_P / RO_SPEED_I).
# Airframe 10045 ships it open loop (P = I = 0.001: throttle = speed / RO_MAX_THR_SPEED): the SIH
# rover then sticks below ~0.3 throttle and runs 1.7 m/s at 0.31, so asked for 1 m/s it swung
# 0.3-1.7 m/s (measured). RO_ACCEL_LIM also slews the throttle (RO_ACCEL_LIM / RO_MAX_THR_SPEED
# per second) and RO_DECEL_LIM its fall: 6 for both lets it break free sooner and cut its throttle
# sooner once free (bench/px4_rover_ramp.py, ramps to 1 m/s at 1 m/s^2: the leap peaks at 1.0-1.49
# m/s with both at 6, 1.09-1.34 with RO_ACCEL_LIM 6 alone, 1.26 with both at 3; it varies run to
# run). PX4 SITL sets PX4_PARAM_<name> from the environment at start.
ROVER_PARAMS = {"RO_MAX_THR_SPEED": 4.0, "RO_SPEED_P": 0.5, "RO_SPEED_I": 0.1, "RO_ACCEL_LIM": 6.0, "RO_DECEL_LIM": 6.0}
CLONE_NEWNET = 0x40000000
GCS_PORT = 14550  # PX4's GCS link (it listens on GCS_LISTEN_PORT + instance) sends here
GCS_LISTEN_PORT = 18570  # + instance: where a PX4's GCS link listens
PASSENGER_SYSID, ROVER_SYSID = 1, 2  # the quadrotor (instance 0) and, with ``rover``, the rover (instance 1)
HOME_LAG_S = 3.5  # a home follows the carrier within this [s]: moved at most once a second, HOME_POSITION at 0.5 Hz
_counter = itertools.count()
T = TypeVar("T")


def build_dir() -> Path | None:
    """The PX4 build named by ``MARSUPIAL_PX4_SITL`` (None if unset)."""
    value = os.environ.get(ENV_VAR)
    return Path(value).resolve() if value else None


def unavailable_reason(build: Path | None = None) -> str | None:
    """Why real PX4 flights cannot run here (None when they can)."""
    build = build or build_dir()
    if build is None:
        return f"{ENV_VAR} is not set (point it at a PX4 SITL build: a folder with bin/px4 and etc/)"
    if not (build / "bin" / "px4").is_file() or not (build / "etc").is_dir():
        return f"{ENV_VAR}={build} has no bin/px4 and etc/"
    if os.geteuid() != 0 or shutil.which("ip") is None or shutil.which("unshare") is None:
        return "PX4 flights run each PX4 in its own network and mount namespace: needs root, ip and unshare"
    return None


class NetNamespace:
    """A network namespace with its loopback up; ``close`` deletes it."""

    def __init__(self, name: str | None = None) -> None:
        self.name = name or f"mpx4-{os.getpid()}-{next(_counter)}"
        subprocess.run(["ip", "netns", "add", self.name], check=True, capture_output=True)
        try:
            self.run_checked(["ip", "link", "set", "lo", "up"])
        except Exception:
            self.close()
            raise

    def command(self, args: list[str]) -> list[str]:
        """``args`` to run inside the namespace (``ip netns exec`` then execs them: same pid)."""
        return ["ip", "netns", "exec", self.name, *args]

    def run_checked(self, args: list[str]) -> None:
        subprocess.run(self.command(args), check=True, capture_output=True)

    def inside(self, fn: Callable[[], T]) -> T:
        """Run ``fn`` on a thread that entered the namespace; sockets it makes live there."""
        result: list[Any] = []

        def target() -> None:
            try:
                libc = ctypes.CDLL(None, use_errno=True)
                with open(f"/var/run/netns/{self.name}") as ns:
                    if libc.setns(ns.fileno(), CLONE_NEWNET) != 0:
                        raise OSError(ctypes.get_errno(), f"setns into {self.name}")
                result.append((True, fn()))
            except BaseException as exc:  # handed back to the caller's thread
                result.append((False, exc))

        thread = threading.Thread(target=target, name=f"netns-{self.name}")
        thread.start()
        thread.join()
        ok, value = result[0]
        if not ok:
            raise value
        return value

    def close(self) -> None:
        subprocess.run(["ip", "netns", "delete", self.name], capture_output=True)

    def __enter__(self) -> NetNamespace:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _prepare_rootfs(build: Path, rootfs: Path) -> None:
    """Wipe ``rootfs`` and give it PX4's module links (what ``run-sih.sh`` does)."""
    shutil.rmtree(rootfs, ignore_errors=True)
    (rootfs / "bin").mkdir(parents=True)
    alias = build / "bin" / "px4-alias.sh"
    shutil.copy(alias, rootfs / "bin")
    import re
    for name in sorted(set(re.findall(r"px4-[a-z0-9_]*", alias.read_text()))):
        (rootfs / "bin" / name).symlink_to(build / "bin" / "px4")


@dataclass
class Px4Sitl:
    """One fresh PX4 SITL process in ``ns``; ``start()`` launches it, ``stop()`` ends it by pid.

    speed_factor: ``PX4_SIM_SPEED_FACTOR`` (SIH's lockstep rate over wall time; here its loop
    falls a little behind, so 1.03 brings PX4's clock near wall time). Output goes to
    ``out_dir/px4-<instance>.out``; ``rootfs`` must not be under /tmp (PX4 gets a private /tmp).
    """

    build: Path
    rootfs: Path
    ns: NetNamespace
    instance: int = 0
    airframe: int = QUAD_AIRFRAME
    speed_factor: float = 1.0
    out_dir: Path = Path(".")
    params: dict[str, float] = field(default_factory=dict)  # PX4_PARAM_<name>: set by PX4 SITL at start
    proc: subprocess.Popen[bytes] | None = None
    _out: Any = None

    def start(self) -> None:
        _prepare_rootfs(self.build, self.rootfs)
        model = next((self.build / "etc" / "init.d-posix" / "airframes").glob(f"{self.airframe}_*")).name.split("_", 1)[1]
        env = {**os.environ, "PATH": f"{self.rootfs / 'bin'}:{self.build / 'bin'}:{os.environ.get('PATH', '')}",
               "PX4_SYS_AUTOSTART": str(self.airframe), "PX4_SIMULATOR": "sihsim", "PX4_SIM_MODEL": model,
               "HEADLESS": "1", "PX4_SIM_SPEED_FACTOR": f"{self.speed_factor:g}",
               **{f"PX4_PARAM_{name}": f"{value:g}" for name, value in self.params.items()}}
        self._out = open(self.out_dir / f"px4-{self.instance}.out", "wb")
        px4 = " ".join(shlex.quote(a) for a in [str(self.build / "bin" / "px4"), "-d", "-i", str(self.instance), "-w",
                                                str(self.rootfs), "-s", "etc/init.d-posix/rcS", str(self.build / "etc")])
        # PX4 keeps a lock socket per instance number in /tmp, which a network namespace does not
        # separate: a private /tmp (its own mount namespace) keeps another PX4 of the same instance
        # elsewhere on the machine from making ours exit. Every exec keeps the pid: PX4's own.
        self.proc = subprocess.Popen(
            self.ns.command(["unshare", "-m", "sh", "-c", f"mount -t tmpfs px4tmp /tmp && exec {px4}"]),
            cwd=self.rootfs, env=env, stdout=self._out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)

    @property
    def pid(self) -> int | None:
        return None if self.proc is None else self.proc.pid

    def stop(self, timeout_s: float = 5.0) -> None:
        """SIGTERM to PX4's pid (it stops within about a second), SIGKILL after ``timeout_s``."""
        if self.proc is not None:
            stop_process(self.proc, timeout_s)
        if self._out is not None:
            self._out.close()
            self._out = None


def gcs_probe(ns: NetNamespace, instance: int = 0, history_len: int = 4000) -> Any:
    """A :class:`sim.testing.probe.Probe` on PX4's GCS link in ``ns`` (bound to 14550), keeping
    the last ``history_len`` messages of each type."""
    from sim.testing.probe import Probe

    return ns.inside(lambda: Probe(bind=f"127.0.0.1:{GCS_PORT}", vehicle=("127.0.0.1", GCS_LISTEN_PORT + instance),
                                   history_len=history_len))


def wait_armable(probe: Any, timeout_s: float = 30.0) -> float:
    """Wait until PX4 says its pre-arm checks pass (SYS_STATUS health bit
    MAV_SYS_STATUS_PREARM_CHECK) and it has a home position; returns the wall seconds waited.
    Raises TimeoutError."""
    from mission.mavlink.env import mavlink

    bit = mavlink.MAV_SYS_STATUS_PREARM_CHECK

    def armable() -> bool:
        status = probe.latest("SYS_STATUS")
        return status is not None and bool(status.onboard_control_sensors_health & bit) and probe.latest("HOME_POSITION") is not None

    from sim.net import wait_for

    t0 = time.monotonic()
    try:
        wait_for(armable, timeout_s, "PX4 armable")
    except AssertionError:
        raise TimeoutError(f"PX4 not armable within {timeout_s} s") from None
    return time.monotonic() - t0


def clock_ratio(tlog: Path, message: str = "LOCAL_POSITION_NED") -> dict[str, float] | None:
    """PX4's clock against the receiver's over a ``.tlog``: the slope of ``time_boot_ms`` over the
    tlog's receive stamps (a least-squares fit; 1.0 = real time), with the rate the message arrived
    at [Hz of receive time] and the span [s]. None if fewer than 10 such messages."""

    from mission.mavlink.env import mavlink

    mav = mavlink.MAVLink(None)
    mav.robust_parsing = True
    data = Path(tlog).read_bytes()
    rx, boot = [], []
    i = 0
    while i + 8 <= len(data):
        (usec,) = struct.unpack(">Q", data[i:i + 8])
        i += 8
        if i >= len(data):
            break
        magic = data[i]
        if magic == 0xFD:
            length = 12 + data[i + 1] + (13 if data[i + 2] & 1 else 0)
        elif magic == 0xFE:
            length = 8 + data[i + 1]
        else:
            break
        packet = data[i:i + length]
        i += length
        try:
            msgs = mav.parse_buffer(packet) or []
        except Exception:
            continue
        for m in msgs:
            if m.get_type() == message and m.get_srcComponent() == 1:
                rx.append(usec * 1e-6)
                boot.append(m.time_boot_ms * 1e-3)
    if len(rx) < 10:
        return None
    span = float(rx[-1] - rx[0])
    return {"ratio": clock_ratio_of(rx, boot), "rate_hz": (len(rx) - 1) / span if span > 0 else float("nan"), "span_s": span}


def clock_ratio_of(rx_s: Any, boot_s: Any) -> float:
    """PX4's clock against the receiver's: the least-squares slope of PX4's times ``boot_s`` [s]
    over their receive times ``rx_s`` [s] (1.0 = real time)."""
    import numpy as np

    rx_a, boot_a = np.asarray(rx_s, dtype=float), np.asarray(boot_s, dtype=float)
    return float(np.polyfit(rx_a - rx_a[0], boot_a - boot_a[0], 1)[0])


def patched_config(text: str, overrides: dict[str, str]) -> str:
    """``text`` (TOML) with ``section.key = value`` lines replaced, or added at the top of their
    section (``value`` a TOML literal): a scenario beside a shipped config."""
    import re

    for dotted, value in overrides.items():
        section, key = dotted.rsplit(".", 1)
        header = re.search(rf"^\[{re.escape(section)}\]\s*$", text, flags=re.M)
        if header is None:
            text = f"{text.rstrip()}\n\n[{section}]\n{key} = {value}\n"
            continue
        nxt = re.search(r"^\[", text[header.end():], flags=re.M)
        end = header.end() + (nxt.start() if nxt else len(text) - header.end())
        body = text[header.end():end]
        line = re.compile(rf"^{re.escape(key)}\s*=.*$", flags=re.M)
        body = line.sub(f"{key} = {value}", body, count=1) if line.search(body) else f"\n{key} = {value}{body}"
        text = text[:header.end()] + body + text[end:]
    return text


@dataclass
class Px4Flight:
    """The mission flown on a fresh PX4 in its own namespace: PX4, the carrier simulator and
    ``marsupial run`` as processes (``python -m mission.cli``), and an observer on PX4's GCS
    link. Outputs in ``dir`` (``mission.out``, ``carrier.out``, ``px4-0.out``, ``flight/``).

    ``rover=True``: the carrier is a second PX4 in the same namespace, the SIH Ackermann rover
    (instance 1, sysid 2, :data:`ROVER_PARAMS`), driven by ``marsupial carrier`` with the config's
    ``carrier.backend = "mavlink"``; both start at SIH's home, so their local frames coincide. The
    GCS observer then hears both PX4s (sysid 1 and 2 on one port)."""

    dir: Path
    config: Path
    build: Path = field(default_factory=lambda: build_dir() or Path("."))
    speed_factor: float = 1.08
    mission_args: tuple[str, ...] = ()
    carrier_args: tuple[str, ...] = ()
    ns: NetNamespace | None = None
    px4: Px4Sitl | None = None
    gcs: Any = None
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)
    armable_after_s: float = float("nan")
    _rootfs: Path | None = None
    settle_s: float = 0.0  # extra wall seconds after PX4 is armable before the carrier and the mission start
    ground_truth_hz: float = 0.0  # > 0: record PX4's estimate and SIH's truth at this rate (``truth.csv``)
    px4_params: dict[str, float] = field(default_factory=dict)  # PX4_PARAM_<name>: set by PX4 SITL at start
    rover: bool = False  # the carrier a PX4 rover (instance 1) rather than the carrier simulator
    rover_px4: Px4Sitl | None = None
    monotonic_offset_s: float = float("nan")  # [s] wall time less monotonic time as the mission started
    _files: list[Any] = field(default_factory=list)

    @property
    def log_dir(self) -> Path:
        return self.dir / "flight"

    def _popen(self, name: str, args: list[str]) -> subprocess.Popen[bytes]:
        out, err = open(self.dir / f"{name}.out", "ab"), open(self.dir / f"{name}.err", "ab")
        self._files += [out, err]
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONPATH": f"{REPO_ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
        proc = subprocess.Popen(self.ns.command([sys.executable, "-m", "mission.cli", *args]), stdout=out, stderr=err,
                                env=env, cwd=REPO_ROOT, stdin=subprocess.DEVNULL)
        self.procs[name] = proc
        return proc

    def start(self, zenoh_port: int = 7450) -> None:
        """PX4 first; once it is armable, the carrier and the mission."""
        self.dir.mkdir(parents=True, exist_ok=True)
        self.ns = NetNamespace()
        # ROOTFS outside /tmp: PX4 gets a private /tmp (see Px4Sitl.start), which would hide it
        self._rootfs = Path(f"/var/tmp/{self.ns.name}") / "rootfs"
        self.px4 = Px4Sitl(self.build, self._rootfs, self.ns, speed_factor=self.speed_factor, out_dir=self.dir,
                           params=self.px4_params)
        self.px4.start()
        if self.rover:
            self.rover_px4 = Px4Sitl(self.build, self._rootfs.parent / "rootfs1", self.ns, instance=1,
                                     airframe=ROVER_AIRFRAME, speed_factor=self.speed_factor, out_dir=self.dir,
                                     params=ROVER_PARAMS)
            self.rover_px4.start()
        self.gcs = gcs_probe(self.ns, history_len=100_000 if self.ground_truth_hz > 0 or self.rover else 4000)
        from sim.testing.probe import connect

        connect(self.gcs, timeout_s=20.0, heartbeat_period_s=0.5)
        self.armable_after_s = wait_armable(self.gcs)
        if self.rover:  # the observer hears both: each PX4 says when its estimator has a home (armable)
            from sim.net import wait_for

            for name in ("px4-0.out", "px4-1.out"):
                wait_for(lambda name=name: "home set" in self.text(name), 60.0, f"'home set' in {name}")
        if self.ground_truth_hz > 0:
            from sim.sitl import ground_truth

            ground_truth.ask(self.gcs, self.ground_truth_hz)
            if self.rover:  # the rover's too, on its own GCS port (both arrive on the observer's socket)
                ground_truth.ask(self.gcs, self.ground_truth_hz, system_id=ROVER_SYSID, gcs_port=GCS_LISTEN_PORT + 1)
        if self.settle_s > 0:
            time.sleep(self.settle_s)  # real-time PX4's estimator keeps converging (the probe keeps receiving)
        self.monotonic_offset_s = time.time() - time.monotonic()
        endpoint = f"tcp/127.0.0.1:{zenoh_port}"
        self._popen("carrier", ["-v", "carrier", str(self.config), "--zenoh-listen", endpoint, *self.carrier_args])
        self._popen("mission", ["-v", "run", str(self.config), "--zenoh-connect", endpoint, "--log-dir",
                                str(self.log_dir), "--json", *self.mission_args])

    def wait_mission(self, timeout_s: float = 120.0) -> int:
        try:
            return self.procs["mission"].wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"mission still running after {timeout_s} s: {self.text('mission.out')[-2000:]}") from None

    def watch_after(self, target_ned_m: Any, duration_s: float = 3.0) -> float:
        """After the mission has ended: the farthest [m] PX4's LOCAL_POSITION_NED on the GCS link
        gets from ``target_ned_m`` over the next ``duration_s`` wall seconds (its own Hold)."""
        import numpy as np

        mark = self.gcs.mark()
        time.sleep(duration_s)  # PX4 holds on its own, in real time; the probe's thread records it
        pts = [(m.x, m.y, m.z) for m in self.gcs.messages("LOCAL_POSITION_NED", after=mark)]
        if not pts:
            return float("nan")
        return float(np.linalg.norm(np.asarray(pts) - np.asarray(target_ned_m, dtype=float), axis=1).max())

    def home_following(self, lag_s: float = HOME_LAG_S) -> dict[str, Any] | None:
        """Did PX4's home follow the carrier (``rover=True``)? Each HOME_POSITION the passenger's
        PX4 (sysid 1) sent on the GCS link, against the rover's LOCAL_POSITION_NED (sysid 2)
        received on the same socket (one clock): ``homes`` (how many), ``moved_m`` (how far the home
        travelled, first to last [m]), ``max_lagged_m`` (the largest over the homes of the distance
        to the nearest point of the rover's track over the ``lag_s`` before it arrived [m]: the
        home is moved at most once a second and streamed at 0.5 Hz), ``final_m`` (the last home
        from the rover's position when it arrived [m]); horizontal. None without the rover's or the
        homes' messages."""
        import numpy as np

        if self.gcs is None:
            return None
        homes = [(t, m.x, m.y) for t, m in self.gcs.timed("HOME_POSITION") if m.get_srcSystem() == 1]
        track = [(t, m.x, m.y) for t, m in self.gcs.timed("LOCAL_POSITION_NED") if m.get_srcSystem() == 2]
        if not homes or not track:
            return None
        h, r = np.asarray(homes), np.asarray(track)
        lagged = []
        for t, x, y in h:
            window = r[(r[:, 0] <= t) & (r[:, 0] >= t - lag_s)]
            if len(window):
                lagged.append(float(np.hypot(window[:, 1] - x, window[:, 2] - y).min()))
        last = r[np.searchsorted(r[:, 0], h[-1, 0], side="right") - 1]
        return {"homes": len(h), "moved_m": round(float(np.hypot(*(h[-1, 1:] - h[0, 1:]))), 3),
                "max_lagged_m": round(max(lagged), 3) if lagged else None,
                "final_m": round(float(np.hypot(*(h[-1, 1:] - last[1:]))), 3)}

    def text(self, name: str) -> str:
        path = self.dir / name
        return path.read_text(errors="replace") if path.exists() else ""

    def summary(self) -> dict[str, Any]:
        return json.loads((self.log_dir / "summary.json").read_text())

    def write_ground_truth(self) -> Path | None:
        """Write what the GCS link received of PX4's estimate and SIH's truth to ``truth.csv``
        (:mod:`sim.sitl.ground_truth`; the quadrotor's, sysid 1) and, with the rover, the rover's
        to ``truth-rover.csv``: its estimate in its own EKF frame, its truth projected about the
        quadrotor's EKF origin (one frame for both truths). None when not recorded."""
        if self.gcs is None or self.ground_truth_hz <= 0:
            return None
        from sim.sitl import ground_truth

        est, truth = ground_truth.series(self.gcs, system_id=PASSENGER_SYSID if self.rover else None)
        path = self.dir / "truth.csv"
        ground_truth.write_csv(path, est, truth)
        if self.rover:
            origin = ground_truth.ekf_origin(self.gcs, PASSENGER_SYSID)
            est, truth = ground_truth.series(self.gcs, system_id=ROVER_SYSID, origin=origin)
            ground_truth.write_csv(self.dir / "truth-rover.csv", est, truth)
        return path

    def close(self) -> None:
        for name in ("mission", "carrier"):
            if name in self.procs:
                stop_process(self.procs[name])
        if self.gcs is not None:
            with contextlib.suppress(LookupError):
                self.write_ground_truth()
            self.gcs.close()
        for px4 in (self.px4, self.rover_px4):
            if px4 is not None:
                px4.stop()
        if self.ns is not None:
            self.ns.close()
        for f in self._files:
            f.close()
        if self._rootfs is not None:
            shutil.rmtree(self._rootfs.parent, ignore_errors=True)


@contextlib.contextmanager
def px4_flight(directory: Path, config: Path, *, start: bool = True, **kwargs: Any) -> Iterator[Px4Flight]:
    """A :class:`Px4Flight` in ``directory``; everything it started is stopped on exit."""
    f = Px4Flight(dir=Path(directory), config=Path(config), **kwargs)
    try:
        if start:
            f.start()
        yield f
    finally:
        f.close()
