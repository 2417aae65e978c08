"""The relative estimator's inputs as flight-log messages, and back (``marsupial.RelativeInput``).

Every record the passenger's step hands to :class:`mission.relnav.estimator.RelativeEstimator`
(:data:`mission.relnav.inputs.EstimatorInput`) becomes one message, in the order handed, numbered
by ``seq``: the own sample that ticks it, the carrier's fix, the marker, the downward range, the
vehicle seated on the deck. Numbers are written as Python writes a float (``repr``), which reads
back to the same bits, so the inputs of a flight replay its estimator exactly
(``python -m bench.relnav_replay``, docs/relnav.md). Times [s] on the mission clock, vectors NED [m],
[m/s], [m/s^2]; covariances 3 x 3 row-major [m^2].
"""
from __future__ import annotations

from typing import Any

import numpy as np

from mission.relnav.inputs import CarrierFix, EstimatorInput, MarkerFix, OwnSample, RangeFix, Seated

KINDS = ("own", "carrier", "marker", "range", "seated")


def _floats(v: Any) -> list[float]:
    return [float(x) for x in np.asarray(v, dtype=float).ravel()]


def input_message(item: EstimatorInput, seq: int) -> dict[str, Any]:
    """The message of one input, ``seq`` its place among the flight's inputs (from 0)."""
    if isinstance(item, OwnSample):
        return {"seq": seq, "kind": "own", "t_s": float(item.t_s), "position": _floats(item.position_ned_m),
                "velocity": _floats(item.velocity_ned_m_s)}
    if isinstance(item, CarrierFix):
        a = item.acceleration_ned_m_s2
        return {"seq": seq, "kind": "carrier", "t_s": float(item.t_s), "position": _floats(item.position_ned_m),
                "velocity": _floats(item.velocity_ned_m_s), "acceleration": None if a is None else _floats(a)}
    if isinstance(item, MarkerFix):
        return {"seq": seq, "kind": "marker", "t_s": float(item.capture_t_s), "offset": _floats(item.deck_rel_ned_m),
                "covariance": _floats(item.covariance_ned_m2)}
    if isinstance(item, RangeFix):
        return {"seq": seq, "kind": "range", "t_s": float(item.t_s), "range_m": float(item.range_m),
                "sigma_m": float(item.sigma_m), "deck_top": _floats(item.deck_top_ned_m),
                "deck_radius_m": float(item.deck_radius_m)}
    return {"seq": seq, "kind": "seated", "t_s": float(item.t_s), "offset": _floats(item.carrier_rel_ned_m),
            "sigma_m": float(item.sigma_m)}


def input_from_message(m: dict[str, Any]) -> EstimatorInput:
    """The input record a message was written from (ValueError: not one of :data:`KINDS`)."""
    kind, t = m.get("kind"), float(m["t_s"])
    if kind == "own":
        return OwnSample(t, np.array(m["position"], float), np.array(m["velocity"], float))
    if kind == "carrier":
        a = m.get("acceleration")
        return CarrierFix(t, np.array(m["position"], float), np.array(m["velocity"], float),
                          None if a is None else np.array(a, float))
    if kind == "marker":
        return MarkerFix(t, np.array(m["offset"], float), np.array(m["covariance"], float).reshape(3, 3))
    if kind == "range":
        return RangeFix(t, float(m["range_m"]), float(m["sigma_m"]), np.array(m["deck_top"], float), float(m["deck_radius_m"]))
    if kind == "seated":
        return Seated(t, np.array(m["offset"], float), float(m["sigma_m"]))
    raise ValueError(f"not a relative estimator's input: kind {kind!r} (one of {', '.join(KINDS)})")
