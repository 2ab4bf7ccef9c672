"""The simulator's joints as the motors of emulated CAN drives.

With ``holonomic-bringup ROBOT --driver odrive_can|cia402 --sim-drives`` the
emulated drives (:mod:`holonomic_drivers.emulation`) drive simulated joints
instead of ideal motors. Two pieces:

* :class:`SimulatedJoints` holds every joint's latest command (velocity
  [rad/s] or torque [N m], from whichever drive last set it) and the joint
  states of the last physics step; :meth:`SimulatedJoints.step` hands the
  commands to the :class:`~holonomic_sim.sim_driver.SimDriver` through its
  public ``write_velocities`` / ``write_efforts`` and steps it with ``read``,
  so whatever motor model the simulator has applies to them;
* :class:`SimulatedJointMotor` is one drive's motor (the motor protocol of
  :mod:`holonomic_drivers.emulation`, motor shaft, SI units): it converts
  between the motor shaft and the joint through the robot's *true* gear
  ratio and direction, which a test (or a user checking a CAN YAML against
  the drawings) may set apart from the YAML's::

      q_motor = direction * gear_ratio * (q_joint - position_offset)
      tau_joint = direction * gear_ratio * tau_motor      (ideal gear)

Thread safety: the drives command and sample their motors from the emulator
thread, another thread steps the physics (:mod:`holonomic_sim.sim_drives`);
one lock guards the commands and states.
"""

from __future__ import annotations

import threading

import numpy as np

from holonomic_core.driver import Driver, JointReading

VELOCITY, TORQUE = "velocity", "torque"


class SimulatedJoints:
    """Commands and states of a simulated robot's joints (``joint_names`` order)."""

    def __init__(self, sim: Driver, max_efforts: np.ndarray, max_velocities: np.ndarray):
        """``sim``: an ACTIVE simulator driver; ``max_efforts`` [N m] and
        ``max_velocities`` [rad/s] per joint (the stiffness of the velocity loop
        of a joint whose drive is in velocity mode while another is in torque
        mode, see :meth:`step`)."""
        n = len(max_efforts)
        self._sim = sim
        self._max_efforts = np.asarray(max_efforts, float)
        self._max_velocities = np.asarray(max_velocities, float)
        self._modes = [VELOCITY] * n
        self._commands = np.zeros(n)
        self._positions = np.zeros(n)
        self._velocities = np.zeros(n)
        self._lock = threading.Lock()

    def command(self, index: int, mode: str, value: float) -> None:
        """Joint ``index``'s setpoint: ``mode`` VELOCITY [rad/s] or TORQUE [N m]."""
        with self._lock:
            self._modes[index] = mode
            self._commands[index] = value

    def state(self, index: int) -> tuple[float, float]:
        """Joint ``index``'s position [rad] and velocity [rad/s] after the last step."""
        with self._lock:
            return float(self._positions[index]), float(self._velocities[index])

    def step(self) -> JointReading:
        """Apply the latest commands and advance the physics by one control
        period (the simulator's ``read``); returns the simulator's reading.

        All joints in velocity mode -> ``write_velocities``; any in torque mode
        -> ``write_efforts``, where a joint still in velocity mode (its drive
        idle, or not yet switched) gets a proportional velocity loop that
        reaches its torque limit at a tenth of its speed limit of error."""
        with self._lock:
            modes, commands = list(self._modes), self._commands.copy()
            velocities = self._velocities.copy()
        if all(m == VELOCITY for m in modes):
            self._sim.write_velocities(commands)
        else:
            gain = self._max_efforts / (0.1 * self._max_velocities)
            loop = np.clip(gain * (commands - velocities), -self._max_efforts, self._max_efforts)
            self._sim.write_efforts(np.where([m == TORQUE for m in modes], commands, loop))
        reading = self._sim.read()
        with self._lock:
            self._positions[:] = reading.positions
            self._velocities[:] = reading.velocities
        return reading


class SimulatedJointMotor:
    """One emulated drive's motor: joint ``index`` of :class:`SimulatedJoints`
    seen from the motor shaft (rad, rad/s, N m at the motor)."""

    def __init__(self, joints: SimulatedJoints, index: int, gear_ratio: float,
                 direction: int, position_offset: float = 0.0):
        """``gear_ratio`` [motor rev per joint rev] and ``direction`` (+1/-1):
        the mechanism's true values; ``position_offset`` [rad]: the joint angle
        at motor position zero."""
        if gear_ratio <= 0 or direction not in (-1, 1):
            raise ValueError(f"gear_ratio {gear_ratio} > 0 and direction {direction} in (-1, 1)")
        self._joints = joints
        self._index = index
        self._scale = direction * float(gear_ratio)       # motor rad per joint rad
        self._offset = float(position_offset)

    def command_velocity(self, rad_per_s: float) -> None:
        self._joints.command(self._index, VELOCITY, rad_per_s / self._scale)

    def command_torque(self, newton_metre: float) -> None:
        self._joints.command(self._index, TORQUE, newton_metre * self._scale)

    def position(self) -> float:
        return self._scale * (self._joints.state(self._index)[0] - self._offset)

    def velocity(self) -> float:
        return self._scale * self._joints.state(self._index)[1]

    def advance(self, dt: float) -> None:
        """Nothing: the physics of all joints advances in :meth:`SimulatedJoints.step`."""
