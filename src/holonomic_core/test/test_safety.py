"""Emergency stop, holding still and setting the pose, without ROS: the
controller on the mock driver with an injected clock."""

import math

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController, ControllerState
from holonomic_core.driver import DriverState
from holonomic_core.mock_driver import QUICK_STOP_TIME, MockDriver
from holonomic_core.safety import (DisarmPolicy, EmergencyStop, parse_covariance, parse_pose,
                                   planar_covariance)
from holonomic_core.schema import ConfigError


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def make(**overrides):
    cfg = load_config("hamr", dict({"driver": "mock"}, **overrides))
    clock = FakeClock()
    driver = MockDriver(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock)
    driver.configure()
    return BaseController(cfg, driver, clock=clock), driver, clock


def run(ctrl, clock, cycles, twist=None):
    for _ in range(cycles):
        if twist is not None:
            ctrl.set_command(twist)
        clock.t += ctrl.dt
        ctrl.step()


def request(ctrl, clock, future):
    run(ctrl, clock, 1)
    return future.result(timeout=0)


def armed_at_speed(**overrides):
    """A hamr at 0.5 m/s forward (limits reached within 2 s)."""
    ctrl, driver, clock = make(**overrides)
    assert request(ctrl, clock, ctrl.request_enable(True)) == (True, "motors armed")
    run(ctrl, clock, 400, (0.5, 0.0, 0.0))
    assert ctrl.odometry.twist[0] == pytest.approx(0.5, abs=1e-3)
    return ctrl, driver, clock


# -- emergency stop -------------------------------------------------------------
def test_estop_quick_stops_the_drives_and_disarms_naming_the_source():
    ctrl, driver, clock = armed_at_speed()
    moving = np.abs(ctrl.reading.velocities).max()
    ctrl.request_estop(True, "panel button")
    run(ctrl, clock, 1, (0.5, 0.0, 0.0))
    assert driver.state is DriverState.INACTIVE
    s = ctrl.status()
    assert s.state is ControllerState.DISARMED
    assert s.estop == "emergency stop pressed by panel button"
    # a braking ramp, not a coast or a jump: the wheels still turn one cycle
    # in and are at rest after the mock's quick-stop time (speed limit -> 0
    # in QUICK_STOP_TIME, so at most that from any lower speed)
    assert 0.0 < np.abs(ctrl.reading.velocities).max() < moving
    run(ctrl, clock, math.ceil(QUICK_STOP_TIME / ctrl.dt) + 1, (0.5, 0.0, 0.0))
    assert np.abs(ctrl.reading.velocities).max() == 0.0


def test_enable_is_refused_while_the_estop_is_pressed():
    ctrl, driver, clock = armed_at_speed()
    ctrl.request_estop(True, "teleop")
    run(ctrl, clock, 1)
    ok, text = request(ctrl, clock, ctrl.request_enable(True))
    assert not ok and "emergency stop pressed by teleop" in text
    assert driver.state is DriverState.INACTIVE


def test_release_never_rearms_by_itself_but_allows_enable():
    ctrl, driver, clock = armed_at_speed()
    ctrl.request_estop(True, "teleop")
    run(ctrl, clock, 1)
    ctrl.request_estop(False, "teleop")
    run(ctrl, clock, 100, (0.5, 0.0, 0.0))
    assert ctrl.status().estop is None
    assert driver.state is DriverState.INACTIVE and ctrl.state is ControllerState.DISARMED
    assert request(ctrl, clock, ctrl.request_enable(True)) == (True, "motors armed")


def test_estop_heartbeat_timeout_counts_as_pressed():
    ctrl, driver, clock = make(**{"safety.estop_timeout": 0.2})
    # no 'released' heard yet: cannot arm
    ok, text = request(ctrl, clock, ctrl.request_enable(True))
    assert not ok and "heartbeat" in text
    ctrl.request_estop(False, "radio")
    assert request(ctrl, clock, ctrl.request_enable(True)) == (True, "motors armed")
    # releases every 0.1 s keep it armed for 1 s ...
    for _ in range(10):
        ctrl.request_estop(False, "radio")
        run(ctrl, clock, 20, (0.3, 0.0, 0.0))
    assert ctrl.state is ControllerState.ARMED
    # ... silence longer than 0.2 s quick-stops it (200 Hz: 41 cycles > 0.2 s)
    run(ctrl, clock, 41, (0.3, 0.0, 0.0))
    assert driver.state is DriverState.INACTIVE
    assert "heartbeat lost: no 'released' from radio" in ctrl.status().estop


def test_estop_input_alone():
    e = EmergencyStop()
    assert e.reason(0.0) is None                         # no heartbeat: released at start
    e.update(True, "", 1.0)
    assert e.reason(1e6) == "emergency stop pressed by emergency_stop"   # latched
    e.update(False, "x", 2.0)
    assert e.reason(1e6) is None
    h = EmergencyStop(0.5)
    assert "no 'released' message yet" in h.reason(0.0)
    h.update(False, "x", 1.0)
    assert h.reason(1.5) is None and h.reason(1.51) is not None
    with pytest.raises(ValueError):
        EmergencyStop(-1.0)


# -- holding still --------------------------------------------------------------
def test_hold_brings_the_base_to_rest_and_keeps_the_drives_at_zero_velocity():
    ctrl, driver, clock = armed_at_speed()
    ok, text = request(ctrl, clock, ctrl.request_enable(False))
    assert ok and "holding" in text
    # hamr's x deceleration limit 2.0 m/s^2 (config/hamr.yaml): 0.5 m/s to
    # rest in 0.25 s = 50 cycles; commands meanwhile are not followed
    run(ctrl, clock, 110, (0.5, 0.0, 0.0))
    assert driver.state is DriverState.ACTIVE
    s = ctrl.status()
    assert s.state is ControllerState.DISARMED and s.holding
    assert np.all(ctrl.joint_command == 0.0)
    assert s.twist_command == (0.0, 0.0, 0.0)
    # a second disarm idles the drives (safety.hold_time 0: until then)
    assert request(ctrl, clock, ctrl.request_enable(False)) == (True, "motors disarmed")
    assert driver.state is DriverState.INACTIVE and not ctrl.status().holding


