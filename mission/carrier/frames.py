"""The frame the carrier's P3 guard runs in (pure: no clock, no I/O, no log).

With a shared frame (``[relnav]`` off) the carrier's own position is where the passenger and the
targets have it, and the guard (:mod:`mission.carrier.guard`) runs on it. With relative navigation
there is no shared frame: the carrier knows itself in its own GNSS frame, the targets
(``scenario.targets``) are in the passenger's, and the two disagree by the frames' bias ``b`` (the
carrier's GNSS frame minus the passenger's, [m] NED), metres. A passenger whose relative estimate
has converged shares its estimate of ``b`` and its standard deviation in its status
(:class:`mission.bus.wire.PassengerStatus`: ``bias``, ``bias_sigma``); with
``carrier.p3_frame = "passenger"`` the guard then runs on the carrier's position moved into the
passenger's frame, ``x_c - b`` (in the plane for a planar carrier: its height is the scenario's),
with its radius ``b c - carrier.p3_margin_m`` [m]. Only the guard and the P3 figures move: the
law, the CBF filter and the published state stay in the carrier's own frame.

A bias is used only while it is *usable*, judged every step at the carrier's clock
(:meth:`GuardFrame.settle`); the passenger may be faulty or hostile:

- fresh: its status was heard at most ``carrier.p3_bias_max_age_s`` [s] ago (else ``stale``; the
  bias is slow, metres drifting over minutes, and a passenger stops sharing it when its marker
  leaves the camera, a second after it separates, while the carrier still brakes);
- converged: its sigma is at most ``carrier.p3_bias_max_sigma_m`` [m] (else ``unconverged``);
- plausible: ``|b|`` at most ``carrier.p3_bias_max_m`` [m] (else ``implausible``);
- steady: at most ``carrier.p3_bias_max_step_m`` [m] from the bias the guard has (else ``jump``).

The guard's bias is the samples smoothed, ``b_g += (1 - exp(-dt / tau)) (b - b_g)`` (``tau``
``carrier.p3_bias_tau_s`` [s], ``dt`` [s] between the samples' arrivals; 0: the sample itself):
the estimate swings 0.1-0.4 m from one GNSS fix to the next, and the guard's idea of the carrier
would swing with it. So no single sample moves the guard's idea of the carrier by more than
``p3_bias_max_step_m (1 - exp(-dt / tau))``. A run of usable samples, each steady, starts the
guard's bias afresh; the guard enters the passenger's frame once the run has lasted
``carrier.p3_bias_settle_s`` [s] (else ``settling``). A sample that fails a gate is dropped
(counted by reason, :attr:`GuardFrame.dropped`) and ends the run (a ``jump`` starts the next one
at itself: a passenger whose estimate really jumped, a reset, is used again after the settling).
Without a usable bias the guard runs in the carrier's own frame with its margin widened by
``carrier.p3_unaligned_margin_m`` [m] (radius ``b c - p3_margin_m - p3_unaligned_margin_m``), so
that it never parks short of where the passenger separates, the frames disagreeing by metres.
Every fall back from the passenger's frame counts too (:attr:`GuardFrame.fallbacks`, by reason).

What a hostile passenger can do: in the passenger's frame the guard keeps the carrier at least
``b c - p3_margin_m - p3_bias_max_m`` [m] from a target as its own frame has it, and in its own
frame ``b c - p3_margin_m - p3_unaligned_margin_m``: it moves the guard's circle within that,
creeping at most as above a step while it stays in the passenger's frame, and every larger jump
costs it ``p3_bias_settle_s`` in the carrier's own frame first. The carrier's law and the next
leg's start run in the same frame (:mod:`mission.carrier.step`, :mod:`mission.carrier.legs`), so
within those bounds it moves where the carrier drives too. ``carrier.p3_frame = "own"`` (the
default) is the guard as it always was: its own frame, no widening, the bias ignored.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

#: Why a bias is not used (keys of :attr:`GuardFrame.dropped` and :attr:`GuardFrame.fallbacks`):
#: ``none`` no bias heard (not shared, not converged yet, no relnav), ``settling`` a run of usable
#: samples not yet ``p3_bias_settle_s`` long, then the gates above.
REASONS: tuple[str, ...] = ("none", "settling", "stale", "unconverged", "implausible", "jump")


@dataclass(frozen=True)
class HeardBias:
    """The frames' bias as the passenger's newest status shares it: ``bias_ned_m`` [m] (3,) NED the
    carrier's GNSS frame minus the passenger's; ``sigma_m`` [m] its largest standard deviation;
    ``stamp_s`` [s] the status's stamp on the passenger's clock (a new sample has another);
    ``age_s`` [s] since the status arrived, on the carrier's clock."""

    bias_ned_m: np.ndarray
    sigma_m: float
    stamp_s: float
    age_s: float


