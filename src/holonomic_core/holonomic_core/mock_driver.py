"""The ``mock`` backend: ideal motors, commands become states.

Each ``read`` integrates the last commanded joint velocities over the time
since the previous read (positions) and reports them as measured velocities.
Useful to run the whole stack without physics or hardware (benchmarks,
controller tests). Disarmed joints stand still; a quick stop (the
emergency stop) brakes each joint from its speed limit to rest in
QUICK_STOP_TIME, as a drive's quick-stop ramp does.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from holonomic_core.driver import Driver, JointReading

#: [s] a mock joint's quick stop from its speed limit to rest (its deceleration
#: is max_velocity / QUICK_STOP_TIME)
QUICK_STOP_TIME = 0.25


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
        # joint speeds [rad/s] while a quick stop brakes them; None: not braking
        self._braking: np.ndarray | None = None

    def _on_configure(self) -> None:
        self._last = self._clock()

    def _on_activate(self) -> None:
        self._braking = None

    def _on_deactivate(self) -> None:
        self._command[:] = 0.0

    def _on_quick_stop(self) -> None:
        self._braking = self._command.copy()
        self._command[:] = 0.0

    def _on_read(self) -> JointReading:
        now = self._clock()
        dt = max(0.0, now - self._last)
        self._last = now
        if self._braking is not None:
            # the ramp to rest: the mean speed over the interval integrates
            before = self._braking
            step = self._max_rates / QUICK_STOP_TIME * dt
            after = np.sign(before) * np.maximum(np.abs(before) - step, 0.0)
            self._positions += 0.5 * (before + after) * dt
            self._braking = after if after.any() else None
            return JointReading(now, self._positions.copy(), after, self._no_efforts)
        velocities = self._command.copy() if self.armed else np.zeros_like(self._command)
        self._positions += velocities * dt
        return JointReading(now, self._positions.copy(), velocities, self._no_efforts)

    def _on_write_velocities(self, velocities: np.ndarray) -> None:
        np.clip(velocities, -self._max_rates, self._max_rates, out=self._command)
