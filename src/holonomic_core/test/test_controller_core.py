"""The control cycle without ROS: mock driver, injected clock."""

import dataclasses
import math

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController, ControllerState
from holonomic_core.driver import DriverCommunicationError, DriverStateError
from holonomic_core.mock_driver import MockDriver
from holonomic_core.schema import ConfigError

#: every test here runs on both implementations of the cycle's closed forms
#: ([pure], [compiled]: the hot_path_mode fixture of holonomic_testing)
pytestmark = pytest.mark.usefixtures("hot_path_mode")


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


def drive(ctrl, clock, twist, cycles):
    """``cycles`` cycles with ``twist`` received before each (a live publisher)."""
    for _ in range(cycles):
        ctrl.set_command(twist)
        run(ctrl, clock, 1)


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
    drive(ctrl, clock, (1.0, 0.0, 0.0), 400)
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
    drive(ctrl, clock, (0.5, 0.0, 0.0), 200)
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
    drive(ctrl, clock, (0.5, 0.0, 0.0), 100)
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
    drive(ctrl, clock, (0.5, 0.0, 0.0), 200)
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


# -- the cycle's bookkeeping, boundaries and trajectories (issue 21: the
# -- controller's mutation survivors; expected values by hand) ----------------

class GlitchMock(MockDriver):
    """A mock that can return a reading of the wrong size (a garbled frame):
    the reading monitor refuses it whatever the numbers."""

    glitch = False

    def _on_read(self):
        reading = super()._on_read()
        if self.glitch:
            return dataclasses.replace(reading, positions=reading.positions[:2])
        return reading


def test_status_counts_cycles_and_is_a_frozen_snapshot():
    ctrl, driver, clock = make()
    s = ctrl.status()
    assert (s.driver_errors, s.implausible_readings, s.timeouts, s.rejected_commands) == (0, 0, 0, 0)
    run(ctrl, clock, 3)
    s = ctrl.status()
    assert s.cycles == 3
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.cycles = 0                        # diagnostics cannot alter what they report


def test_step_returns_whether_the_cycle_ran():
    """True for a cycle that ran, disarmed or armed; False when the driver
    failed or its reading was refused."""
    ctrl, driver, clock = make(GlitchMock)
    clock.t += ctrl.dt
    assert ctrl.step() is True              # disarmed
    arm(ctrl, clock)
    clock.t += ctrl.dt
    assert ctrl.step() is True              # armed
    driver.glitch = True
    clock.t += ctrl.dt
    assert ctrl.step() is False


def test_failing_driver_counts_every_failed_cycle():
    ctrl, driver, clock = make(FlakyMock)
    arm(ctrl, clock)
    driver.fail = True
    clock.t += ctrl.dt
    assert ctrl.step() is False
    run(ctrl, clock, 2)                     # still silent: two more failed reads
    assert ctrl.status().driver_errors == 3
    assert "left_wheel_joint" in ctrl.fault
    assert ctrl.status().twist_command == (0.0, 0.0, 0.0)


def test_implausible_reading_faults_a_disarmed_base_once_and_blocks_arming():
    """A garbled reading faults even a disarmed base (the drives are not to be
    trusted); while faulted and disarmed the same garbage is its consequence,
    not counted again. Arming re-checks a fresh reading and refuses it."""
    ctrl, driver, clock = make(GlitchMock)
    run(ctrl, clock, 2)
    driver.glitch = True
    clock.t += ctrl.dt
    assert ctrl.step() is False
    assert ctrl.state is ControllerState.FAULT
    run(ctrl, clock, 3)
    assert ctrl.status().implausible_readings == 1
    fut = ctrl.request_enable(True)
    run(ctrl, clock, 1)
    ok, message = fut.result(timeout=0)
    assert ok is False and "positions" in message
    assert ctrl.state is ControllerState.FAULT
    driver.glitch = False
    arm(ctrl, clock)
    assert ctrl.state is ControllerState.ARMED
    driver.glitch = True                    # armed again: a new fault, counted
    run(ctrl, clock, 1)
    assert ctrl.status().implausible_readings == 2


def test_arm_twice_and_disarm_answer_the_request():
    ctrl, driver, clock = make()
    arm(ctrl, clock)
    fut = ctrl.request_enable(True)
    run(ctrl, clock, 1)
    assert fut.result(timeout=0) == (True, "already armed")
    assert ctrl.status().twist_command == (0.0, 0.0, 0.0)
    fut = ctrl.request_enable(False)
    run(ctrl, clock, 1)
    # safety.disarm_mode hold (the default): disarmed, the drives hold still
    assert fut.result(timeout=0) == (
        True, "motors disarmed; holding the base at rest until disarmed again")
    assert ctrl.state is ControllerState.DISARMED
    assert ctrl.status().twist_command == (0.0, 0.0, 0.0)