@dataclass(frozen=True)
class FrameParams:
    """``frame`` ``"own"`` or ``"passenger"``; the gates' bounds ``max_age_s`` [s], ``max_sigma_m``
    [m], ``max_bias_m`` [m], ``max_step_m`` [m]; ``tau_s`` [s] the smoothing, ``settle_s`` [s] the
    run of usable samples before the guard uses them; ``unaligned_margin_m`` [m] the guard's margin
    widened by this without a usable bias (``carrier.p3_*``, module docstring; their defaults are
    the configuration's, :meth:`from_carrier`)."""

    frame: Literal["own", "passenger"]
    max_age_s: float
    max_sigma_m: float
    max_bias_m: float
    max_step_m: float
    tau_s: float
    settle_s: float
    unaligned_margin_m: float

    @classmethod
    def from_carrier(cls, c: Any) -> FrameParams:
        """The parameters of a ``[carrier]`` section (:class:`mission.config.carrier.CarrierSection`)."""
        return cls(c.p3_frame, c.p3_bias_max_age_s, c.p3_bias_max_sigma_m, c.p3_bias_max_m, c.p3_bias_max_step_m,
                   c.p3_bias_tau_s, c.p3_bias_settle_s, c.p3_unaligned_margin_m)


class GuardFrame:
    """Which frame the guard runs in, step by step: :meth:`hear` the passenger's newest bias,
    :meth:`settle` at the step's time, then the guards read :meth:`shift_ned_m` and
    :attr:`widen_m` (module docstring). A ``planar`` carrier's guard takes the bias's horizontal
    part only (its height is the scenario's plane): the gates judge that part."""

    def __init__(self, params: FrameParams, planar: bool = False) -> None:
        self.p, self.planar = params, planar
        self.bias_ned_m: np.ndarray | None = None  # [m] NED the bias in use (None: the own frame)
        self.why = "none"  # why the own frame ("" while in the passenger's)
        self.dropped = dict.fromkeys(REASONS[3:], 0)  # samples dropped, by gate
        self.fallbacks = dict.fromkeys(REASONS[2:], 0)  # falls back from the passenger's frame, by reason
        self.steps = {"passenger": 0, "own": 0}  # steps guarded in each frame
        self.closest_m = math.inf  # [m] the closest approach to a target in the frame the guard used
        self._heard: HeardBias | None = None
        self._stamp: float | None = None  # [s] the passenger's stamp of the last sample judged
        self._heard_s: float | None = None  # [s] when it was heard, on the carrier's clock
        self._run: tuple[float, float, np.ndarray] | None = None  # (start [s], last [s], smoothed bias [m]) of the run

    @property
    def passenger(self) -> bool:
        """The guard runs in the passenger's frame (``carrier.p3_frame`` and a usable bias)."""
        return self.bias_ned_m is not None

    @property
    def widen_m(self) -> float:
        """[m] by how much the guard's radius shrinks now: ``carrier.p3_unaligned_margin_m`` in the
        own frame when the passenger's is configured, else 0."""
        return self.p.unaligned_margin_m if self.p.frame == "passenger" and self.bias_ned_m is None else 0.0

    def shift_ned_m(self, k: int, planar: bool) -> np.ndarray:
        """[m] (k,) what to subtract from the carrier's own position [m] (its first ``k`` axes) to
        have it in the guard's frame: the bias in use (horizontal only when ``planar``), else 0."""
        out = np.zeros(k)
        if self.bias_ned_m is not None:
            n = 2 if planar else k
            out[:n] = self.bias_ned_m[:n]
        return out

    def hear(self, bias: HeardBias | None) -> None:
        """Take the passenger's newest shared bias (None: its newest status has none, or no status:
        the last one shared holds while it is fresh)."""
        self._heard = bias

    def settle(self, now_s: float) -> str:
        """Judge the bias heard at the carrier's clock time ``now_s`` [s] and choose the frame;
        returns what changed, for the log (``""``: nothing)."""
        if self.p.frame != "passenger":
            return ""
        h = self._heard
        new = h is not None and h.stamp_s != self._stamp
        if h is not None and new:
            self._stamp, self._heard_s = h.stamp_s, now_s - h.age_s
        if self._heard_s is None:
            why = "none"
        elif now_s - self._heard_s > self.p.max_age_s:  # none since (statuses without one): the last holds till then
            why, self._run = "stale", None
        elif h is not None and new:  # a new sample: the gates, the run
            why = self._take(np.asarray(h.bias_ned_m, dtype=float), h.sigma_m, self._heard_s)
        else:
            why = self.why  # the sample judged before: as it was
        run = self._run
        if not why and run is not None:
            was = self.bias_ned_m
            self.bias_ned_m, self.why = run[2].copy(), ""
            return "" if was is not None else \
                f"P3 guard in the passenger's frame: bias {np.round(self.bias_ned_m, 2).tolist()} m"
        why = why or "none"
        change = ""
        if self.bias_ned_m is not None:
            self.fallbacks[why] += 1
            change = f"P3 guard in its own frame ({why} bias), margin widened by {self.p.unaligned_margin_m:g} m"
        self.bias_ned_m, self.why = None, why
        return change

    def _take(self, b: np.ndarray, sigma_m: float, heard_s: float) -> str:
        """A new sample ``b`` [m] (sigma [m]) heard at ``heard_s`` [s] (carrier's clock) through the
        gates into the run; why the guard may not use the run (``""``: it may)."""
        run = self._run
        if b.shape == (3,) and self.planar:
            b = np.array([b[0], b[1], 0.0])
        if not (math.isfinite(sigma_m) and sigma_m <= self.p.max_sigma_m):
            why = "unconverged"
        elif not (b.shape == (3,) and np.all(np.isfinite(b)) and float(np.linalg.norm(b)) <= self.p.max_bias_m):
            why = "implausible"
        elif run is not None and float(np.linalg.norm(b - run[2])) > self.p.max_step_m:
            why = "jump"
        else:
            if run is None:
                self._run = (heard_s, heard_s, b.copy())
            else:
                dt = max(heard_s - run[1], 0.0)
                gain = 1.0 if self.p.tau_s <= 0 else -math.expm1(-dt / self.p.tau_s)
                self._run = (run[0], heard_s, run[2] + gain * (b - run[2]))
            return "" if heard_s - self._run[0] >= self.p.settle_s else "settling"
        self.dropped[why] += 1
        self._run = (heard_s, heard_s, b.copy()) if why == "jump" else None
        return why

    def account(self, x_c: np.ndarray, targets: list[np.ndarray]) -> None:
        """Count the step in the frame used and take the carrier at ``x_c`` [m] (its own frame)
        into the closest approach to ``targets`` [m] in the guard's frame."""
        if self.p.frame != "passenger":
            return
        self.steps["passenger" if self.passenger else "own"] += 1
        x = np.asarray(x_c, dtype=float)
        x = x - self.shift_ned_m(x.shape[0], self.planar)
        self.closest_m = min([self.closest_m, *(float(np.linalg.norm(np.asarray(t)[:x.shape[0]] - x)) for t in targets)])

    def summary(self) -> dict[str, Any]:
        """``frame`` configured, ``passenger`` (in it now), ``why`` not, ``steps`` in each frame,
        ``dropped`` and ``fallbacks`` by reason, ``closest_target_distance_m`` [m] in the guard's
        frame (None: never guarded in the passenger's mode), ``bias_ned_m`` [m] in use."""
        return {"frame": self.p.frame, "passenger": self.passenger, "why": self.why, "steps": dict(self.steps),
                "dropped": dict(self.dropped), "fallbacks": dict(self.fallbacks),
                "closest_target_distance_m": None if math.isinf(self.closest_m) else self.closest_m,
                "bias_ned_m": None if self.bias_ned_m is None else self.bias_ned_m.tolist()}
