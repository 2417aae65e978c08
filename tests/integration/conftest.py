"""Fixtures of the integration tests."""
from __future__ import annotations

from collections.abc import Iterator

import pytest

from sim.testing.probe import Probe


@pytest.fixture
def probe() -> Iterator[Probe]:
    """A pymavlink ground-side peer on an ephemeral UDP port (closed after the test)."""
    with Probe() as p:
        yield p
