"""A stand-in for motor drives in torque mode, for the controller's fast tests.

:class:`~holonomic_core.mock_driver.MockDriver` (the ``mock`` backend) has
ideal velocity motors and no torque mode, and the simulator needs pybullet;
this driver follows the same :class:`~holonomic_core.driver.Driver`
interface with ``supports_effort``, but moves nothing: the joints stay where
the test puts them, and every command is recorded, so a test can compare the
torques the controller wrote with values derived by hand.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from holonomic_core.driver import Driver, DriverError, JointReading


class EffortRecorder(Driver):
    """Joints at :attr:`positions` [rad] and :attr:`velocities` [rad/s] (set
    by the test), each read stamped with ``clock()`` [s]; each write appended
    to :attr:`written` as ``("velocities", rad/s)`` or ``("efforts", N m)``.
    The efforts read back are the last torques written (an ideal current
    loop), zero while disarmed. A write raises :attr:`fail_writes` when set
    (a drive that stopped answering)."""

    name = "effort_recorder"
    supports_effort = True

    def __init__(self, model, params, control_rate: float,
                 clock: Callable[[], float] = time.monotonic):
        super().__init__(model, params, control_rate)
        n = len(model.joint_names)
        self._clock = clock
        #: joint positions [rad] and velocities [rad/s] every read reports
        self.positions = np.zeros(n)
        self.velocities = np.zeros(n)
        #: every command written, in order: (kind, a copy of the values)
        self.written: list[tuple[str, np.ndarray]] = []
        #: raised by every write while set
        self.fail_writes: DriverError | None = None
        self._efforts = np.zeros(n)

    def efforts_written(self) -> list[np.ndarray]:
        """The torques [N m] of every ``write_efforts``, in order."""
        return [values for kind, values in self.written if kind == "efforts"]

    def _on_configure(self) -> None:
        pass

    def _on_deactivate(self) -> None:
        self._efforts = np.zeros_like(self._efforts)

    def _on_read(self) -> JointReading:
        return JointReading(self._clock(), self.positions.copy(), self.velocities.copy(),
                            self._efforts.copy())

    def _on_write_velocities(self, velocities: np.ndarray) -> None:
        if self.fail_writes is not None:
            raise self.fail_writes
        self.written.append(("velocities", np.array(velocities, dtype=float)))

    def _on_write_efforts(self, efforts: np.ndarray) -> None:
        if self.fail_writes is not None:
            raise self.fail_writes
        self._efforts = np.array(efforts, dtype=float)
        self.written.append(("efforts", self._efforts.copy()))
