"""Vision's cost per 640x480 frame on one core: the renderer, the bare detector (OpenCV's
``detectMarkers`` alone: the floor), and detection + pose (``MarkerDetector.measure``), plus the
ways to go faster (a region of interest around the predicted tag, a decimated search, a single
threshold pass), each with its pose error against the truth.

    python -m bench.vision_cost [--frames 200] [--json out/bench_vision.json]
    python -m bench.vision_cost --descent     # what the bundle gives along a descent

p50/p95 of the thread's CPU time (``time.thread_time``: what the frame costs, whatever the
machine's load) and of the wall clock, in milliseconds; ``cv2.setNumThreads(1)``.
"""
from __future__ import annotations

import json
import os
import platform
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import click
import cv2
import numpy as np

from mission.vision.camera import CameraModel, Mount
from mission.vision.detect import MarkerDetector, predicted_roi, schema_settings
from mission.vision.frames import euler_quaternion, quaternion_matrix
from mission.vision.layout import MarkerLayout
from sim.camera.render import Poses, render, true_marker_pose
from sim.camera.sensor import Sensor, image_motion_px, sensor_model

CAMERA = CameraModel.from_fov(640, 480, 80.0, Mount.downward((0.05, 0.0, 0.08)))
HEIGHTS_M = (0.5, 1.0, 2.0, 4.0, 8.0)
TARGET_MS = 5.0


@dataclass
class Scene:
    poses: Poses
    image: np.ndarray

    @property
    def truth_m(self) -> np.ndarray:
        return np.asarray(self.poses.deck_ned_m) - np.asarray(self.poses.vehicle_ned_m)


def scenes(count: int, layout: MarkerLayout, seed: int = 0) -> list[Scene]:
    """``count`` frames: heights cycled over HEIGHTS_M, tilts up to 20 deg, any yaw, the deck
    within 10 % of the height of the optical axis, 2 grey levels of noise, 1 m/s of blur."""
    rng = np.random.default_rng(seed)
    sensor = Sensor(sensor_model(dropout_probability=0.0), seed=seed)
    out = []
    for i in range(count):
        h = HEIGHTS_M[i % len(HEIGHTS_M)]
        q = euler_quaternion(*np.radians([*rng.uniform(-20, 20, 2), rng.uniform(-180, 180)]))
        axis = quaternion_matrix(q) @ CAMERA.mount.rotation_body_cam[:, 2]
        deck = np.array([3.0, -2.0, 0.0])
        camera_ned = deck - axis * h / axis[2] - np.array([*rng.uniform(-0.1, 0.1, 2) * h, 0.0])
        poses = Poses(camera_ned - quaternion_matrix(q) @ CAMERA.mount.offset_body_m, q, deck, rng.uniform(-3, 3))
        marker = true_marker_pose(CAMERA, poses)
        blur = image_motion_px(CAMERA, marker, rng.normal(0, 1.0, 3), sensor.model.exposure_s)
        out.append(Scene(poses, sensor.expose(render(CAMERA, layout, marker), blur)))
    return out


def timed(work: Callable[[int], object], count: int) -> tuple[np.ndarray, np.ndarray, list]:
    """CPU and wall time [ms] of ``work(i)`` for i < count, and its results."""
    cpu, wall, results = [], [], []
    for i in range(count):
        c0, w0 = time.thread_time(), time.perf_counter()
        results.append(work(i))
        cpu.append(time.thread_time() - c0)
        wall.append(time.perf_counter() - w0)
    return np.array(cpu) * 1e3, np.array(wall) * 1e3, results


def row(name: str, cpu: np.ndarray, wall: np.ndarray, note: str = "") -> dict:
    return {"figure": name, "cpu_p50_ms": float(np.percentile(cpu, 50)), "cpu_p95_ms": float(np.percentile(cpu, 95)),
            "wall_p50_ms": float(np.percentile(wall, 50)), "wall_p95_ms": float(np.percentile(wall, 95)), "note": note}


def accuracy(results: list, frames: list[Scene]) -> str:
    errors = [np.linalg.norm(m.deck_rel_ned_m - s.truth_m) for m, s in zip(results, frames) if m is not None]
    seen = len(errors) / len(frames)
    return f"seen {seen:.0%}, error p50 {np.median(errors) * 100:.1f} cm, p95 {np.percentile(errors, 95) * 100:.1f} cm"


