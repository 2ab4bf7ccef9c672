"""Faults that only show in the numbers: the controller core with a mock
whose readings can be corrupted like real encoders and drives corrupt them."""

import numpy as np
import pytest

from holonomic_core.controller import ControllerState
from holonomic_core.driver import JointReading
from holonomic_core.mock_driver import MockDriver
from holonomic_core.monitor import MonitorLimits, ReadingMonitor

from test_controller_core import arm, make, run

#: every test here runs on both implementations of the cycle's closed forms
#: ([pure], [compiled]: the hot_path_mode fixture of holonomic_testing)
pytestmark = pytest.mark.usefixtures("hot_path_mode")


class CorruptibleMock(MockDriver):
    """Ideal motors, plus injectable faults of the reading path."""

    velocity_spike = None          # (joint index, rad/s) for the next reading
    position_jump = None           # (joint index, rad) from the next reading on
    position_glitch = None         # (joint index, rad) in the next reading only
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
        if self.position_glitch is not None:
            positions[self.position_glitch[0]] += self.position_glitch[1]
            self.position_glitch = None
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
    # safety.glitch_policy fault: every invalid reading faults (test_glitch_policy.py
    # has drop, the default)
    ctrl, driver, clock = make(CorruptibleMock, **{"safety.glitch_policy": "fault"})
    arm(ctrl, clock)
    for _ in range(200):
        ctrl.set_command((0.4, 0.0, 0.0))
        run(ctrl, clock, 1)
    return ctrl, driver, clock


@pytest.mark.parametrize("spike", [4000.0, -4000.0])
def test_encoder_velocity_spike_faults_and_stops_naming_the_joint(moving, spike):
    ctrl, driver, clock = moving
    pose = ctrl.odometry.pose.copy()
    driver.velocity_spike = (1, spike)      # thousands of rad/s, either way, as encoders glitch
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


@pytest.mark.parametrize("jump", [50.0, -50.0])
def test_encoder_position_jump_faults_and_never_reaches_the_odometry(moving, jump):
    ctrl, driver, clock = moving
    driver.position_jump = (0, jump)        # 50 rad in one 5 ms cycle, forwards or back
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


@pytest.mark.parametrize("glitch", [50.0, -50.0])
def test_a_glitch_that_returns_faults_once_and_leaves_the_odometry_alone(moving, glitch):
    """One reading 50 rad off (a bit error on the bus), the next back on the
    encoder's track. The glitch faults the base; it never becomes the
    reference, so the good reading after it is no second jump (neither the
    +-50 rad there nor the -+50 rad back reach the odometry: 50 rad on a
    6 cm wheel would be 3 m), and re-armed the base drives on."""
    ctrl, driver, clock = moving
    pose = ctrl.odometry.pose.copy()
    faults = ctrl.counters["implausible_readings"]
    driver.position_glitch = (0, glitch)
    run(ctrl, clock, 1)
    assert ctrl.state is ControllerState.FAULT
    # 50 rad less or more the wheel's 6.5 rad/s x 5 ms of true motion
    assert ctrl.fault.startswith("left_wheel_joint: position jumped by ")
    assert abs(float(ctrl.fault.split(" by ")[1].split()[0]) - 50.0) < 0.1, ctrl.fault
    run(ctrl, clock, 20)                    # back on track; the base is stopped
    assert ctrl.counters["implausible_readings"] == faults + 1
    # at most the cycle before the fault's motion (0.4 m/s x 5 ms) and the stop
    assert np.linalg.norm(ctrl.odometry.pose[:2] - pose[:2]) < 0.01
    arm(ctrl, clock)
    ctrl.set_command((0.4, 0.0, 0.0))
    run(ctrl, clock, 100)
    assert ctrl.state is ControllerState.ARMED and ctrl.twist_command[0] > 0.3
    # 0.5 s forward at up to 0.4 m/s: forward, never a 3 m leap
    moved = ctrl.odometry.pose[:2] - pose[:2]
    assert 0.02 < np.linalg.norm(moved) < 0.25


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_a_single_glitch_reading_is_named_and_the_next_good_one_passes(sign):
    """By hand, a 1 rad/s joint at rest, bound 3 x 1 rad/s x 0.25 s = 0.75 rad:
    a reading 2 rad off either way is a jump of 2 rad; the next, back at 0,
    is compared with the last good reading (0 rad, 0.5 s before): no jump.
    A reading 2 rad off that stays is named once, then (as it is never
    accepted) named again on the next reading."""
    limits = MonitorLimits(3.0, 0.5, 0.3, 0.5)
    monitor = ReadingMonitor(["a"], [1.0], 0.25, limits)
    assert monitor.check(JointReading(1.0, [0.0], [0.0], []), 1.0) is None
    assert monitor.check(JointReading(1.25, [2.0 * sign], [0.0], []), 1.25) == (
        "a: position jumped by 2 rad in 0.25 s: encoder glitch")
    assert monitor.check(JointReading(1.5, [0.0], [0.0], []), 1.5) is None
    assert monitor.check(JointReading(1.75, [2.0 * sign], [0.0], []), 1.75) is not None
    assert monitor.check(JointReading(2.0, [2.0 * sign], [0.0], []), 2.0) is not None


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


