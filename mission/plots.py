"""The paper's figures (trajectories; the three distances over time) from a simulation or a
flight, the recovery's (the approach in the carrier's frame; distances with the phases), and a
team's (every passenger's track from above; the passengers' distances over time).

Input is plain arrays so that ``marsupial simulate --plot`` and ``marsupial plot LOG`` draw the
same figure. In a ``local_ned`` frame the vertical axis is drawn as altitude (``-z``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Circle, Rectangle  # noqa: E402

from mission.core.docking import DockingGeometry, course  # noqa: E402
from mission.core.law import norm  # noqa: E402
from mission.phases.phase import HOMEWARD, Phase  # noqa: E402

if TYPE_CHECKING:
    from mission.flightdata.read import TeamRecord
    from mission.record.table import FlightRecord


@dataclass(frozen=True)
class Trajectories:
    """What a figure needs. t [s] (K,); x_c, x_p [m] (K, n); target [m] (n,), or (K, n) for a
    flight of several targets (each tick's own leg's target: the distances are measured to it);
    separation_time_s (or None); obstacles as (center, radius) pairs; frame "local_ned" or "xyz"."""

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
    c, p = _display(tr.x_c, tr.frame), _display(tr.x_p, tr.frame)
    targets = np.unique(np.atleast_2d(tr.target), axis=0)  # each target once, for drawing
    several = len(targets) > 1
    labels = ("east [m]", "north [m]", "up [m]") if tr.frame == "local_ned" else ("x [m]", "y [m]", "z [m]")
    sep_i = None if tr.separation_time_s is None else int(np.searchsorted(tr.t, tr.separation_time_s))
    sep_i = None if sep_i is None or sep_i >= len(c) else sep_i
    z = {} if n == 3 else {"zorder": 5}
    ax.plot(*c.T, color="tab:blue", lw=2, label="carrier")
    ax.plot(*p.T, color="tab:orange", lw=1.5, ls="--", label="passenger")
    for i, target in enumerate(targets):
        ax.scatter(*_display(target, tr.frame), color="red", marker="*", s=160,
                   label=("targets" if several else "target") if i == 0 else None, **z)
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
        for i, target in enumerate(targets if tr.bc_m else []):
            ax.add_patch(Circle(_display(target, tr.frame)[:2], tr.bc_m, fill=False, ls=":", color="red", alpha=0.6,
                                label=f"b·c = {tr.bc_m:g} m around the target{'s' if several else ''}" if i == 0 else None))
        ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    ax.set_title("trajectories")
    ax.legend(loc="best", fontsize=8)

    ax2 = fig.add_subplot(1, 2, 2)
    d = {"e_pc": norm(tr.x_p - tr.x_c), "e_tc": norm(tr.target - tr.x_c), "e_pt": norm(tr.x_p - tr.target)}
    for key, label, style in DISTANCE_STYLES:
        ax2.plot(tr.t, d[key], label=label + (" (its leg's)" if several and key != "e_pc" else ""), **style)
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


def record_trajectories(rec: FlightRecord, title: str, whole_flight: bool = False) -> Trajectories | None:
    """The paper figure's input from a flight record (``record.csv`` of a flight, or a simulated
    one): the carrier drawn as its dock point (the law's carrier position for the passenger),
    its target (``info["target_ned_m"]``; ``whole_flight`` with several targets: each tick's own
    leg's, cut at the legs' ends ``info["legs_done"][k]["end_s"]``), time from its first RIDING
    tick (t = 0 as in the paper; the first tick with both positions if it never rode). None: no
    tick has both."""
    x_p, x_c = rec.vec("x_p"), rec.vec("dock")
    ok = np.isfinite(x_p).all(axis=1) & np.isfinite(x_c).all(axis=1)
    if not ok.any():
        return None
    riding = np.flatnonzero(rec.phase == "RIDING")
    t0 = rec.t[riding[0]] if len(riding) else rec.t[ok][0]
    origin = "start of riding" if len(riding) else "first tick with both positions (never rode)"
    sep, info = rec.info.get("separation_time_s"), rec.info
    target = np.asarray(info["target_ned_m"])
    targets = info.get("targets") or []
    if whole_flight and len(targets) > 1:
        ends = [leg["end_s"] for leg in info.get("legs_done") or []]
        leg = np.minimum(np.searchsorted(ends, rec.t[ok], side="left"), len(targets) - 1)
        target = np.asarray(targets, dtype=float)[leg]
    return Trajectories(t=rec.t[ok] - t0, x_c=x_c[ok], x_p=x_p[ok], target=target,
                        separation_time_s=None if sep is None else sep - t0,
                        obstacles=[(np.asarray(o["center"]), o["radius"]) for o in info.get("obstacles", [])],
                        frame=info.get("frame", "local_ned"),
                        title=f"{title} (carrier = its dock point; t = 0 at the {origin}, mission clock {t0:.2f} s)",
                        bc_m=info.get("bc_m"))


def plot_legs(rec: FlightRecord, beside: Path, title: str) -> list[Path]:
    """A flight of several targets: each flown leg's paper figure, judged against its own target
    (:meth:`~mission.record.table.FlightRecord.legs`), at ``<stem>-leg<k><suffix>`` beside ``beside``
    (k from 1). Empty for a one-target flight."""
    if len(rec.info.get("targets") or []) < 2:
        return []
    out: list[Path] = []
    for leg in rec.legs():
        tr = None if leg.record is None else record_trajectories(leg.record, f"{title}, leg {leg.k + 1}")
        if tr is not None:
            out.append(plot_run(tr, beside.with_name(f"{beside.stem}-leg{leg.k + 1}{beside.suffix}")))
    return out


# ----------------------------------------------------------------------------------------- recovery

#: The phases shaded (in their :attr:`~mission.phases.phase.Phase.colour`) in the recovery's distance panel.
SHADED = HOMEWARD | {Phase.ARRIVED}
SHADE_ALPHA = 0.35  # the shading's opacity: the curves stay readable over it
ATTEMPT_COLOURS = ("tab:green", "tab:orange", "tab:purple", "tab:brown", "tab:pink")


@dataclass(frozen=True)
class RecoveryTrack:
    """What the recovery's figure needs, from a flight log or a simulation.

    t [s] (K,); phase (K,) the phase names; x_p [m] (K, 3) the vehicle, dock [m] (K, 3) the dock
    point, both NED; course (K, 3) the carrier's course as the recovery saw it (a horizontal unit
    vector NED; NaN before the recovery); geometry the recovery's
    :class:`~mission.core.docking.DockingGeometry`; deck_radius_m [m]; contact the contact
    figures (summary.json's ``contact``) or None; outcome ("docked", "fallback: ..."); title."""

    t: np.ndarray
    phase: np.ndarray
    x_p: np.ndarray
    dock: np.ndarray
    course: np.ndarray
    geometry: DockingGeometry
    deck_radius_m: float
    contact: dict | None = None
    outcome: str = ""
    title: str = ""

    def in_carrier_frame(self) -> np.ndarray:
        """(K, 3): the vehicle relative to the dock point along the course, to its right and up [m]."""
        r = self.x_p - self.dock
        c = self.course
        along = r[:, 0] * c[:, 0] + r[:, 1] * c[:, 1]
        right = -r[:, 0] * c[:, 1] + r[:, 1] * c[:, 0]
        return np.stack([along, right, -r[:, 2]], axis=-1)

    def attempts(self) -> np.ndarray:
        """(K,) int: the approach each tick belongs to (1, 2, ...; the go-around and the holdoff
        after an approach belong to it), 0 before the first."""
        entered = (self.phase == Phase.APPROACH) & np.concatenate([[True], self.phase[1:] != self.phase[:-1]])
        return np.cumsum(entered)


def recovery_track(rec, title: str = "") -> RecoveryTrack | None:
    """The :class:`RecoveryTrack` of a :class:`mission.record.table.FlightRecord` (None: no recovery
    in it). A flight log holds no course: it is rebuilt as the recovery keeps it, the direction
    of the carrier's velocity while it moves faster than
    :data:`~mission.core.docking.COURSE_MIN_SPEED_M_S`, else the last one, starting from the
    direction the holdoff point lay in (behind the dock point) when the first approach began."""
    params = rec.info.get("recovery")
    recovering = np.isin(rec.phase, sorted(HOMEWARD))
    if params is None or not recovering.any():
        return None
    g = DockingGeometry(
        holdoff_distance_m=params["holdoff_distance_m"], glide_angle_rad=math.radians(params["glide_angle_deg"]),
        cone_half_angle_rad=math.radians(params["cone_half_angle_deg"]), cone_min_radius_m=params["cone_min_radius_m"],
        decision_height_m=params["decision_height_m"], contact_radius_m=params["contact_radius_m"],
        contact_height_m=params["contact_height_m"],
        contact_max_horizontal_speed_m_s=params["contact_max_horizontal_speed_m_s"],
        contact_max_vertical_speed_m_s=params["contact_max_vertical_speed_m_s"])
    if "course_n" in rec.cols:
        course_ned = rec.vec("course")
    else:
        course_ned = _rebuilt_course(rec, recovering, g)
    start = max(int(np.argmax(recovering)) - int(2.0 / max(float(np.median(np.diff(rec.t))), 1e-3)), 0)
    keep = np.arange(len(rec.t)) >= start
    recovered = rec.info.get("recovered") or {}
    contact = recovered.get("contact")
    outcome = "docked" if contact else (f"fallback: {recovered['fallback']}" if recovered.get("fallback") else "")
    return RecoveryTrack(t=rec.t[keep], phase=rec.phase[keep], x_p=rec.vec("x_p")[keep], dock=rec.vec("dock")[keep],
                         course=course_ned[keep], geometry=g, deck_radius_m=params["deck_radius_m"], contact=contact,
                         outcome=outcome, title=title)


def _rebuilt_course(rec, recovering: np.ndarray, g: DockingGeometry) -> np.ndarray:
    x_ref, dock, v_c = rec.vec("x_ref"), rec.vec("dock"), rec.vec("v_c")
    first = np.flatnonzero(rec.phase == Phase.APPROACH)
    at = int(first[0]) - 1 if len(first) else int(np.flatnonzero(recovering)[-1])
    behind = (dock[at] - x_ref[at])[:2]
    c = np.array([behind[0], behind[1], 0.0]) / max(float(np.hypot(*behind)), 1e-9)
    if not np.isfinite(c).all() or float(np.hypot(*behind)) < 0.5 * g.holdoff_distance_m:
        c = np.array([1.0, 0.0, 0.0])
    out = np.full((len(rec.t), 3), np.nan)
    for i in range(at, -1, -1):  # before: the course the holdoff point was placed with, as flown back
        if not recovering[i]:
            break
        out[i] = c
    prev = c
    for i in range(at, len(rec.t)):
        if not recovering[i]:
            continue
        if np.isfinite(v_c[i]).all():
            prev = course(v_c[i], prev)
        out[i] = prev
    return out


def _side(ax, g: DockingGeometry, deck_radius_m: float) -> None:
    """The glide path, the cone round it, the holdoff point, the gate and the deck, side view."""
    h_d, h_up = -g.holdoff_distance_m, g.holdoff_height_m
    s = np.linspace(0.0, 1.0, 60)
    along, up = h_d * (1 - s), h_up + s * (g.decision_height_m - h_up)
    to_gate = np.hypot(along, up - g.decision_height_m)
    radius = g.cone_min_radius_m + to_gate * math.tan(g.cone_half_angle_rad)
    normal = np.array([-(g.decision_height_m - h_up), -h_d]) / math.hypot(h_d, g.decision_height_m - h_up)
    upper = np.stack([along + radius * normal[0], up + radius * normal[1]], axis=-1)
    lower = np.stack([along - radius * normal[0], up - radius * normal[1]], axis=-1)
    ax.fill(np.concatenate([upper[:, 0], lower[::-1, 0]]), np.concatenate([upper[:, 1], lower[::-1, 1]]),
            color="tab:blue", alpha=0.08, label=f"cone ({math.degrees(g.cone_half_angle_rad):g} deg, "
            f"{g.cone_min_radius_m:g} m at the gate)")
    ax.plot([h_d, 0.0, 0.0], [h_up, g.decision_height_m, 0.0], color="tab:blue", lw=1.5, ls="--",
            label=f"glide path ({math.degrees(g.glide_angle_rad):g} deg), then straight down")
    ax.plot([-deck_radius_m, deck_radius_m], [0.0, 0.0], color="black", lw=4, solid_capstyle="butt",
            label=f"deck ({deck_radius_m:g} m round the dock point)")
    ax.add_patch(Rectangle((-g.contact_radius_m, -g.contact_height_m), 2 * g.contact_radius_m, 2 * g.contact_height_m,
                           color="tab:green", alpha=0.25, label="contact conditions"))
    ax.scatter([h_d], [h_up], marker="s", color="goldenrod", s=60, zorder=6, label="holdoff point")
    ax.scatter([0.0], [g.decision_height_m], marker="^", color="tab:blue", s=60, zorder=6, label="gate")


def _tracks(ax, tr: RecoveryTrack, rel: np.ndarray, x: int, y: int) -> None:
    """Each attempt's track (the return in grey), columns ``x`` and ``y`` of ``rel``."""
    attempt = tr.attempts()
    flying = np.isin(tr.phase, sorted(HOMEWARD))
    back = flying & (attempt == 0)
    ax.plot(rel[back, x], rel[back, y], color="grey", lw=1.0, label="return and holdoff")
    for n in range(1, int(attempt.max()) + 1):
        on = flying & (attempt == n) & (tr.phase != Phase.HOME)
        ax.plot(rel[on, x], rel[on, y], color=ATTEMPT_COLOURS[(n - 1) % len(ATTEMPT_COLOURS)], lw=1.6,
                label=f"attempt {n}")
    docked = np.flatnonzero(tr.phase == Phase.DOCKED)
    if len(docked):
        ax.scatter(rel[docked[0], x], rel[docked[0], y], marker="X", color="red", s=90, zorder=7, label="contact")


def plot_recovery(tr: RecoveryTrack, path: str | Path) -> Path:
    """Write the recovery's figure (PNG/PDF/SVG by suffix): the approach in the carrier's frame,
    from the side (along the course, up) and from above (along the course, to its right), and
    the distances to the dock point over time with the phases shaded."""
    path = Path(path)
    g = tr.geometry
    rel = tr.in_carrier_frame()
    fig = plt.figure(figsize=(14, 8.5))
    grid = fig.add_gridspec(2, 2, height_ratios=(1.15, 1.0))
    side, top, dist = fig.add_subplot(grid[0, 0]), fig.add_subplot(grid[0, 1]), fig.add_subplot(grid[1, :])
    reach = g.holdoff_distance_m + 1.5
    _side(side, g, tr.deck_radius_m)
    _tracks(side, tr, rel, 0, 2)
    side.set_xlim(-reach, 1.5)
    side.set_ylim(-0.4, g.holdoff_height_m + 1.2)
    side.set_aspect("equal", adjustable="box")
    side.set_xlabel("along the carrier's course from the dock point [m]")
    side.set_ylabel("height above the dock point [m]")
    side.set_title("approach in the carrier's frame, from the side")
    side.grid(alpha=0.3)
    side.legend(fontsize=7, loc="lower left")

    along = np.linspace(-g.holdoff_distance_m, 0.0, 40)
    half = g.cone_min_radius_m + np.hypot(along, (g.holdoff_height_m - g.decision_height_m) * along
                                          / -g.holdoff_distance_m) * math.tan(g.cone_half_angle_rad)
    top.fill_between(along, -half, half, color="tab:blue", alpha=0.08, label="cone")
    top.plot([-g.holdoff_distance_m, 0.0], [0.0, 0.0], color="tab:blue", ls="--", lw=1.5, label="glide path")
    top.add_patch(Circle((0.0, 0.0), tr.deck_radius_m, fill=False, color="black", lw=2, label="deck"))
    top.add_patch(Circle((0.0, 0.0), g.contact_radius_m, color="tab:green", alpha=0.25, label="contact radius"))
    top.scatter([-g.holdoff_distance_m], [0.0], marker="s", color="goldenrod", s=60, zorder=6, label="holdoff point")
    _tracks(top, tr, rel, 0, 1)
    top.set_xlim(-reach, 1.5)
    top.set_ylim(-2.5, 2.5)
    top.set_aspect("equal", adjustable="box")
    top.set_xlabel("along the carrier's course from the dock point [m]")
    top.set_ylabel("to the right of the course [m]")
    top.set_title("from above (the carrier's course points right)")
    top.grid(alpha=0.3)
    top.legend(fontsize=7, loc="upper left")

    r = tr.x_p - tr.dock
    floor = 1e-3  # [m] the log scale's floor
    dist.plot(tr.t, np.maximum(norm(r), floor), color="black", lw=1.6, label="distance to the dock point")
    dist.plot(tr.t, np.maximum(np.hypot(r[:, 0], r[:, 1]), floor), color="tab:blue", lw=1.2, ls="--", label="horizontal")
    dist.plot(tr.t, np.maximum(np.abs(r[:, 2]), floor), color="tab:red", lw=1.2, ls="-.", label="vertical")
    dist.axhline(g.contact_radius_m, color="tab:green", lw=0.8, ls=":", label=f"contact radius {g.contact_radius_m:g} m")
    dist.axhline(g.decision_height_m, color="tab:blue", lw=0.8, ls=":", label=f"gate height {g.decision_height_m:g} m")
    shaded = set()
    change = np.flatnonzero(np.concatenate([[True], tr.phase[1:] != tr.phase[:-1], [True]]))
    for a, b in zip(change[:-1], change[1:]):
        name = str(tr.phase[a])
        if name not in SHADED:
            continue
        t1 = tr.t[b] if b < len(tr.t) else tr.t[-1]
        dist.axvspan(tr.t[a], t1, color=Phase[name].colour, alpha=SHADE_ALPHA, lw=0,
                     label=None if name in shaded else name)
        shaded.add(name)
    if tr.contact is not None and tr.contact.get("time_s") is not None:
        dist.axvline(tr.contact["time_s"], color="red", lw=1.0, label="contact")
    dist.set_yscale("log")
    dist.set_ylim(0.01, None)
    dist.set_xlabel("t [s] on the mission clock")
    dist.set_ylabel("distance [m]")
    dist.set_title("distances over time, phases shaded")
    dist.grid(alpha=0.3)
    dist.legend(fontsize=7, ncol=4, loc="upper right")
    c = tr.contact
    figures = "" if c is None else (f": contact {c['horizontal_error_m']:.3f} m off, relative speed "
                                    f"{c['horizontal_relative_speed_m_s']:.2f} / {c['vertical_relative_speed_m_s']:.2f} m/s "
                                    f"(h / v), attempt {c['attempts']}")
    fig.suptitle((tr.title + "\n" if tr.title else "") + f"recovery {tr.outcome or 'unfinished'}{figures}")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# --------------------------------------------------------------------------------------------- team

#: Each passenger's colour, the team's order (the carrier is tab:blue, the targets red).
PASSENGER_COLOURS = ("tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")


def plot_team(rec: TeamRecord, path: str | Path, title: str = "") -> Path:
    """Write a team's figure (PNG/PDF/SVG by suffix) from its carrier's log
    (:func:`mission.flightdata.read.read_team`), everything as the carrier heard it on its clock:
    from above, the carrier's track, every passenger's track (its own colour, labelled by name),
    the targets (with their passenger) and their b c circles, and the closest pair's two positions
    joined; beside it every pair's distance over time (faint where it does not count: neither
    flies, or either is unheard or stale) with ``safety.passenger_separation_m`` and the closest
    pair marked."""
    path = Path(path)
    fig, (top, dist) = plt.subplots(1, 2, figsize=(14, 6.2), gridspec_kw={"width_ratios": (1.0, 1.15)})
    colour = {name: PASSENGER_COLOURS[i % len(PASSENGER_COLOURS)] for i, name in enumerate(rec.names)}
    c = _display(rec.carrier, "local_ned")
    top.plot(c[:, 0], c[:, 1], color="tab:blue", lw=2.2, label="carrier")
    ok = np.isfinite(c).all(axis=1)
    if ok.any():
        top.scatter(*c[ok][0, :2], color="tab:blue", marker="s", s=50, zorder=5, label="carrier start")
        top.scatter(*c[ok][-1, :2], facecolor="white", edgecolor="tab:blue", marker="X", s=90, lw=1.5, zorder=5,
                    label="carrier end")
    carrier_then = np.stack([np.interp(rec.t, rec.carrier_t[ok], c[ok, a]) for a in (0, 1)], axis=-1) if ok.any() \
        else np.zeros((len(rec.t), 2))
    for i, name in enumerate(rec.names):
        p = _display(rec.positions[:, i], "local_ned")
        top.plot(p[:, 0], p[:, 1], color=colour[name], lw=1.4, ls="--", label=f"{name} (as heard)")
        seen = np.flatnonzero(np.isfinite(p).all(axis=1))
        if len(seen):  # its name where it flew farthest from the carrier (clear of the tracks on the deck)
            far = seen[int(np.argmax(np.linalg.norm(p[seen, :2] - carrier_then[seen], axis=1)))]
            top.annotate(name, p[far, :2], textcoords="offset points", xytext=(6, 6), color=colour[name],
                         fontsize=10, fontweight="bold")
    for k, (target, owner) in enumerate(zip(rec.targets, rec.owners)):
        t = _display(target, "local_ned")
        top.scatter(*t[:2], color="red", marker="*", s=160, zorder=6, label="targets" if k == 0 else None)
        top.annotate(f"{k} ({owner})", t[:2], textcoords="offset points", xytext=(6, -12), color="red", fontsize=8)
        top.add_patch(Circle(t[:2], rec.bc_m, fill=False, ls=":", color="red", alpha=0.6,
                             label=f"b·c = {rec.bc_m:g} m around the targets" if k == 0 else None))
    closest = rec.closest()
    if closest is not None:
        d, t_s, pair = closest
        k = int(np.argmin(np.abs(rec.t - t_s)))
        two = [_display(rec.positions[k, rec.names.index(n)], "local_ned") for n in rec.pairs[pair]]
        top.plot([two[0][0], two[1][0]], [two[0][1], two[1][1]], color="black", lw=2.0, marker="o", ms=4, zorder=7,
                 label=f"closest pair as heard, {d:.2f} m")
    top.set_aspect("equal", adjustable="datalim")
    top.set_xlabel("east [m]")
    top.set_ylabel("north [m]")
    top.set_title("the team from above, as the carrier heard it")
    top.grid(alpha=0.3)
    top.legend(loc="best", fontsize=7)

    for j, (a, b) in enumerate(rec.pairs):
        gap = rec.distances[:, j]
        line = colour[b] if len(rec.names) > 2 else "black"
        dist.plot(rec.t, np.where(rec.counted[:, j], gap, np.nan), color=line, lw=1.5, label=f"{a} - {b}")
        idle = np.where(rec.counted[:, j], np.nan, gap)
        if np.isfinite(idle).any():
            dist.plot(rec.t, idle, ls=":", alpha=0.5, lw=1.0, color=line, label=f"{a} - {b}, neither flying (not counted)")
    dist.axhline(rec.separation_m, color="red", ls="--", lw=1.2,
                 label=f"safety.passenger_separation_m = {rec.separation_m:g} m")
    if closest is not None:
        d, t_s, pair = closest
        dist.scatter([t_s], [d], color="black", zorder=6, s=40,
                     label=f"closest: {' - '.join(rec.pairs[pair])}, {d:.3f} m at t = {t_s:.1f} s")
    dist.set_xlabel("t [s] on the carrier's clock (the mission clock)")
    dist.set_ylabel("distance [m]")
    dist.set_ylim(0.0, None)
    dist.set_title("the passengers' distance as heard (positions moved on by their age)")
    dist.grid(alpha=0.3)
    dist.legend(fontsize=7, loc="upper right")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
