"""The marker on the deck: one AprilTag 36h11, or a bundle of them (a big tag seen from far, a small
one at the deck centre seen in the last half metre), each placed in the deck frame
(:mod:`mission.vision.measurement`). A tag's size is its black border's outer edge [m], the square
OpenCV's detector returns the corners of; print it with a white margin of at least one bit."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mission.vision.frames import ROTATION_DECK_TAG

FAMILY = "DICT_APRILTAG_36h11"
TAG_BITS = 8  # the 36h11 tag's side in bits: 6 data bits and a black border of one each side


@dataclass(frozen=True)
class Tag:
    """One tag: its ``id`` in the family, ``size_m`` [m] (black border's outer edge), its centre
    ``centre_deck_m`` (x, y) [m] in the deck frame, printed with its top towards the deck's forward."""

    id: int
    size_m: float
    centre_deck_m: tuple[float, float] = (0.0, 0.0)

    def tag_points(self) -> np.ndarray:
        """The four corners (4, 3) [m] in the tag's own frame, in the detector's order (top-left,
        top-right, bottom-right, bottom-left of the printed tag): what ``SOLVEPNP_IPPE_SQUARE`` wants."""
        h = self.size_m / 2
        return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])

    def deck_points(self) -> np.ndarray:
        """The same corners (4, 3) [m] in the deck frame."""
        return self.tag_points() @ ROTATION_DECK_TAG.T + np.array([*self.centre_deck_m, 0.0])


@dataclass(frozen=True)
class MarkerLayout:
    """The tags on the deck; the deck centre is the layout's origin."""

    tags: tuple[Tag, ...]

    def __post_init__(self) -> None:
        if not self.tags:
            raise ValueError("a marker layout needs at least one tag")
        ids = [t.id for t in self.tags]
        if len(set(ids)) != len(ids):
            raise ValueError(f"tag ids must differ: {ids}")
        if any(t.size_m <= 0 for t in self.tags):
            raise ValueError("tag sizes must be positive")

    @classmethod
    def single(cls, size_m: float = 0.5, tag_id: int = 0) -> MarkerLayout:
        """One tag of side ``size_m`` [m] centred on the deck."""
        return cls((Tag(tag_id, size_m),))

    @classmethod
    def bundle(cls, big_size_m: float = 0.5, small_size_m: float = 0.1, gap_m: float = 0.08,
               big_id: int = 0, small_id: int = 1) -> MarkerLayout:
        """A small tag centred on the deck and a big one ahead of it, ``gap_m`` [m] between their
        edges: the big tag carries the approach from metres up, the small one the last half metre,
        where the big one no longer fits in the image. One pose is solved from all the tags seen."""
        big_x = small_size_m / 2 + gap_m + big_size_m / 2
        return cls((Tag(small_id, small_size_m), Tag(big_id, big_size_m, (big_x, 0.0))))

    def tag(self, tag_id: int) -> Tag | None:
        return next((t for t in self.tags if t.id == tag_id), None)

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(t.id for t in self.tags)
