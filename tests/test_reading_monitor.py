"""Faults that only show in the numbers: the controller core with a mock
whose readings can be corrupted like real encoders and drives corrupt them."""

import numpy as np
import pytest

from holonomic_core.controller import ControllerState
from holonomic_core.driver import JointReading
from holonomic_core.mock_driver import MockDriver

from test_controller_core import arm, make, run


class CorruptibleMock(MockDriver):
    """Ideal motors, plus injectable faults of the reading path."""

    velocity_spike = None          # (joint index, rad/s) for the next reading
    position_jump = None           # (joint index, rad) from the next reading on
    frozen = False                 # repeat the last reading forever
    blocked = None                 # joint index that cannot move
    stamp_offset = 0.0             # added to every stamp (a clock restart)

    def _on_read(self):
        if self.frozen and self._last_reading is not None:
            return self._last_reading
        if self.blocked is not None:
            self._command[self.blocked] = 0.0
        r = super()._on_read()
        positions, velocities = r.positions.copy(), r.velocities.copy()
        if self.position_jump is not None:
            positions[self.position_jump[0]] += self.position_jump[1]
        if self.velocity_spike is not None:
            velocities[self.velocity_spike[0]] = self.velocity_spike[1]
            self.velocity_spike = None
        reading = JointReading(r.stamp + self.stamp_offset, positions, velocities, r.efforts)
        self._last_reading = reading
        return reading

    _last_reading = None

    def _on_write_velocities(self, velocities):
        super()._on_write_velocities(velocities)
        if self.blocked is not None:
            self._command[self.blocked] = 0.0


@pytest.fixture
def moving():
    ctrl, driver, clock = make(CorruptibleMock)
    arm(ctrl, clock)
    for _ in range(200):
        ctrl.set_command((0.4, 0.0, 0.0))
        run(ctrl, clock, 1)
    return ctrl, driver, clock


def test_encoder_velocity_spike_faults_and_stops_naming_the_joint(moving):
    ctrl, driver, clock = moving
    pose = ctrl.odometry.pose.copy()
    driver.velocity_spike = (1, 4000.0)     # thousands of rad/s, as real encoders glitch
    run(ctrl, clock, 1)
    assert ctrl.state is ControllerState.FAULT
    assert "right_wheel_joint" in ctrl.fault and "glitch" in ctrl.fault
    assert not driver.armed and np.all(ctrl.joint_command == 0.0)
    # the glitch is not odometry: the pose moved by at most one cycle's motion
    assert np.linalg.norm(ctrl.odometry.pose[:2] - pose[:2]) < 0.4 * ctrl.dt * 2
    # the glitch is gone: re-enable and drive again
    arm(ctrl, clock)
    ctrl.set_command((0.4, 0.0, 0.0))
    run(ctrl, clock, 100)
    assert ctrl.state is ControllerState.ARMED and ctrl.twist_command[0] > 0.3


def test_encoder_position_jump_faults_and_never_reaches_the_odometry(moving):
    ctrl, driver, clock = moving
    driver.position_jump = (0, 50.0)        # 50 rad in one 5 ms cycle
    pose = ctrl.odometry.pose.copy()
    run(ctrl, clock, 1)
    assert ctrl.state is ControllerState.FAULT and "left_wheel_joint" in ctrl.fault
    run(ctrl, clock, 20)                    # the offset persists; the base is stopped
    # 50 rad on a 6 cm wheel would be 3 m: odometry saw none of it
    assert np.linalg.norm(ctrl.odometry.pose[:2] - pose[:2]) < 0.01
    arm(ctrl, clock)                        # the offset becomes the new reference
    assert ctrl.state is ControllerState.ARMED
    run(ctrl, clock, 10)
    assert np.linalg.norm(ctrl.odometry.pose[:2] - pose[:2]) < 0.05


def test_frozen_readings_fault_after_the_reading_timeout(moving):
    ctrl, driver, clock = moving
    timeout = ctrl.config.controller.monitor.reading_timeout     # 0.05 s
    driver.frozen = True
    cycles = int(timeout / ctrl.dt)
    run(ctrl, clock, cycles)
    assert ctrl.state is ControllerState.ARMED
    run(ctrl, clock, 2)
    assert ctrl.state is ControllerState.FAULT and "stopped updating" in ctrl.fault
    assert not driver.armed


def test_a_blocked_motor_faults_after_the_tracking_timeout(moving):
    ctrl, driver, clock = moving
    driver.blocked = 0                      # left wheel stuck, the command is 6.5 rad/s
    run(ctrl, clock, int(0.4 / ctrl.dt))
    assert ctrl.state is ControllerState.ARMED
    run(ctrl, clock, int(0.2 / ctrl.dt))
    assert ctrl.state is ControllerState.FAULT
    assert "left_wheel_joint" in ctrl.fault and "cannot follow" in ctrl.fault


def test_a_clock_restart_neither_faults_nor_jumps_the_odometry(moving):
    ctrl, driver, clock = moving
    pose = ctrl.odometry.pose.copy()
    driver.stamp_offset = -50.0             # /clock restarted
    run(ctrl, clock, 5)
    assert ctrl.state is ControllerState.ARMED
    step = np.linalg.norm(ctrl.odometry.pose[:2] - pose[:2])
    assert step == pytest.approx(5 * 0.4 * ctrl.dt, rel=0.2)
    assert np.all(np.isfinite(ctrl.odometry.twist))


def test_a_long_loop_stall_integrates_the_motion_without_a_fault(moving):
    ctrl, driver, clock = moving
    pose = ctrl.odometry.pose.copy()
    clock.t += 0.2                          # the loop stalled 200 ms; the base kept going
    run(ctrl, clock, 1)
    assert ctrl.state is ControllerState.ARMED
    assert np.linalg.norm(ctrl.odometry.pose[:2] - pose[:2]) == pytest.approx(
        0.4 * (0.2 + ctrl.dt), rel=0.05)
