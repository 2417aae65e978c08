"""Real PX4 SITL flights: skipped, with the reason, unless ``MARSUPIAL_PX4_SITL`` names a PX4
SITL build (a folder with ``bin/px4`` and ``etc/``) and we may make network namespaces."""
from __future__ import annotations

import pytest

from sim.px4_sitl import unavailable_reason


@pytest.fixture
def px4_build():
    why = unavailable_reason()
    if why:
        pytest.skip(why)
    from sim.px4_sitl import build_dir

    return build_dir()
