"""A still of the shipped Foxglove layout (:mod:`mission.flightdata.layout`) drawn from a
``flight.mcap`` with matplotlib: for a reader without Foxglove, and for the docs.

The panels show what the layout's panels show, from the same channels: the 3D scene at the last
tick (ENU ``map`` frame: east, north, up), with both robots' paths; the phase and the safety
filter's activity; the distances with b c; the law's and the safe command with the filter's
change; the log. The time axis is the mission clock [s], as Foxglove shows the file's.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from mission.flightdata.mission_log import bc_circle
from mission.flightdata.read import RECORD_SCHEMA, log_lines, read_messages
from mission.phases.phase import Phase
from mission.record.table import read_record

BG, PANEL, GRID, TEXT = "#16161d", "#1f1f29", "#33334a", "#e6e6f0"


def _json_series(content: Any, topic: str) -> tuple[np.ndarray, list[dict[str, Any]]]:
    rows = [((t - content.epoch_ns) / 1e9, json.loads(d)) for top, _, t, d in content.messages if top == topic]
    return np.array([t for t, _ in rows]), [r for _, r in rows]


def _values(rows: list[dict[str, Any]], *path: str) -> np.ndarray:
    out = []
    for r in rows:
        v: Any = r
        for key in path:
            v = None if v is None else v.get(key)
        out.append(np.nan if v is None else float(v))
    return np.array(out)


def _enu(x: np.ndarray) -> np.ndarray:
    """NED (..., 3) -> ENU (east, north, up)."""
    return np.stack([x[..., 1], x[..., 0], -x[..., 2]], axis=-1)


def _panel(ax: Any, title: str) -> None:
    ax.set_facecolor(PANEL)
    ax.set_title(title, color=TEXT, fontsize=9, loc="left")
    ax.tick_params(colors=TEXT, labelsize=7)
    for side in ax.spines.values():
        side.set_color(GRID)
    ax.grid(color=GRID, lw=0.5)


def draw_panels(mcap_path: str | Path, out_path: str | Path) -> Path:
    """Draw the layout's panels from the flight in ``mcap_path`` into ``out_path`` (PNG by suffix)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    content = read_messages(mcap_path)
    rec = read_record(mcap_path)
    pair = next(top.split("/")[1] for top, schema, _, _ in content.messages if schema == RECORD_SCHEMA)
    info = rec.info
    fig = plt.figure(figsize=(16, 9), dpi=100, facecolor=BG)
    grid = fig.add_gridspec(6, 5, left=0.01, right=0.985, top=0.93, bottom=0.05, hspace=0.55, wspace=0.25)
    fig.suptitle(f"{Path(mcap_path).parent.name}/{Path(mcap_path).name}: the Foxglove layout configs/foxglove/"
                 f"marsupial.json, drawn from the MCAP (mission clock)", color=TEXT, fontsize=10, x=0.01,
                 ha="left", y=0.985)

    # 3D: paths, robots at the last tick, target, obstacles, b c circle, dock, anchor
    ax = fig.add_subplot(grid[:, :3], projection="3d", facecolor=PANEL)
    ax.set_title(f"3D  /{pair}/scene, /{pair}/tf/*  (map = ENU over world = NED)", color=TEXT, fontsize=9, loc="left",
                 y=0.97)
    x_p, x_c, dock = _enu(rec.vec("x_p")), _enu(rec.vec("x_c")), _enu(rec.vec("dock"))
    ax.plot(*x_c.T, color="#9a9aae", lw=1.5, label="carrier")
    ax.plot(*x_p.T, color="#4e98e2", lw=1.8, label="passenger")
    last_c = x_c[np.isfinite(x_c).all(axis=1)][-1]
    ax.bar3d(last_c[0] - 0.4, last_c[1] - 0.6, last_c[2] - 0.2, 0.8, 1.2, 0.4, color="#8c8ca0", shade=True)
    ax.scatter(*x_p[-1], s=120, color="#3a7bd5", edgecolor="white", depthshade=False)
    last_dock = dock[np.isfinite(dock).all(axis=1)][-1]
    ax.scatter(*last_dock, s=30, color="#ffd91a", depthshade=False, label="dock point")
    target = _enu(np.asarray(info["target_ned_m"], dtype=float))
    ax.scatter(*target, s=160, color="#e51a1a", depthshade=False, label="target")
    ax.text(*(target + [0, 0, 0.8]), "target", color=TEXT, fontsize=8)
    circle = _enu(bc_circle(info))
    ax.plot(*np.vstack([circle, circle[:1]]).T, color="#e69a1a", lw=1.5, label=f"b c = {info['bc_m']:g} m")
    if info.get("anchor_ned_m") is not None:
        anchor = _enu(np.asarray(info["anchor_ned_m"], dtype=float))
        ax.scatter(*anchor, s=50, color="#1acc4d", depthshade=False, label="anchor")
        ax.text(*(anchor + [0, 0, 0.8]), "anchor", color=TEXT, fontsize=8)
    u, v = np.mgrid[0:2 * np.pi:16j, 0:np.pi:8j]
    for o in info.get("obstacles", []):
        c, r = _enu(np.asarray(o["center"], dtype=float)), float(o["radius"])
        ax.plot_wireframe(c[0] + r * np.cos(u) * np.sin(v), c[1] + r * np.sin(u) * np.sin(v), c[2] + r * np.cos(v),
                          color="#f0661a", lw=0.5, alpha=0.6)
    for axis, name, color in ((np.array([0, 2.0, 0]), "N", "#e55"), (np.array([2.0, 0, 0]), "E", "#5e5"),
                              (np.array([0, 0, -2.0]), "D", "#58f")):
        ax.quiver(0, 0, 0, *axis, color=color, lw=1.5)
        ax.text(*(axis * 1.2), name, color=color, fontsize=8)
    ax.set_xlabel("east [m]", color=TEXT, fontsize=8)
    ax.set_ylabel("north [m]", color=TEXT, fontsize=8)
    ax.set_zlabel("up [m]", color=TEXT, fontsize=8)
    ax.tick_params(colors=TEXT, labelsize=7)
    for pane in (ax.xaxis, ax.yaxis, ax.zaxis):
        pane.set_pane_color((0.12, 0.12, 0.16, 1.0))
    pts = np.vstack([x_p, x_c, target[None], circle])
    span = np.nanmax(pts, axis=0) - np.nanmin(pts, axis=0)
    ax.set_box_aspect((span[0], span[1], max(span[2], 0.3 * max(span[0], span[1]))))
    ax.view_init(elev=24, azim=-62)
    ax.legend(loc="upper right", fontsize=8, facecolor=PANEL, labelcolor=TEXT, edgecolor=GRID)

    # phase and safety filter (state transitions)
    ax = fig.add_subplot(grid[0, 3:])
    _panel(ax, f"phase and safety filter  /{pair}/phase.phase, /{pair}/safety.acted")
    t_ph, phase_rows = _json_series(content, f"/{pair}/phase")
    names = [r["phase"] for r in phase_rows]
    starts = [i for i in range(len(names)) if i == 0 or names[i] != names[i - 1]]
    for k, i in enumerate(starts):
        end = t_ph[starts[k + 1]] if k + 1 < len(starts) else t_ph[-1]
        colour = Phase[names[i]].colour if names[i] in Phase.__members__ else GRID  # (a phase we no longer have)
        ax.broken_barh([(t_ph[i], end - t_ph[i])], (1.1, 0.8), color=colour)
        if end - t_ph[i] > 0.08 * (t_ph[-1] - t_ph[0]):  # room for the name
            ax.text(t_ph[i] + 0.1, 1.5, names[i], fontsize=6.5, va="center", color="black")
    t_sf, safety = _json_series(content, f"/{pair}/safety")
    acted = np.array([bool(r["acted"]) for r in safety])
    dt = float(np.median(np.diff(t_sf))) if len(t_sf) > 1 else 0.02
    ax.broken_barh([(t, dt) for t in t_sf[acted]], (0.1, 0.8), color="#f05b5b")
    ax.set_yticks([0.5, 1.5], ["filter acted", "phase"], color=TEXT)
    ax.set_ylim(0, 2)

    # distances
    ax = fig.add_subplot(grid[1:3, 3:])
    _panel(ax, f"distances [m]  /{pair}/distances (the law's carrier is the dock point)")
    t_d, dist = _json_series(content, f"/{pair}/distances")
    for key, label, color, style in (("e_pc_m", "|e_pc|", "#4e98e2", "-"), ("e_tc_m", "|e_tc|", "#f5774d", "-"),
                                     ("e_pt_m", "|e_pt|", "#61cbff", "-"), ("bc_m", "b c", "#f7df71", "--")):
        ax.plot(t_d, _values(dist, key), color=color, ls=style, lw=1.4, label=label)
    ax.legend(fontsize=7, ncol=4, loc="upper right", facecolor=PANEL, labelcolor=TEXT, edgecolor=GRID)

    # command and filter
    ax = fig.add_subplot(grid[3:5, 3:])
    _panel(ax, f"command [m/s]  /{pair}/command (law dashed, safe solid), /{pair}/safety.change_m_s")
    t_c, cmd = _json_series(content, f"/{pair}/command")
    for name, color in (("n", "#4e98e2"), ("e", "#f5774d")):
        ax.plot(t_c, _values(cmd, "law", name), color=color, ls="--", lw=1.2, label=f"law {name}")
        ax.plot(t_c, _values(cmd, "safe", name), color=color, lw=1.4, label=f"safe {name}")
    ax.plot(t_sf, _values(safety, "change_m_s"), color="#9cd86b", lw=1.0, label="|safe - law|")
    ax.legend(fontsize=7, ncol=5, loc="upper right", facecolor=PANEL, labelcolor=TEXT, edgecolor=GRID)
    ax.set_xlabel("mission clock [s]", color=TEXT, fontsize=8)

    # log
    ax = fig.add_subplot(grid[5, 3:])
    _panel(ax, f"log  /{pair}/log")
    ax.grid(False)
    ax.set_xticks([])
    ax.set_yticks([])
    lines = log_lines(content, f"/{pair}/log")
    shown = [f"{t:7.2f}  {'INFO' if level == 2 else 'ERROR' if level == 4 else 'WARN'}  {text}" for t, level, text in lines][-12:]
    half = (len(shown) + 1) // 2
    for col, chunk in enumerate((shown[:half], shown[half:])):
        ax.text(0.005 + 0.5 * col, 0.95, "\n".join(chunk), family="monospace", fontsize=6.5, color=TEXT, va="top",
                transform=ax.transAxes)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, facecolor=BG)
    plt.close(fig)
    return out
