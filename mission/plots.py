"""The paper's figures (trajectories; the three distances over time) from a simulation or a flight.

Input is plain arrays so that ``marsupial simulate --plot`` and ``marsupial plot LOG`` draw the
same figure. In a ``local_ned`` frame the vertical axis is drawn as altitude (``-z``).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402

from mission.core.law import norm  # noqa: E402


@dataclass(frozen=True)
class Trajectories:
    """What a figure needs. t [s] (K,); x_c, x_p [m] (K, n); target [m] (n,); separation_time_s
    (or None); obstacles as (center, radius) pairs; frame "local_ned" or "xyz"."""

    t: np.ndarray
    x_c: np.ndarray
    x_p: np.ndarray
    target: np.ndarray
    separation_time_s: float | None
    obstacles: list[tuple[np.ndarray, float]]
    frame: str = "local_ned"
    title: str = ""
    bc_m: float | None = None


def _display(x: np.ndarray, frame: str) -> np.ndarray:
    """Coordinates as drawn: NED (n, e, d) -> (east, north, up); others unchanged."""
    if frame == "local_ned":
        out = np.stack([x[..., 1], x[..., 0]] + ([-x[..., 2]] if x.shape[-1] == 3 else []), axis=-1)
        return out
    return x


TIME_LABEL = "t [s] since the start of riding (t = 0 as in the paper)"

# |e_pc| and |e_tc| coincide on a carrier that stops at b c (both 8 m after separation in the
# paper's 3D run): each curve has its own line style and width, not only its own colour.
DISTANCE_STYLES = (
    ("e_pc", r"$\|e_{pc}\|$ passenger-carrier", dict(color="tab:orange", ls="-", lw=3.2, alpha=0.75)),
    ("e_tc", r"$\|e_{tc}\|$ carrier-target", dict(color="tab:blue", ls="--", lw=1.8)),
    ("e_pt", r"$\|e_{pt}\|$ passenger-target", dict(color="tab:green", ls="-.", lw=1.5)),
)


def plot_run(tr: Trajectories, path: str | Path) -> Path:
    """Write a two-panel PNG/PDF/SVG (by suffix): trajectories, and |e_pc|, |e_tc|, |e_pt| over time.

    Every drawn element is in a legend: carrier and passenger paths, carrier start and end,
    target, separation point, obstacles and the b c circle (2D); in the distance panel the three
    distances (distinct line styles), the separation instant and the b c level. Time runs from
    the start of riding (t = 0).
    """
    path = Path(path)
    n = tr.x_c.shape[-1]
    fig = plt.figure(figsize=(12, 5.2))
    ax = fig.add_subplot(1, 2, 1, projection="3d" if n == 3 else None)
    c, p, tgt = _display(tr.x_c, tr.frame), _display(tr.x_p, tr.frame), _display(tr.target, tr.frame)
    labels = ("east [m]", "north [m]", "up [m]") if tr.frame == "local_ned" else ("x [m]", "y [m]", "z [m]")
    sep_i = None if tr.separation_time_s is None else int(np.searchsorted(tr.t, tr.separation_time_s))
    sep_i = None if sep_i is None or sep_i >= len(c) else sep_i
    z = {} if n == 3 else {"zorder": 5}
    ax.plot(*c.T, color="tab:blue", lw=2, label="carrier")
    ax.plot(*p.T, color="tab:orange", lw=1.5, ls="--", label="passenger")
    ax.scatter(*tgt, color="red", marker="*", s=160, label="target", **z)
    ax.scatter(*c[0], color="tab:blue", marker="s", s=50, label="carrier start", **z)
    ax.scatter(*c[-1], facecolor="white", edgecolor="tab:blue", marker="X", s=90, lw=1.5, label="carrier end", **z)
    if sep_i is not None:
        ax.scatter(*c[sep_i], color="magenta", marker="o", s=60, label="separation (carrier)", **z)
    if n == 3:
        ax.set_zlabel(labels[2])
    else:
        for i, (centre, radius) in enumerate(tr.obstacles):
            ax.add_patch(Circle(_display(np.asarray(centre), tr.frame)[:2], radius, color="grey", alpha=0.5,
                                label="obstacle" if i == 0 else None))
        if tr.bc_m:
            ax.add_patch(Circle(tgt[:2], tr.bc_m, fill=False, ls=":", color="red", alpha=0.6,
                                label=f"b·c = {tr.bc_m:g} m around the target"))
        ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    ax.set_title("trajectories")
    ax.legend(loc="best", fontsize=8)

    ax2 = fig.add_subplot(1, 2, 2)
    d = {"e_pc": norm(tr.x_p - tr.x_c), "e_tc": norm(tr.target - tr.x_c), "e_pt": norm(tr.x_p - tr.target)}
    for key, label, style in DISTANCE_STYLES:
        ax2.plot(tr.t, d[key], label=label, **style)
    if tr.separation_time_s is not None:
        ax2.axvline(tr.separation_time_s, color="magenta", ls=":", label=f"separation, t = {tr.separation_time_s:.2f} s")
    if tr.bc_m:
        ax2.axhline(tr.bc_m, color="grey", ls=(0, (1, 3)), lw=1.0, label=f"b·c = {tr.bc_m:g} m")
    ax2.set_xlabel(TIME_LABEL)
    ax2.set_ylabel("distance [m]")
    ax2.set_title("distances")
    ax2.grid(alpha=0.3)
    ax2.legend(fontsize=8)
    if tr.title:
        fig.suptitle(tr.title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