def test_samples_bunched_by_a_loop_stall_are_motion_not_a_glitch():
    """A control loop that stalls 100 ms, then runs its catch-up cycle 0.7 ms
    later (ControlLoop does one at once after an overrun). A drive's sample
    taken at the last SYNC before the stall is handled late, after the next
    SYNC, so the host stamps it with that SYNC; the next sample, 0.7 ms of
    stamps later, carries the whole stall's motion. On a real bus under load
    (the CiA 402 rig with two busy CPUs beside it) this was a false "encoder
    glitch: position jumped by 0.21 rad in 0.7 ms" that stopped the base."""
    period, speed = 0.005, 10.0                     # one joint at half its 20 rad/s limit
    # the safety.* defaults of the controller's schema
    monitor = ReadingMonitor(["wheel"], [20.0], period, MonitorLimits(3.0, 0.05, 0.3, 0.5))

    def check(now, stamp, sampled_at):
        return monitor.check(JointReading(stamp, [speed * sampled_at], [speed], []), now)

    for k in range(10):                             # steady 200 Hz, stamps on time
        assert check(k * period, k * period, k * period) is None
    last = 9 * period
    # the stall: the sample of t = last is stamped with the SYNC after the stall
    assert check(last + 0.1, last + 0.1, last) is None
    # catch-up cycle 0.7 ms later: 10 rad/s * 0.1 s = 1 rad "in 0.7 ms", over
    # the period's bound of 3 * 20 rad/s * 5 ms = 0.3 rad, within the stall's
    # 3 * 20 * 0.1 = 6 rad
    assert check(last + 0.1007, last + 0.1007, last + 0.1) is None
    # a real glitch right after the stall is still one (50 rad > 6 rad) ...
    glitch = monitor.check(JointReading(last + 0.1057, [50.0], [speed], []), last + 0.1057)
    assert glitch is not None and "position jumped" in glitch


@pytest.mark.parametrize("checks_after_stall, glitch", [(3, False), (4, True)])
def test_a_stall_widens_the_glitch_bound_for_four_checks(checks_after_stall, glitch):
    """The check that sees a 100 ms gap and the next three (four: 20 ms at
    200 Hz, time for samples queued during the stall to come in) allow the
    stall's motion; the fourth check after it is back to the period's bound
    (3 * 20 rad/s * 5 ms = 0.3 rad): a 1 rad jump is a glitch again."""
    period = 0.005
    monitor = ReadingMonitor(["wheel"], [20.0], period, MonitorLimits(3.0, 0.05, 0.3, 0.5))
    t = 0.0
    for _ in range(5):
        assert monitor.check(JointReading(t, [0.0], [0.0], []), t) is None
        t += period
    t += 0.1                                        # the stall
    assert monitor.check(JointReading(t, [0.0], [0.0], []), t) is None
    for _ in range(checks_after_stall - 1):
        t += period
        assert monitor.check(JointReading(t, [0.0], [0.0], []), t) is None
    t += period
    problem = monitor.check(JointReading(t, [1.0], [0.0], []), t)
    assert (problem is not None and "position jumped by 1 rad" in problem) == glitch, problem