def test_disarming_a_saturated_base_reports_rest_and_no_scaling():
    # without the speed norm: the per-axis 1.2 m/s on a diagonal (1.7 m/s)
    # is beyond the wheels' 1.23 m/s, so the joint speeds saturate; coast:
    # the drives idle at once (hold decelerates first: test_safety)
    ctrl, driver, clock = make(**{"limits.linear.max_speed": 0.0, "safety.disarm_mode": "coast"})
    arm(ctrl, clock)
    drive(ctrl, clock, (1e308, 1e308, 0.0), 600)
    assert ctrl.status().saturation < 1.0
    fut = ctrl.request_enable(False)
    run(ctrl, clock, 2)
    assert fut.result(timeout=0)[0] is True
    s = ctrl.status()
    assert s.saturation == 1.0 and s.twist_command == (0.0, 0.0, 0.0)
    assert np.all(ctrl.joint_command == 0.0)


def test_saturated_twist_command_is_what_the_joints_do():
    """When the joint rates are scaled down, the reported twist command is
    scaled with them: the kinematics' inverse of the twist command gives the
    joint command, and the fastest joint is at its limit (without the speed
    norm, which keeps the diagonal within the joints' reach)."""
    ctrl, driver, clock = make(**{"limits.linear.max_speed": 0.0})
    arm(ctrl, clock)
    drive(ctrl, clock, (1e308, 1e308, 0.0), 600)
    assert ctrl.saturation < 1.0
    rates = ctrl.model.kinematics.inverse(ctrl.reading.positions, ctrl.twist_command)
    np.testing.assert_allclose(rates, ctrl.joint_command, rtol=1e-9, atol=1e-12)
    assert np.max(np.abs(ctrl.joint_command) / ctrl.model.max_joint_velocity) \
        == pytest.approx(1.0, abs=1e-9)


def test_zero_correction_is_added_to_every_reading():
    """joints.turret_joint.zero_correction = 0.3 rad: the mock's encoders read
    0, the controller (odometry, inverse kinematics, joint_states) sees 0.3."""
    ctrl, driver, clock = make(**{"joints.turret_joint.zero_correction": 0.3})
    run(ctrl, clock, 1)
    i = ctrl.model.joint_names.index("turret_joint")
    expected = np.zeros(len(ctrl.model.joint_names))
    expected[i] = 0.3
    np.testing.assert_array_equal(ctrl.reading.positions, expected)


@pytest.mark.parametrize("bad,what", [((math.nan, 0.0, 0.0), "non-finite"),
                                      (("x" * 100, 0.0, 0.0), "malformed"),
                                      ((True, 0, 0), "malformed")])
def test_rejected_command_says_why_and_is_a_stop_command(bad, what):
    ctrl, driver, clock = make()
    reason = ctrl.set_command(bad)
    assert reason.startswith(f"{what} command ")
    # the echoed command is cut to 80 characters
    assert len(reason[len(f"{what} command "):-len(" rejected; stopping the base")]) \
        == min(80, len(repr(bad)))
    # the rejection is itself a (zero) command received now: not stale
    assert ctrl.command_age() == 0.0
    arm(ctrl, clock)
    run(ctrl, clock, 2)
    assert ctrl.status().twist_command == (0.0, 0.0, 0.0)


def test_integer_and_numpy_commands_are_accepted_bools_are_not():
    ctrl, driver, clock = make()
    assert ctrl.set_command((1, 0, 0)) is None
    assert ctrl.set_command((np.float32(0.5), np.int64(0), 0.0)) is None
    assert ctrl.set_command((True, 0, 0)) is not None


def test_command_age_and_the_timeout_boundary():
    """A command exactly cmd_timeout (0.5 s in hamr.yaml) old still holds;
    each time commands stop the timeout is counted once."""
    ctrl, driver, clock = make()
    arm(ctrl, clock)
    ctrl.set_command((0.004, 0.0, 0.0))
    clock.t += 0.25
    assert ctrl.command_age() == 0.25
    ctrl.set_command((0.004, 0.0, 0.0), received=clock.t - 0.5)   # 100.x - 0.5 exact
    ctrl.step()                                  # clock not advanced: age exactly 0.5
    assert ctrl.stale is False
    assert ctrl.twist_command[0] == pytest.approx(0.004)
    for _ in range(2):
        run(ctrl, clock, int(0.6 / ctrl.dt))     # commands stop for 0.6 s
        ctrl.set_command((0.004, 0.0, 0.0))
        run(ctrl, clock, 1)
    assert ctrl.status().timeouts == 2


