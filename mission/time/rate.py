"""A send schedule at a rate, on whatever clock its caller reads (pure: it is given the times)."""
from __future__ import annotations

import math


class RateGate:
    """Spaces sends at ``rate_hz`` [Hz] on the caller's clock (0: never due): :meth:`due` is True
    at the first call and then once a period, the schedule kept on the period's grid (a tick that
    comes late does not push the next send later), restarted after a gap of over a period (no burst)."""

    def __init__(self, rate_hz: float) -> None:
        self.period_s = 1.0 / rate_hz if rate_hz > 0 else math.inf
        self.next_s = -math.inf

    def due(self, t_s: float) -> bool:
        """Whether to send at ``t_s`` [s]; True advances the schedule."""
        if not math.isfinite(self.period_s) or t_s < self.next_s - 1e-6:
            return False
        self.next_s = self.next_s + self.period_s if t_s - self.next_s < self.period_s else t_s + self.period_s
        return True
