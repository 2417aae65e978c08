"""SIH's true state beside PX4's estimate, from a PX4 SITL's own MAVLink streams.

PX4's SIH publishes its true state on the ``vehicle_*_groundtruth`` topics, and PX4's MAVLink
module streams them as HIL_STATE_QUATERNION (its ``GROUND_TRUTH`` stream: true latitude,
longitude, altitude and NED velocity; ``time_usec`` is left 0) when asked with
SET_MESSAGE_INTERVAL. Ask it together with LOCAL_POSITION_NED (the estimate) on one link and
both arrive on the same socket: their receive times put them on one clock.

The true position is projected about PX4's EKF origin (GPS_GLOBAL_ORIGIN) with PX4's own
projection, so it lies in the estimate's local NED frame; what remains between them is the
estimate's error (its origin's offset included). Units: [m], [m/s], NED; times [s] on the
receiver's clock.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np

from mission.core.geodesy import project
from mission.mavlink import px4

HIL_STATE_QUATERNION_ID = 115
LOCAL_POSITION_NED_ID = 32
GPS_GLOBAL_ORIGIN_ID = 49
COLUMNS = ("t_rx_s", "boot_s", "x", "y", "z", "vx", "vy", "vz", "true_x", "true_y", "true_z", "true_vx", "true_vy", "true_vz")


def ask(probe: Any, rate_hz: float, system_id: int = 1, gcs_port: int | None = None) -> dict[int, Any]:
    """Ask PX4 (over ``probe``'s link) for its estimate and its ground truth at ``rate_hz`` and for
    its EKF origin; returns the COMMAND_ACK result per message id (None: no answer). Several PX4s on
    one link: ``system_id`` is the one asked and ``gcs_port`` the port its GCS link listens on
    (18570 + its instance; None: the probe's vehicle)."""
    vehicle = probe.vehicle
    if gcs_port is not None:
        probe.vehicle = ("127.0.0.1", gcs_port)
    target = (system_id, 1)
    results: dict[int, Any] = {}
    try:
        for msg_id in (LOCAL_POSITION_NED_ID, HIL_STATE_QUATERNION_ID):
            ack = probe.command(px4.MAV_CMD_SET_MESSAGE_INTERVAL, (msg_id, 1e6 / rate_hz), target=target)
            results[msg_id] = None if ack is None else ack.result
        ack = probe.command(px4.MAV_CMD_REQUEST_MESSAGE, (GPS_GLOBAL_ORIGIN_ID,), target=target)
        results[GPS_GLOBAL_ORIGIN_ID] = None if ack is None else ack.result
    finally:
        probe.vehicle = vehicle
    return results


def series(probe: Any, system_id: int | None = None,
           origin: tuple[float, float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(estimate, truth) received so far: rows ``t_rx, boot, x, y, z, vx, vy, vz`` (the truth's
    boot time NaN) in PX4's local NED frame. ``system_id``: only that PX4's messages (several
    PX4s on one link; None: all). ``origin``: project the truth about this latitude, longitude
    [deg] and altitude [m] instead of the PX4's own EKF origin (several PX4s' truths in one frame).
    Raises LookupError without an EKF origin."""
    def mine(entries: Any) -> list[Any]:
        return [e for e in entries if system_id is None or e[2].get_srcSystem() == system_id]

    with probe._cond:  # the probe's thread keeps receiving
        lps = mine(probe.history.get("LOCAL_POSITION_NED", ()))
        hils = mine(probe.history.get("HIL_STATE_QUATERNION", ()))
    if origin is None:
        origin = ekf_origin(probe, system_id)
    return rows([(t, m) for _, t, m in lps], [(t, m) for _, t, m in hils], origin)


def ekf_origin(probe: Any, system_id: int | None = None) -> tuple[float, float, float]:
    """The EKF origin (latitude, longitude [deg], altitude [m]) that PX4 ``system_id`` (None: any)
    last sent on ``probe``'s link; raises LookupError without one."""
    with probe._cond:  # the probe's thread keeps receiving
        origins = [m for _, _, m in probe.history.get("GPS_GLOBAL_ORIGIN", ())
                   if system_id is None or m.get_srcSystem() == system_id]
    if not origins:
        raise LookupError(f"no GPS_GLOBAL_ORIGIN received{'' if system_id is None else f' from system {system_id}'}: "
                          "PX4's EKF origin is unknown")
    msg = origins[-1]
    return msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3


def rows(estimates: list[tuple[float, Any]], truths: list[tuple[float, Any]],
         origin: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """(estimate, truth) rows as :func:`series` returns them, from (receive time [s], message)
    pairs of LOCAL_POSITION_NED and HIL_STATE_QUATERNION, the truth projected about ``origin``
    (latitude, longitude [deg], altitude [m])."""
    est = np.array([(t, m.time_boot_ms * 1e-3, m.x, m.y, m.z, m.vx, m.vy, m.vz) for t, m in estimates]).reshape(-1, 8)
    lat0, lon0, alt0 = origin
    out = []
    for t, m in truths:
        n, e = project(m.lat * 1e-7, m.lon * 1e-7, lat0, lon0)
        out.append((t, math.nan, n, e, -(m.alt * 1e-3 - alt0), m.vx * 0.01, m.vy * 0.01, m.vz * 0.01))
    return est, np.array(out).reshape(-1, 8)


def aligned(est: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """The truth interpolated to each estimate row's receive time: shape (len(est), 6)
    ``x, y, z, vx, vy, vz`` (NaN without truth)."""
    if len(truth) < 2:
        return np.full((len(est), 6), math.nan)
    return np.column_stack([np.interp(est[:, 0], truth[:, 0], truth[:, k]) for k in range(2, 8)])


def write_csv(path: Path, est: np.ndarray, truth: np.ndarray) -> None:
    """One row per estimate sample with the truth at its receive time (:data:`COLUMNS`)."""
    tr = aligned(est, truth)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for row, t in zip(est, tr):
            w.writerow([f"{row[0]:.4f}", f"{row[1]:.3f}", *[f"{v:.4f}" for v in row[2:]], *[f"{v:.4f}" for v in t]])


def read_csv(path: Path) -> dict[str, np.ndarray]:
    """A :func:`write_csv` file as columns."""
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        data = np.array([[float(x) for x in row] for row in reader]).reshape(-1, len(header))
    return {name: data[:, i] for i, name in enumerate(header)}
