"""The control cycle without ROS: mock driver, injected clock."""

import math

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController, ControllerState
from holonomic_core.driver import DriverCommunicationError, DriverStateError
from holonomic_core.mock_driver import MockDriver
from holonomic_core.schema import ConfigError


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


class FlakyMock(MockDriver):
    """A mock whose reads can be made to fail, like a drive that stops answering."""

    fail = False

    def _on_read(self):
        if self.fail:
            raise DriverCommunicationError("no answer within 10 ms", device="left_wheel_joint")
        return super()._on_read()


def make(driver_cls=MockDriver, **overrides):
    cfg = load_config("hamr", dict({"driver": "mock"}, **overrides))
    clock = FakeClock()
    driver = driver_cls(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock)
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=clock)
    return ctrl, driver, clock


def run(ctrl, clock, cycles):
    for _ in range(cycles):
        clock.t += ctrl.dt
        ctrl.step()


def arm(ctrl, clock):
    fut = ctrl.request_enable(True)
    run(ctrl, clock, 1)
    assert fut.result(timeout=0) == (True, "motors armed")


def test_motors_start_disarmed_and_commands_do_not_move_them():
    ctrl, driver, clock = make()
    assert ctrl.state is ControllerState.DISARMED
    ctrl.set_command((0.5, 0.0, 0.0))
    run(ctrl, clock, 100)
    assert np.all(ctrl.joint_command == 0.0)
    assert np.all(ctrl.reading.positions == 0.0)
    with pytest.raises(DriverStateError):
        driver.write_velocities(np.ones(3))


def test_commands_sent_before_arming_are_dropped():
    ctrl, driver, clock = make()
    ctrl.set_command((0.5, 0.0, 0.0))
    arm(ctrl, clock)
    run(ctrl, clock, 20)
    assert np.all(ctrl.joint_command == 0.0)


def test_armed_base_follows_the_command_after_the_ramp():
    ctrl, driver, clock = make()
    arm(ctrl, clock)
    for _ in range(400):  # 2 s at 200 Hz, command refreshed at 200 Hz
        ctrl.set_command((0.3, 0.2, 0.5))
        run(ctrl, clock, 1)
    np.testing.assert_allclose(ctrl.twist_command, [0.3, 0.2, 0.5], atol=1e-12)
    # the mock's encoders integrate the commands; odometry sees the twist (to
    # the discretisation: rates are solved at the cycle's start, odometry uses
    # the mid-point turret angle -- a 1e-5 difference at 0.5 rad/s, 200 Hz)
    np.testing.assert_allclose(ctrl.odometry.twist, [0.3, 0.2, 0.5], atol=1e-4)


def test_stale_command_stops_the_base_within_the_deceleration_limit():
    ctrl, driver, clock = make()
    arm(ctrl, clock)
    for _ in range(400):
        ctrl.set_command((1.0, 0.0, 0.0))
        run(ctrl, clock, 1)
    assert ctrl.twist_command[0] == pytest.approx(1.0)
    # publisher dies: for cmd_timeout (0.5 s) the command holds ...
    run(ctrl, clock, int(0.5 / ctrl.dt) - 1)
    assert ctrl.twist_command[0] == pytest.approx(1.0)
    # ... then the base decelerates at the configured limit, never faster
    decel = ctrl.config.controller.max_deceleration[0]      # 2.0 m/s^2 in hamr.yaml
    speeds = []
    for _ in range(200):
        run(ctrl, clock, 1)
        speeds.append(ctrl.twist_command[0])
    steps = -np.diff(speeds)
    assert np.all(steps <= decel * ctrl.dt + 1e-12)
    assert ctrl.stale and ctrl.counters["timeouts"] == 1
    # 1 m/s at 2.0 m/s^2 stops in 0.5 s = 100 cycles (the first at speed 1 - decel dt)
    stop = math.ceil(1.0 / (decel * ctrl.dt) - 1e-9) - 1
    assert speeds[stop - 1] > 0.0
    assert speeds[stop] == pytest.approx(0.0, abs=1e-12)
    assert np.all(ctrl.joint_command == 0.0)


def test_zero_timeout_disables_the_timeout():
    ctrl, driver, clock = make(cmd_timeout=0.0)
    arm(ctrl, clock)
    ctrl.set_command((0.5, 0.0, 0.0))
    run(ctrl, clock, 2000)  # 10 s without a new command
    assert ctrl.twist_command[0] == pytest.approx(0.5)


@pytest.mark.parametrize("bad", [(math.nan, 0, 0), (0, math.inf, 0), (0, 0, -math.inf),
                                 ("x", 0, 0), (None, 1, 2), ()])
def test_non_finite_or_malformed_command_is_rejected_and_stops_the_base(bad):
    ctrl, driver, clock = make()
    arm(ctrl, clock)
    for _ in range(200):
        ctrl.set_command((0.5, 0.0, 0.0))
        run(ctrl, clock, 1)
    reason = ctrl.set_command(bad)
    assert reason and "rejected" in reason
    assert ctrl.counters["rejected_commands"] == 1
    # The base brakes from the very next cycle, at the deceleration limit --
    # not after cmd_timeout (0.5 s = 100 cycles) on the last good command:
    # 0.5 m/s at 2.0 m/s^2 (hamr.yaml) loses decel * dt = 0.01 m/s a cycle and
    # is at rest after 0.5 / 0.01 = 50 cycles.
    decel = ctrl.config.controller.max_deceleration[0]
    run(ctrl, clock, 1)
    assert ctrl.twist_command[0] == pytest.approx(0.5 - decel * ctrl.dt, abs=1e-12)
    stop = math.ceil(0.5 / (decel * ctrl.dt) - 1e-9)
    assert stop < ctrl.cmd_timeout / ctrl.dt
    run(ctrl, clock, stop - 1)
    assert np.all(ctrl.twist_command == 0.0) and np.all(ctrl.joint_command == 0.0)
    run(ctrl, clock, 200)
    assert np.all(ctrl.joint_command == 0.0)
    assert np.all(np.isfinite(ctrl.odometry.pose))


