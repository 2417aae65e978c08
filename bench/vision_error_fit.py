"""Fits the batch's detection-error model (:class:`sim.camera.error_model.DetectionErrorModel`) to
the real detector's errors on rendered frames, and measures the fit on frames it has not seen
(other seeds, and a tag of another size).

    python -m bench.vision_error_fit [--frames 400]

Prints the fitted model (the coefficients ``sim.camera.error_model.FITTED`` holds), then per bin
of the tag's apparent side: the detector's relative error along the line of sight (mean, std)
and across it beside the model's; the share of normalised errors within 1 and 2 sigma (a
Gaussian: 68 % / 95 %); and how often the model and the detector agree that a frame is seen.
"""
from __future__ import annotations

import click
import cv2
import numpy as np

from mission.vision.detect import MarkerDetector
from mission.vision.frames import euler_quaternion, quaternion_matrix
from mission.vision.layout import MarkerLayout
from sim.camera.error_model import FITTED, DetectionErrorModel, apparent_side_px
from sim.camera.render import Poses, render, true_marker_pose
from sim.camera.sensor import Sensor, sensor_model
from bench.vision_cost import CAMERA


def samples(count: int, layout: MarkerLayout, seed: int) -> np.ndarray:
    """Rows (side_px or nan, seen by the detector, distance, along error, across error 1, 2) [px, -, m, m, m, m]."""
    rng = np.random.default_rng(seed)
    detector = MarkerDetector(CAMERA, layout)
    sensor = Sensor(sensor_model(dropout_probability=0.0), seed=seed)
    rows = []
    for _ in range(count):
        h = float(np.exp(rng.uniform(np.log(0.6), np.log(12.0))))
        q = euler_quaternion(*np.radians([*rng.uniform(-20, 20, 2), rng.uniform(-180, 180)]))
        axis = quaternion_matrix(q) @ CAMERA.mount.rotation_body_cam[:, 2]
        camera_ned = -axis * h / axis[2] - np.array([*rng.uniform(-0.3, 0.3, 2) * h, 0.0])
        poses = Poses(camera_ned - quaternion_matrix(q) @ CAMERA.mount.offset_body_m, q, np.zeros(3), rng.uniform(-3, 3))
        marker = true_marker_pose(CAMERA, poses)
        m = detector.measure(sensor.expose(render(CAMERA, layout, marker)), 0.0, q)
        seen = apparent_side_px(CAMERA, layout, marker)
        t = marker.deck_in_cam_m
        u = t / np.linalg.norm(t)
        a = np.cross(u, [1.0, 0.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(u, a)
        e = (m.marker.deck_in_cam_m - t) if m is not None else np.full(3, np.nan)
        rows.append([seen[0] if seen else np.nan, m is not None, np.linalg.norm(t), e @ u, e @ a, e @ b])
    return np.array(rows)


def binned(rows: np.ndarray, bins: int) -> list[tuple[float, float, float, float, int]]:
    """Per quantile bin of side_px among detected frames: (median side, mean along/d, std along/d,
    rms across/d per axis, count)."""
    ok = rows[:, 1] > 0
    r = rows[ok & ~np.isnan(rows[:, 0])]
    edges = np.quantile(r[:, 0], np.linspace(0, 1, bins + 1))
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        s = r[(r[:, 0] >= lo) & (r[:, 0] <= hi)]
        along, across = s[:, 3] / s[:, 2], s[:, 4:6] / s[:, 2:3]
        out.append((float(np.median(s[:, 0])), float(along.mean()), float(along.std()),
                    float(np.sqrt(np.mean(across ** 2))), len(s)))
    return out


def power_law(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """(k, p) of y = k x^-p, least squares in logs."""
    p, logk = np.polyfit(np.log(x), np.log(np.maximum(y, 1e-12)), 1)
    return float(np.exp(logk)), float(-p)


def fit(rows: np.ndarray, bins: int = 10) -> DetectionErrorModel:
    b = np.array(binned(rows, bins))
    bias, bias_p = power_law(b[:, 0], np.maximum(b[:, 1], 1e-7))
    sigma, sigma_p = power_law(b[:, 0], b[:, 2])
    across, across_p = power_law(b[:, 0], b[:, 3])
    return DetectionErrorModel(bias, bias_p, sigma, sigma_p, across, across_p, FITTED.min_side_px)


def report(model: DetectionErrorModel, rows: np.ndarray, name: str) -> None:
    print(f"\n{name}: {len(rows)} frames")
    print(f"{'side px':>8} {'n':>4} {'along mean %':>13} {'model':>7} {'along std %':>12} {'model':>7} {'across %':>9} {'model':>7}")
    for side, mean, std, across, n in binned(rows, 6):
        pm, ps, pa = model.predicted(side)
        print(f"{side:8.1f} {n:4d} {mean * 100:13.3f} {pm * 100:7.3f} {std * 100:12.3f} {ps * 100:7.3f} "
              f"{across * 100:9.4f} {pa * 100:7.4f}")
    ok = (rows[:, 1] > 0) & ~np.isnan(rows[:, 0])
    r = rows[ok]
    pm, ps, pa = (np.array(v) for v in zip(*(model.predicted(s) for s in r[:, 0])))
    z_along = (r[:, 3] / r[:, 2] - pm) / ps
    z_across = (r[:, 4:6] / r[:, 2:3]) / pa[:, None]
    print(f"within 1 / 2 sigma: along {np.mean(abs(z_along) < 1):.0%} / {np.mean(abs(z_along) < 2):.0%}, "
          f"across {np.mean(abs(z_across) < 1):.0%} / {np.mean(abs(z_across) < 2):.0%} (Gaussian: 68 % / 95 %)")
    model_seen = ~np.isnan(rows[:, 0]) & (np.nan_to_num(rows[:, 0]) >= model.min_side_px)
    agree = np.mean(model_seen == (rows[:, 1] > 0))
    print(f"seen: detector {np.mean(rows[:, 1] > 0):.0%}, model {np.mean(model_seen):.0%}, agree on {agree:.0%} of frames")


@click.command()
@click.option("--frames", default=400, show_default=True)
def main(frames: int) -> None:
    cv2.setNumThreads(1)
    single = MarkerLayout.single(0.5)
    model = fit(samples(frames, single, seed=1))
    print(f"fitted on {frames} frames (0.5 m tag, 0.6-12 m, tilts to 20 deg):\n{model!r}")
    report(model, samples(frames // 2, single, seed=2), "held out: 0.5 m tag, other poses")
    report(model, samples(frames // 2, MarkerLayout.single(0.3), seed=3), "held out: 0.3 m tag")
    report(FITTED, samples(frames // 2, single, seed=2), "the stored FITTED, same held-out frames")


if __name__ == "__main__":
    main()
