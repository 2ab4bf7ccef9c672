"""Which wheel unit keeps slipping: the per-unit odometry residual over time.

The odometry's estimator leaves, per wheel unit (a caster), the contact
velocity it could not explain (``Odometry.residual``, m/s). One cycle above a
threshold is a bump or a steering transient; a unit that stays above it for
``duration`` seconds has a problem a user can act on (a worn or
under-inflated tyre, a wet patch, a loose wheel, a miscalibrated encoder or
steering offset). :class:`SlipMonitor` names those units; the ROS node turns
them into a WARN on ``diagnostics``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence


@dataclass(frozen=True)
class SlipLimits:
    """``threshold`` [m/s]: residual above which a unit counts as slipping;
    ``duration`` [s]: how long it must stay above it to be reported."""

    threshold: float = 0.05
    duration: float = 1.0


class SlipMonitor:
    """Tracks, per wheel unit, since when its residual has been above the threshold.

    ``names``: the units in the order of the residual array (empty for a base
    with no redundancy, the DDROT, which never reports).
    """

    def __init__(self, names: Sequence[str], limits: SlipLimits):
        self.names = tuple(names)
        self.limits = limits
        self.reset()

    def reset(self) -> None:
        """Forget the history (after a reset of the odometry, a re-arm)."""
        self._since: list[float | None] = [None] * len(self.names)
        #: the latest residual of each unit [m/s]
        self.latest = [0.0] * len(self.names)

    def update(self, residual: Sequence[float], stamp: float) -> None:
        """Feed one cycle's residual [m/s] per unit, at time ``stamp`` [s]."""
        if len(residual) != len(self.names):
            return
        threshold = self.limits.threshold
        for i, value in enumerate(residual):
            value = float(value)
            self.latest[i] = value
            if math.isfinite(value) and value > threshold:
                if self._since[i] is None:
                    self._since[i] = stamp
            else:
                self._since[i] = None

    def slipping(self, stamp: float) -> list[tuple[str, float]]:
        """Units above the threshold for at least ``duration`` at ``stamp`` [s]:
        ``[(name, seconds above)]``."""
        out = []
        for name, since in zip(self.names, self._since):
            if since is not None and stamp - since >= self.limits.duration:
                out.append((name, stamp - since))
        return out