def test_oversized_command_is_scaled_within_limits_keeping_direction():
    ctrl, driver, clock = make()
    arm(ctrl, clock)
    for _ in range(600):
        ctrl.set_command((1e308, 1e308, 0.0))
        run(ctrl, clock, 1)
        assert np.all(np.abs(ctrl.joint_command) <= ctrl.model.max_joint_velocity + 1e-9)
        assert np.all(np.isfinite(ctrl.joint_command))
    vx, vy, wz = ctrl.twist_command
    assert vx == pytest.approx(vy) and wz == 0.0 and vx > 0.1


def test_driver_that_stops_answering_faults_disarms_and_recovers_after_enable():
    ctrl, driver, clock = make(FlakyMock)
    arm(ctrl, clock)
    for _ in range(100):
        ctrl.set_command((0.5, 0.0, 0.0))
        run(ctrl, clock, 1)
    driver.fail = True
    run(ctrl, clock, 1)
    assert ctrl.state is ControllerState.FAULT
    assert "left_wheel_joint" in ctrl.fault
    assert not driver.armed
    # still faulted while it does not answer; enable is refused
    fut = ctrl.request_enable(True)
    run(ctrl, clock, 1)
    assert fut.result(timeout=0)[0] is False
    driver.fail = False
    run(ctrl, clock, 10)
    assert ctrl.state is ControllerState.FAULT  # latched until re-enabled
    assert np.all(ctrl.joint_command == 0.0)
    arm(ctrl, clock)
    assert ctrl.state is ControllerState.ARMED


def test_reset_odometry_request_zeroes_the_pose():
    ctrl, driver, clock = make()
    arm(ctrl, clock)
    for _ in range(200):
        ctrl.set_command((0.5, 0.0, 0.0))
        run(ctrl, clock, 1)
    assert ctrl.odometry.pose[0] > 0.1
    fut = ctrl.request_reset_odometry()
    run(ctrl, clock, 1)
    assert fut.result(timeout=0)[0] is True
    assert abs(ctrl.odometry.pose[0]) < 0.01


@pytest.mark.parametrize("overrides,key", [
    ({"control_rate": -5.0}, "control_rate"),
    ({"control_rate": "fast"}, "control_rate"),
    ({"publish_rate": 500.0}, "publish_rate"),
    ({"estimator": "kalman"}, "estimator"),
    ({"driver": "tcp"}, "driver"),
    ({"limits.linear.x.max_velocity": 0.0}, "limits.linear.x.max_velocity"),
    ({"joints.turret_joint.max_velocity": float("nan")}, "joints.turret_joint.max_velocity"),
    ({"cmd_timout": 1.0}, "cmd_timout"),
    ({"odometry.twist_variance": [1.0]}, "odometry.twist_variance"),
])
def test_invalid_configuration_names_the_key(overrides, key):
    with pytest.raises(ConfigError) as err:
        load_config("hamr", dict({"driver": "mock"}, **overrides))
    assert err.value.key == key
    assert f"'{key}'" in str(err.value)


def test_unknown_robot_name_lists_the_known_ones():
    with pytest.raises(ConfigError, match="hamr"):
        load_config("no_such_robot")


def test_non_zero_commands_while_disarmed_are_counted_and_reported_for_a_while():
    ctrl, driver, clock = make()
    run(ctrl, clock, 2)
    ctrl.set_command((0.0, 0.0, 0.0))           # a teleop idling: nothing to report
    assert ctrl.counters["commands_while_disarmed"] == 0
    assert not ctrl.commanded_while_disarmed(2.0)
    ctrl.set_command((0.3, 0.0, 0.0))
    assert ctrl.counters["commands_while_disarmed"] == 1
    clock.t += 1.9
    assert ctrl.commanded_while_disarmed(2.0)   # the diagnostics' 2 s window
    assert ctrl.status().commanded_while_disarmed
    clock.t += 0.2
    assert not ctrl.commanded_while_disarmed(2.0)
    assert not ctrl.status().commanded_while_disarmed
    arm(ctrl, clock)
    ctrl.set_command((0.3, 0.0, 0.0))           # armed: the base follows, nothing to report
    assert ctrl.counters["commands_while_disarmed"] == 1


def test_status_before_the_first_cycle():
    """What diagnostics show of a controller built but not yet stepped: no
    command ever (age inf, stale), no reading (no slipping casters), a zero
    twist command, nothing scaled (saturation 1), disarmed, no fault."""
    ctrl, driver, clock = make()
    s = ctrl.status()
    assert s.state is ControllerState.DISARMED and s.fault is None
    assert s.command_age == math.inf and s.stale is True
    assert s.twist_command == (0.0, 0.0, 0.0) and s.saturation == 1.0
    assert s.slipping == () and s.cycles == 0
    assert not s.commanded_while_disarmed