def test_no_command_since_arming_is_stale():
    ctrl, driver, clock = make()
    arm(ctrl, clock)
    ctrl.set_command((0.004, 0.0, 0.0))
    run(ctrl, clock, 1)
    assert ctrl.stale is False
    fut = ctrl.request_enable(False)
    run(ctrl, clock, 1)
    arm(ctrl, clock)                             # the old command is dropped
    assert ctrl.status().stale is True


def test_commands_while_disarmed_counted_each_and_window_inclusive():
    ctrl, driver, clock = make()
    clock.t = 100.0
    ctrl.set_command((0.3, 0.0, 0.0), received=98.0)
    ctrl.set_command((0.3, 0.0, 0.0), received=98.0)
    assert ctrl.counters["commands_while_disarmed"] == 2
    assert ctrl.commanded_while_disarmed(2.0)       # exactly 2 s ago: still reported


def test_velocity_mode_follows_a_trajectory_then_rests():
    """follow(): t starts at 0 on the next cycle and advances with the clock;
    the target is the feed-forward twist plus TRAJECTORY_GAIN (4 /s) times the
    reference pose in base_link. First cycle: the base is at the origin, the
    reference at (0.0005 m, 0, 0) with twist (0.002 m/s, 0, 0), so the target is
    0.002 + 4 * 0.0005 = 0.004 m/s, under the acceleration step 1.0 m/s^2 *
    5 ms = 0.005 m/s (hamr.yaml), so it is commanded as is. When the trajectory
    returns None the base is commanded to rest (a fresh zero command)."""
    ctrl, driver, clock = make()
    arm(ctrl, clock)
    times = []

    def trajectory(t):
        times.append(t)
        if t >= 2 * ctrl.dt - 1e-9:
            return None
        return (0.0005, 0.0, 0.0), (0.002, 0.0, 0.0), (0.0, 0.0, 0.0)

    ctrl.follow(trajectory)
    run(ctrl, clock, 1)
    np.testing.assert_allclose(ctrl.twist_command, [0.004, 0.0, 0.0], atol=1e-12)
    run(ctrl, clock, 2)
    np.testing.assert_allclose(times, [0.0, ctrl.dt, 2 * ctrl.dt], atol=1e-9)
    assert ctrl.command_age() == 0.0 and ctrl.stale is False
    run(ctrl, clock, 100)                        # at rest, the trajectory not called again
    assert len(times) == 3
    np.testing.assert_allclose(ctrl.twist_command, 0.0, atol=1e-12)


def test_state_names_seen_by_diagnostics():
    """The diagnostics' controller_state value is the state's value (the node
    publishes status.state.value): the names operators and their tools read."""
    assert [s.value for s in ControllerState] == ["disarmed", "armed", "fault"]


def test_status_reports_the_drift_watch_only_where_it_applies():
    """The powered-caster bases run the calibration drift watch (on by default,
    drift_watch.enabled): before any motion it has no findings and has judged
    nothing. The HAMR has none: its findings are None, not an empty list."""
    cfg = load_config("comr3", {"driver": "mock"})
    clock = FakeClock()
    driver = MockDriver(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock)
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=clock)
    run(ctrl, clock, 2)
    s = ctrl.status()
    assert s.drift_findings == () and s.drift_judged is False
    hamr, _, _ = make()
    assert hamr.status().drift_findings is None and hamr.status().drift_judged is False


class RecordingMock(MockDriver):
    """A mock that logs its reads into a shared event list."""

    events: list

    def _on_read(self):
        self.events.append("read")
        return super()._on_read()


def test_take_command_runs_after_the_reading_and_its_command_is_used_in_that_cycle():
    # loop_host hands the newest command over through step(take_command):
    # after the cycle's reading, so a command that arrives while the cycle
    # reads the drives is used by this cycle, not the next one
    ctrl, driver, clock = make(RecordingMock)
    events = driver.events = []
    arm(ctrl, clock)
    events.clear()

    def take():
        events.append("take")
        ctrl.set_command((0.2, 0.0, 0.0))

    clock.t += ctrl.dt
    ctrl.step(take)
    assert events == ["read", "take"]
    # the limiter moves the twist toward the command already in this cycle
    # (from rest: by max_acceleration x dt, > 0); had the command been taken
    # after the control law, this cycle would still command zero
    assert 0.0 < ctrl.twist_command[0] <= 0.2
    assert np.any(ctrl.joint_command != 0.0)


def test_take_command_also_runs_disarmed_but_not_when_the_reading_fails():
    ctrl, driver, clock = make(FlakyMock)
    taken = []
    clock.t += ctrl.dt
    assert ctrl.step(lambda: taken.append(clock.t))
    assert taken == [clock.t]            # disarmed: still drained (counted, not used)
    driver.fail = True
    clock.t += ctrl.dt
    assert not ctrl.step(lambda: taken.append(clock.t))
    assert len(taken) == 1               # the caller drains that cycle itself (loop_host)
