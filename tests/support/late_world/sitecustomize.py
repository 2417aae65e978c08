"""A timing perturbation for the lockstep demo's determinism test (tests/integration/test_relnav_demo.py):
on ``PYTHONPATH`` of the demo's processes with ``MARSUPIAL_LATE_WORLD=1``, the mock vehicle's
carrier-truth subscriber sleeps 150 ms (wall) on each of its first 5 samples (a deck that would be
heard late: its first truth arrived at 0.075 s in one run, 0.14 s in another) and every camera
exposure sleeps 3 ms (a slower renderer). Only wall timing changes; a lockstep run must not.
Python imports ``sitecustomize`` at start-up in every process that has this folder on its path."""
from __future__ import annotations

import os

if os.environ.get("MARSUPIAL_LATE_WORLD") == "1":
    import time
    from typing import Any

    from mission.bus import feeds
    from sim.camera import simulated

    _on_sample, _capture = feeds._Feed._on_sample, simulated.SimulatedCamera.capture
    _late = [5]

    def _late_sample(self: Any, sample: Any) -> None:
        if _late[0] > 0 and str(sample.key_expr).endswith("/sim/carrier_truth"):
            _late[0] -= 1
            time.sleep(0.15)
        _on_sample(self, sample)

    def _slow_capture(self: Any, *args: Any, **kwargs: Any) -> Any:
        time.sleep(0.003)
        return _capture(self, *args, **kwargs)

    feeds._Feed._on_sample = _late_sample  # type: ignore[method-assign]
    simulated.SimulatedCamera.capture = _slow_capture  # type: ignore[method-assign]
