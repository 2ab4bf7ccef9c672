"""The ``mock`` backend: ideal motors, commands become states.

Each ``read`` integrates the last commanded joint velocities over the time
since the previous read (positions) and reports them as measured velocities.
Useful to run the whole stack without physics or hardware (benchmarks,
controller tests). Disarmed joints stand still.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from holonomic_core.driver import Driver, JointReading


class MockDriver(Driver):
    name = "mock"
    supports_effort = False

    def __init__(self, model, params, control_rate: float,
                 clock: Callable[[], float] = time.monotonic):
        """``clock`` [s]: injectable for deterministic tests."""
        super().__init__(model, params, control_rate)
        self._clock = clock
        n = len(model.joint_names)
        self._positions = np.zeros(n)
        self._command = np.zeros(n)
        self._no_efforts = np.full(n, np.nan)
        self._no_efforts.flags.writeable = False
        self._last = 0.0
        self._max_rates = model.max_joint_velocity

    def _on_configure(self) -> None:
        self._last = self._clock()

    def _on_deactivate(self) -> None:
        self._command[:] = 0.0

    def _on_read(self) -> JointReading:
        now = self._clock()
        dt = max(0.0, now - self._last)
        self._last = now
        velocities = self._command.copy() if self.armed else np.zeros_like(self._command)
        self._positions += velocities * dt
        return JointReading(now, self._positions.copy(), velocities, self._no_efforts)

    def _on_write_velocities(self, velocities: np.ndarray) -> None:
        np.clip(velocities, -self._max_rates, self._max_rates, out=self._command)