def run(count: int) -> list[dict]:
    cv2.setNumThreads(1)
    layout = MarkerLayout.bundle()
    frames = scenes(count, layout)
    rows = []
    sensor = Sensor(sensor_model(dropout_probability=0.0))
    cpu, wall, _ = timed(lambda i: render(CAMERA, layout, true_marker_pose(CAMERA, frames[i].poses)), count)
    rows.append(row("render (ideal frame)", cpu, wall))
    cpu, wall, _ = timed(lambda i: sensor.expose(render(CAMERA, layout, true_marker_pose(CAMERA, frames[i].poses)),
                                                 np.array([3.0, 1.0])), count)
    rows.append(row("render + noise + 3 px blur", cpu, wall))
    detector = MarkerDetector(CAMERA, layout)
    bare = detector._detector
    cpu, wall, _ = timed(lambda i: bare.detectMarkers(frames[i].image), count)
    rows.append(row("bare detectMarkers (the floor)", cpu, wall))
    variants = {
        "detection + pose": (schema_settings(), False),
        "  with a region of interest": (schema_settings(), True),
        "  decimated by 2": (schema_settings(decimate=2), False),
        "  one threshold pass (7 px)": (schema_settings(threshold_windows_px=(7, 7, 10)), False),
        "  ROI + one threshold pass": (schema_settings(threshold_windows_px=(7, 7, 10)), True),
    }
    for name, (settings, use_roi) in variants.items():
        d = MarkerDetector(CAMERA, layout, settings)
        # the ROI is the one the previous frame's pose predicts; here the truth stands in for it
        rois = [predicted_roi(CAMERA, layout, true_marker_pose(CAMERA, s.poses)) if use_roi else None for s in frames]
        cpu, wall, results = timed(lambda i: d.measure(frames[i].image, 0.0, frames[i].poses.attitude_q_wxyz, rois[i]), count)
        rows.append(row(name, cpu, wall, accuracy(results, frames)))
    return rows


def descent(seed: int = 0) -> list[dict]:
    """A vertical approach onto the bundle from 10 m to 0.25 m at 30 Hz (0.5 m/s down, a 1 m/s
    sway of the deck, +-10 deg of attitude wobble, +-0.15 m of lateral offset, 2 % dropouts, blur
    over a 5 ms exposure): per band of height, the share of frames measured, the tags used and
    the position error."""
    layout = MarkerLayout.bundle()
    detector = MarkerDetector(CAMERA, layout)
    sensor = Sensor(sensor_model(), seed=seed)
    rng = np.random.default_rng(seed)
    bands: dict[tuple[float, float], list] = {b: [] for b in ((4, 10.01), (2, 4), (1, 2), (0.5, 1), (0.25, 0.5))}
    h, t = 10.0, 0.0
    while h > 0.25:
        q = euler_quaternion(*np.radians([*rng.uniform(-10, 10, 2), 30.0]))
        offset = 0.15 * np.array([np.sin(t * 0.7), np.cos(t * 0.5)])
        poses = Poses(np.array([*(-offset), -h]), q, np.zeros(3), 0.2)
        marker = true_marker_pose(CAMERA, poses)
        velocity_cam = (quaternion_matrix(q) @ CAMERA.mount.rotation_body_cam).T @ np.array(
            [np.sin(t * 2.0), np.cos(t * 1.3), 0.5])
        image = sensor.expose(render(CAMERA, layout, marker), image_motion_px(CAMERA, marker, velocity_cam, 0.005))
        m = None if image is None else detector.measure(image, t, q)
        band = next(b for b in bands if b[0] <= h < b[1])
        truth = np.asarray(poses.deck_ned_m) - np.asarray(poses.vehicle_ned_m)
        bands[band].append(None if m is None else (m.tag_ids, float(np.linalg.norm(m.deck_rel_ned_m - truth))))
        h -= 0.5 / 30.0
        t += 1 / 30.0
    out = []
    for (lo, hi), results in bands.items():
        seen = [r for r in results if r is not None]
        errors = [e for _, e in seen]
        out.append({"band_m": f"{lo:g}-{hi:g}", "frames": len(results), "seen": len(seen) / len(results),
                    "tags": sorted({i for ids, _ in seen for i in ids}),
                    "error_p50_cm": float(np.median(errors) * 100) if errors else None,
                    "error_max_cm": float(np.max(errors) * 100) if errors else None})
    return out


@click.command()
@click.option("--frames", default=200, show_default=True, help="frames per figure")
@click.option("--descent", "descent_only", is_flag=True, help="instead: the bundle seen along a descent from 10 m to 0.25 m")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None, help="also write the rows here")
def main(frames: int, descent_only: bool, json_path: str | None) -> None:
    if descent_only:
        cv2.setNumThreads(1)
        for band in descent():
            print(band)
        return
    rows = run(frames)
    load = os.getloadavg()[0]
    print(f"vision cost per 640x480 frame, one core, {frames} frames (heights {HEIGHTS_M} m), "
          f"{platform.machine()}, OpenCV {cv2.__version__}, load {load:.1f}")
    print(f"{'figure':34} {'CPU p50':>8} {'p95':>7} {'wall p50':>9} {'p95':>7}  [ms]")
    for r in rows:
        mark = ""
        if r["figure"] == "detection + pose":
            mark = f"  target p50 <= {TARGET_MS} ms: {'pass' if r['cpu_p50_ms'] <= TARGET_MS else 'MISS'}"
        print(f"{r['figure']:34} {r['cpu_p50_ms']:8.2f} {r['cpu_p95_ms']:7.2f} {r['wall_p50_ms']:9.2f} "
              f"{r['wall_p95_ms']:7.2f}  {r['note']}{mark}")
    if json_path:
        Path(json_path).parent.mkdir(parents=True, exist_ok=True)
        Path(json_path).write_text(json.dumps({"load": load, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