def test_monitor_limits_cannot_change_under_a_running_monitor():
    limits = MonitorLimits(3.0, 0.05, 0.3, 0.5)
    with pytest.raises(AttributeError):
        limits.velocity_factor = 100.0            # frozen: a config, not state


@pytest.mark.parametrize("measured, faults", [(5.0, False), (3.0, True)])
def test_tracking_error_faults_only_over_its_fraction_of_the_limit(measured, faults):
    """tracking_error 0.3 of a 20 rad/s limit = 6 rad/s: a joint told 10 rad/s
    that turns at 5 (5 off) follows; at 3 (7 off) it cannot, once
    that has lasted tracking_timeout (0.5 s)."""
    period = 0.005
    monitor = ReadingMonitor(["wheel"], [20.0], period, MonitorLimits(3.0, 0.05, 0.3, 0.5))
    command = np.array([10.0])
    problems = []
    for k in range(121):                             # 0.6 s > tracking_timeout
        t = k * period
        problems.append(monitor.check(JointReading(t, [measured * t], [measured], []), t,
                                      command))
    assert all(p is None for p in problems[:100])    # the first 0.5 s: never
    late = [p for p in problems[100:] if p is not None]
    assert bool(late) == faults, late
    if faults:
        assert "wheel: cannot follow its command (10 rad/s commanded, 3 rad/s" in late[0]


@pytest.mark.parametrize("positions, velocities, sizes", [
    ([0.0, 0.0], [0.0, 0.0, 0.0], (2, 3)), ([0.0, 0.0, 0.0], [0.0], (3, 1)),
    (0.0, 0.0, (0, 0))])                                    # scalars: no joints at all
def test_a_reading_of_the_wrong_size_is_named(positions, velocities, sizes):
    monitor = ReadingMonitor(["a", "b", "c"], [1.0, 1.0, 1.0], 0.005,
                             MonitorLimits(3.0, 0.05, 0.3, 0.5))
    problem = monitor.check(JointReading(0.0, positions, velocities, []), 0.0)
    assert problem == (f"driver returned {sizes[0]} positions and {sizes[1]} "
                       "velocities for 3 joints")


def test_a_zero_reading_timeout_disables_the_frozen_check():
    monitor = ReadingMonitor(["a"], [1.0], 0.005, MonitorLimits(3.0, 0.0, 0.3, 0.5))
    for k in range(100):                    # the same stamp for 0.5 s
        assert monitor.check(JointReading(1.0, [0.0], [0.0], []), 1.0 + k * 0.005) is None


def test_readings_frozen_for_exactly_the_timeout_are_not_yet_stale():
    """Stale means frozen for longer than reading_timeout (0.5 s here): the
    same stamp checked 0.5 s after it last changed is still accepted, 0.5 s
    + one period later it is named (times chosen exact in binary)."""
    monitor = ReadingMonitor(["a"], [1.0], 0.25, MonitorLimits(3.0, 0.5, 0.3, 0.5))
    assert monitor.check(JointReading(1.0, [0.0], [0.0], []), 1.0) is None
    assert monitor.check(JointReading(1.0, [0.0], [0.0], []), 1.5) is None
    assert monitor.check(JointReading(1.0, [0.0], [0.0], []), 1.75) == (
        "joint readings stopped updating 0.750 s ago")


