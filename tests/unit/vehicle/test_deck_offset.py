"""A deck off the carrier's position (a team's slot, ``mock-vehicle --deck-offset``): the vehicle
standing on its slot starts on it, carried with the carrier; one standing at the carrier's own
position, 0.75 m from the slot's centre (radius 0.5 m), does not."""
from __future__ import annotations

from dataclasses import replace

import pytest

from sim.vehicle.physics.deck import Deck, DeckMotion, DeckSpec
from sim.vehicle.physics.multicopter import KinState

SLOT = DeckSpec(height_m=0.5, radius_m=0.5, offset_ne_m=(0.0, 0.75))
MOTION = DeckMotion((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.0)


def _step(start: tuple[float, float, float]) -> tuple[Deck, KinState]:
    deck = Deck(SLOT)
    deck.motion = MOTION
    before = replace(KinState(*start), on_ground=True)
    return deck, deck.step(0.02, 0.02, before, before)


def test_a_vehicle_on_its_slot_starts_on_the_deck_and_rides_with_it() -> None:
    deck, after = _step((0.0, 0.75, -0.5))
    assert deck.on_deck and len(deck.touchdowns) == 1 and deck.touchdowns[0].horizontal_error_m == pytest.approx(0.0)
    assert (after.n_m, after.e_m, after.vn_m_s) == pytest.approx((0.02, 0.75, 1.0))


def test_a_vehicle_at_the_carriers_own_position_is_not_on_that_slot() -> None:
    deck, _ = _step((0.0, 0.0, -0.5))
    assert not deck.on_deck and deck.touchdowns == []