def test_hold_decelerates_under_the_limits_not_at_once():
    ctrl, driver, clock = armed_at_speed(**{"limits.linear.x.max_deceleration": 1.0})
    ctrl.request_enable(False)
    run(ctrl, clock, 50)
    # 0.25 s at 1 m/s^2 from 0.5 m/s: 0.25 m/s commanded
    assert ctrl.twist_command[0] == pytest.approx(0.25, abs=0.01)


def test_hold_time_idles_the_drives_after_it():
    ctrl, driver, clock = armed_at_speed(**{"safety.hold_time": 1.0})
    ok, text = request(ctrl, clock, ctrl.request_enable(False))
    assert "for 1 s" in text
    run(ctrl, clock, 190)                   # 0.955 s into the hold
    assert driver.state is DriverState.ACTIVE
    run(ctrl, clock, 20)
    assert driver.state is DriverState.INACTIVE and not ctrl.status().holding


def test_arming_from_a_hold_follows_commands_again():
    ctrl, driver, clock = armed_at_speed()
    request(ctrl, clock, ctrl.request_enable(False))
    run(ctrl, clock, 150)
    assert request(ctrl, clock, ctrl.request_enable(True)) == (True, "motors armed")
    run(ctrl, clock, 400, (0.5, 0.0, 0.0))
    assert ctrl.odometry.twist[0] == pytest.approx(0.5, abs=1e-3)


def test_coast_idles_the_drives_at_once():
    ctrl, driver, clock = armed_at_speed(**{"safety.disarm_mode": "coast"})
    assert request(ctrl, clock, ctrl.request_enable(False)) == (True, "motors disarmed")
    assert driver.state is DriverState.INACTIVE


def test_estop_during_a_hold_quick_stops():
    ctrl, driver, clock = armed_at_speed()
    request(ctrl, clock, ctrl.request_enable(False))
    ctrl.request_estop(True, "panel")
    run(ctrl, clock, 1)
    assert driver.state is DriverState.INACTIVE and not ctrl.status().holding


def test_disarm_policy_rejects_bad_values():
    with pytest.raises(ValueError):
        DisarmPolicy("brake")
    with pytest.raises(ValueError):
        DisarmPolicy("hold", -1.0)


@pytest.mark.parametrize("key, value", [("safety.disarm_mode", "brake"),
                                        ("safety.hold_time", -1.0),
                                        ("safety.estop_timeout", -0.1),
                                        ("safety.estop_timeout", float("nan"))])
def test_bad_safety_parameters_name_the_key(key, value):
    with pytest.raises(ConfigError) as err:
        load_config("hamr", {"driver": "mock", key: value})
    assert err.value.key == key


# -- setting the pose -----------------------------------------------------------
def test_set_pose_during_motion_jumps_and_keeps_integrating():
    ctrl, driver, clock = armed_at_speed()
    cov = (0.01, 0.0, 0.0, 0.0, 0.02, 0.0, 0.0, 0.0, 0.03)
    ok, text = request(ctrl, clock, ctrl.request_set_pose((5.0, -2.0, math.pi / 2), cov))
    assert ok
    # the request ran at the start of that cycle; the cycle's own reading
    # then moved the base 0.5 m/s * 5 ms along its new heading (+y)
    pose = ctrl.odometry.pose
    assert pose[0] == pytest.approx(5.0, abs=1e-9)
    assert pose[1] == pytest.approx(-2.0 + 0.5 * ctrl.dt, abs=1e-6)
    assert pose[2] == pytest.approx(math.pi / 2, abs=1e-9)
    P = ctrl.odometry.pose_covariance
    assert P[0, 0] >= 0.01 and P[1, 1] >= 0.02 and P[2, 2] >= 0.03
    assert P[0, 0] < 0.0101
    # one more second at 0.5 m/s along +y: no displacement lost or repeated
    run(ctrl, clock, 200, (0.5, 0.0, 0.0))
    assert ctrl.odometry.pose[1] == pytest.approx(-2.0 + 0.5 * 201 * ctrl.dt, abs=1e-6)
    assert ctrl.odometry.pose[0] == pytest.approx(5.0, abs=1e-6)


def test_pose_and_covariance_parsing_refuse_bad_values():
    assert parse_pose(("1", 2, 3.0)) == (1.0, 2.0, 3.0)
    for bad in ((1.0, float("nan"), 0.0), (1.0, 2.0), ("a", 0, 0), (0, 0, float("inf"))):
        with pytest.raises(ValueError):
            parse_pose(bad)
    assert parse_covariance([0.0] * 9) == (0.0,) * 9
    for bad in ([1, 2, 0, 0, 1, 0, 0, 0, 1], [-1, 0, 0, 0, 1, 0, 0, 0, 1],
                [float("nan")] * 9, [0.0] * 8):
        with pytest.raises(ValueError):
            parse_covariance(bad)
    cov36 = [0.0] * 36
    cov36[0], cov36[7], cov36[35], cov36[5] = 1.0, 2.0, 3.0, 0.5
    assert planar_covariance(cov36) == (1.0, 0.0, 0.5, 0.0, 2.0, 0.0, 0.0, 0.0, 3.0)
