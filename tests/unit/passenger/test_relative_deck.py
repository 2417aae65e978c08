"""The relative estimator in the passenger's step ([relnav] enabled): the carrier's state moved into
the passenger's frame, the estimate's jumps let through at the configured rate, the descent's gate."""
from __future__ import annotations

import math

import numpy as np

from mission.config.relnav import RelnavSection
from mission.model import derived
from mission.passenger.inputs import VehicleReport
from mission.passenger.relative import RelativeDeck
from mission.phases import Measurements, RelativePosition
from mission.phases.types import CarrierObs, RelnavGates

BIAS = np.array([2.0, -1.0, 0.0])  # [m] the carrier's GNSS frame over the passenger's


def _gates() -> RelnavGates:
    section = RelnavSection(enabled=True)
    return derived(RelnavGates, section, params=section.params())


def _fly(deck: RelativeDeck, t0: float, t1: float, marker: bool, measurements: Measurements) -> list:
    """The vehicle hovering 1.5 m over a deck at rest at the origin; GNSS at 10 Hz with the bias."""
    out = []
    for k in range(int(round(t0 * 50)), int(round(t1 * 50))):
        t = k / 50
        report = VehicleReport(t, np.array([0.0, 0.0, -1.5]), np.zeros(3), t, t, True, "OFFBOARD", 0.0, True)
        fix_t = math.floor(t * 10) / 10
        carrier = CarrierObs(position_ned_m=BIAS.copy(), velocity_ned_m_s=np.zeros(3), age_s=t - fix_t, alive=True)
        new = (RelativePosition(capture_t_s=t, offset_ned_m=np.array([0.0, 0.0, 1.5]), sigma_m=0.02),) if marker else ()
        measurements = measurements.then(new)
        out.append((t, *deck.observe(t, report, carrier, measurements)))
    return out


def test_the_first_marker_moves_the_deck_at_the_rate_then_onto_the_truth():
    gates = _gates()
    deck = RelativeDeck(gates)
    far = _fly(deck, 0.0, 20.0, False, Measurements())
    t, carrier, view = far[-1]
    assert not view.converged and gates.descent_blocked(view) == "marker not in sight"
    assert float(np.linalg.norm(carrier.position_ned_m[:2])) > 1.0  # GNSS alone: the deck seen metres off
    near = _fly(deck, 20.0, 40.0, True, Measurements())
    steps = [float(np.linalg.norm(b[1].position_ned_m - a[1].position_ned_m)) for a, b in zip(near, near[1:])]
    assert max(steps) <= gates.correction_rate_m_s / 50 + 0.01  # no jump: at most the rate a tick (+ 1 cm)
    t, carrier, view = near[-1]
    assert view.converged and gates.descent_blocked(view) is None and gates.taken_in(view)
    assert float(np.linalg.norm(carrier.position_ned_m)) < 0.05  # on the true deck
    assert float(np.linalg.norm(view.bias_ned_m[:2] - BIAS[:2])) < 0.2


def test_a_malformed_reading_is_refused_and_counted_never_raised():
    """A faulty or hostile feed: NaN or infinite capture time, offset or sigma, or no sigma. Each
    reading is refused and counted; the loop goes on, and the estimate is the one without them."""
    bad = (RelativePosition(capture_t_s=math.nan, offset_ned_m=np.array([0.0, 0.0, 1.5]), sigma_m=0.02),
           RelativePosition(capture_t_s=1.0, offset_ned_m=np.array([math.inf, 0.0, 1.5]), sigma_m=0.02),
           RelativePosition(capture_t_s=1.0, offset_ned_m=np.array([0.0, 0.0, 1.5]), sigma_m=math.inf),
           RelativePosition(capture_t_s=1.0, offset_ned_m=np.array([0.0, 0.0, 1.5]), sigma_m=None))
    clean, dirty = RelativeDeck(_gates()), RelativeDeck(_gates())
    a = _fly(clean, 0.0, 2.0, False, Measurements())
    _fly(dirty, 0.0, 1.0, False, Measurements())
    report = VehicleReport(1.0, np.array([0.0, 0.0, -1.5]), np.zeros(3), 1.0, 1.0, True, "OFFBOARD", 0.0, True)
    carrier = CarrierObs(position_ned_m=BIAS.copy(), velocity_ned_m_s=np.zeros(3), age_s=0.0, alive=True)
    dirty.observe(1.0, report, carrier, Measurements().then(bad))  # the tick at t = 1.0 s, with the bad readings
    b = _fly(dirty, 1.02, 2.0, False, Measurements())
    a = [row for row in a if row[0] != 1.0]
    assert dirty.refused == len(bad)
    assert np.allclose(a[-1][1].position_ned_m, b[-1][1].position_ned_m)