def test_glitch_bounds_are_inclusive_with_a_micro_radian_allowance():
    """By hand, velocity factor 3 on a 1 rad/s joint: a speed reading of
    exactly 3 rad/s is accepted, more is a glitch. Over dt = 0.25 s (the
    period; exact in binary) a position may move 3 x 0.25 = 0.75 rad plus
    1e-6 rad of rounding allowance: 0.75 rad is accepted, 0.7500015 rad is
    a jump. A repeated stamp (dt = 0) still bounds the jump by a period."""
    limits = MonitorLimits(3.0, 0.5, 0.3, 0.5)

    def monitor():
        m = ReadingMonitor(["a"], [1.0], 0.25, limits)
        assert m.check(JointReading(1.0, [0.0], [0.0], []), 1.0) is None
        return m

    assert monitor().check(JointReading(1.25, [0.0], [3.0], []), 1.25) is None
    # (the message rounds 3.0001 to 4 significant digits)
    assert monitor().check(JointReading(1.25, [0.0], [3.0001], []), 1.25) == (
        "a: velocity reading 3 rad/s is over 3x its limit (1 rad/s): encoder glitch")
    assert monitor().check(JointReading(1.25, [0.75], [0.0], []), 1.25) is None
    assert monitor().check(JointReading(1.25, [0.7500015], [0.0], []), 1.25) == (
        "a: position jumped by 0.75 rad in 0.25 s: encoder glitch")
    assert monitor().check(JointReading(1.0, [1.0], [0.0], []), 1.25) == (
        "a: position jumped by 1 rad in 0 s: encoder glitch")
    # the same bounds backwards: a speed of -3 rad/s and a step of -0.75 rad
    # are accepted, -3.0001 rad/s and -0.7500015 rad are glitches
    assert monitor().check(JointReading(1.25, [0.0], [-3.0], []), 1.25) is None
    assert monitor().check(JointReading(1.25, [0.0], [-3.0001], []), 1.25) == (
        "a: velocity reading -3 rad/s is over 3x its limit (1 rad/s): encoder glitch")
    assert monitor().check(JointReading(1.25, [-0.75], [0.0], []), 1.25) is None
    assert monitor().check(JointReading(1.25, [-0.7500015], [0.0], []), 1.25) == (
        "a: position jumped by 0.75 rad in 0.25 s: encoder glitch")


def test_a_zero_tracking_timeout_disables_the_tracking_check():
    """tracking_timeout 0 disables the check: a joint that never follows its
    command (2 rad/s commanded, 0 measured, far over 0.3 x 1 rad/s) is not
    named, however long it lasts."""
    monitor = ReadingMonitor(["a"], [1.0], 0.25, MonitorLimits(3.0, 0.5, 0.3, 0.0))
    for k in range(10):
        assert monitor.check(JointReading(1.0 + 0.25 * k, [0.0], [0.0], []), 1.0 + 0.25 * k,
                             np.array([2.0])) is None


def test_tracking_timer_starts_when_armed_and_names_the_time():
    """By hand, tracking error 0.25 of a 1 rad/s limit and a 0.5 s timeout,
    checks every 0.25 s: while disarmed (no command) nothing is timed; armed
    with 2 rad/s commanded and 0 measured the timer starts at the first
    armed check (1.25 s) and the joint is named once it has not followed for
    the whole timeout (at 1.75 s: 0.50 s). A joint exactly at the tracking
    bound (1.75 of 2 rad/s: 0.25 off) follows, however long."""
    limits = MonitorLimits(3.0, 0.5, 0.25, 0.5)
    monitor = ReadingMonitor(["a"], [1.0], 0.25, limits)
    assert monitor.check(JointReading(1.0, [0.0], [0.0], []), 1.0, None) is None
    for t in (1.25, 1.5):
        assert monitor.check(JointReading(t, [0.0], [0.0], []), t, np.array([2.0])) is None
    assert monitor.check(JointReading(1.75, [0.0], [0.0], []), 1.75, np.array([2.0])) == (
        "a: cannot follow its command (2 rad/s commanded, 0 rad/s measured for 0.50 s): "
        "motor saturated or blocked")
    at_bound = ReadingMonitor(["a"], [1.0], 0.25, limits)
    for k in range(8):
        t = 1.0 + 0.25 * k
        assert at_bound.check(JointReading(t, [0.4375 * k], [1.75], []), t,
                              np.array([2.0])) is None
