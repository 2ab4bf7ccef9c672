"""The control cycle in torque mode, without ROS or the simulator: the
XR4000 (a PCV, the family with a dynamic model) on an effort-capable
stand-in driver that holds its joints still and records every command.

The expected torques follow the paper's law (Holmberg & Khatib, Sec. 4) with
the numbers worked by hand in each test: the PD law on the reference,
F* = -Kp e - Kv e_dot + x_ddot_d (eq. 6), in base_link; the wrench F =
Lambda F* + mu (eq. 5) with Lambda from pcv_base's dynamic model and mu = 0
at rest (mu is quadratic in the twist: ``PcvDynamics.terms``' docstring, and
the joints never move here, so the odometry's twist stays 0); the joint
torques C#^T F (eq. 14, ``PcvDynamics.torque_distribution``). The gains
differ per axis so that a mixed-up axis shows.
"""

import dataclasses
import math

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController, ControllerState
from holonomic_core.driver import DriverCommunicationError
from holonomic_testing.effort_driver import EffortRecorder
from pcv_base.dynamics import PcvDynamics

KP = (36.0, 25.0, 16.0)      # torque.kp [1/s^2] (x, y, yaw)
KV = (12.0, 10.0, 8.0)       # torque.kv [1/s]
#: where the stand-in holds the joints: steering angles apart from zero and
#: from each other (so Lambda has off-diagonal terms), wheels anywhere
POSITIONS = np.array([0.3, 1.0, -0.2, 2.0, 0.5, -1.0, 0.1, 0.0])


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def make():
    cfg = load_config("xr4000", {"driver": "mock", "torque.kp": list(KP),
                                 "torque.kv": list(KV)})
    # the configuration refuses torque mode on the mock backend (it has none);
    # the stand-in has one, so the mode is set on the validated config
    cfg = dataclasses.replace(cfg, controller=dataclasses.replace(cfg.controller,
                                                                  control_mode="torque"))
    assert not cfg.model.zero_corrections.any()     # the law sees POSITIONS as they are
    clock = FakeClock()
    driver = EffortRecorder(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock)
    driver.positions[:] = POSITIONS
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=clock)
    return ctrl, driver, clock, PcvDynamics.from_model(cfg.model)


def run(ctrl, clock, cycles=1):
    results = []
    for _ in range(cycles):
        clock.t += ctrl.dt
        results.append(ctrl.step())
    return results


def arm(ctrl, clock):
    fut = ctrl.request_enable(True)
    run(ctrl, clock)
    assert fut.result(timeout=0) == (True, "motors armed")


def expected_torques(dyn, f_star):
    """Eqs. 5 and 14 at rest: C#^T (Lambda F*), Lambda at POSITIONS."""
    lam, mu = dyn.terms(POSITIONS, np.zeros(3))
    assert np.all(mu == 0.0)
    return dyn.torque_distribution(POSITIONS, lam @ np.asarray(f_star))


def within_limits(torques):
    """max |tau_i| / max_effort_i (xr4000.yaml: steering 5 N m, wheels 6 N m)."""
    return float(np.max(np.abs(torques) / np.tile([5.0, 6.0], 4)))


def test_torque_mode_writes_efforts_and_never_velocities():
    ctrl, driver, clock, _ = make()
    assert ctrl.torque is not None
    arm(ctrl, clock)
    ctrl.set_command((0.3, 0.0, 0.0))
    run(ctrl, clock, 5)
    kinds = [kind for kind, _ in driver.written]
    assert kinds == ["efforts"] * 6          # the arming cycle and five more
    # disarmed with safety.disarm_mode hold (the default): the torque law
    # holds the base at rest, still never a velocity
    ctrl.request_enable(False)
    run(ctrl, clock, 3)
    assert [kind for kind, _ in driver.written] == ["efforts"] * 9
    # disarmed again: the drives idle, the cycle writes nothing
    ctrl.request_enable(False)
    run(ctrl, clock, 3)
    assert len(driver.written) == 9


def test_at_rest_on_its_reference_the_base_gets_no_torque():
    """Arming restarts the reference at the measured pose, at rest: e = 0,
    e_dot = 0, x_ddot_d = 0, so F* = 0 and every torque is 0."""
    ctrl, driver, clock, _ = make()
    arm(ctrl, clock)
    run(ctrl, clock, 3)
    assert [list(e) for e in driver.efforts_written()] == [[0.0] * 8] * 4


def test_a_cmd_vel_cycle_writes_the_law_s_torques_for_the_limited_twist():
    """One cycle after (0.5 m/s, 0, 1.0 rad/s) is received, from rest.

    The limiter scales the change uniformly to the first cycle's allowance
    (dt = 1/200 s; x: 2.0 m/s^2 dt = 0.01, yaw: 6.0 rad/s^2 dt = 0.03):
    scale min(0.01/0.5, 0.03/1.0) = 0.02, so the reference twist is
    v = (0.01, 0, 0.02) and its acceleration v/dt = (2, 0, 4). The reference
    pose advances by the arc of the mean twist v/2 over dt: dx = 2.5e-5 m,
    dtheta = 5e-5 rad, i.e. (dx sin(dth)/dth, dx (1 - cos(dth))/dth, dth).
    The base stays at the origin with twist 0, so e = -ref_pose and
    e_dot = -(v turned by dtheta into the base frame)."""
    ctrl, driver, clock, dyn = make()
    arm(ctrl, clock)
    ctrl.set_command((0.5, 0.0, 1.0))
    run(ctrl, clock)
    dt, dx, dth = 0.005, 2.5e-5, 5e-5
    ref = (dx * math.sin(dth) / dth, dx * (1.0 - math.cos(dth)) / dth, dth)
    v_base = (0.01 * math.cos(dth), 0.01 * math.sin(dth), 0.02)
    accel = (0.01 / dt, 0.0, 0.02 / dt)
    f_star = [kp * r + kv * v + a for kp, kv, r, v, a in zip(KP, KV, ref, v_base, accel)]
    # x: 36 * 2.5e-5 + 12 * 0.01 + 2 = 2.1209; yaw: 16 * 5e-5 + 8 * 0.02 + 4 = 4.1608
    assert f_star[0] == pytest.approx(2.1209, abs=1e-9)
    assert f_star[2] == pytest.approx(4.1608, abs=1e-9)
    tau = expected_torques(dyn, f_star)
    assert within_limits(tau) < 1.0          # not scaled: the law's torques as they are
    np.testing.assert_allclose(driver.efforts_written()[-1], tau, rtol=1e-9, atol=1e-12)
    # the reading monitor's reference stays the joint rates of that twist
    np.testing.assert_allclose(ctrl.joint_command,
                               ctrl.model.inverse(POSITIONS, np.array([0.01, 0.0, 0.02])),
                               rtol=1e-9)


def test_at_the_joint_speed_limits_the_law_tracks_the_saturated_twist():
    """Sideways (vy 0.5 m/s) with the casters near straight ahead: each
    steering joint must turn at about vy / b = vy / 0.02 m, which reaches its
    12 rad/s limit near vy = 0.24 m/s, 24 cycles into the 0.01 m/s-per-cycle
    ramp. Then the joint rates are scaled (saturation < 1), and the torque
    law's reference is the scaled twist: the one the joints can do, which the
    limiter continues from (ctrl.twist_command), not the unscaled one.
    (The joints stand still, so the reading monitor's tracking check would
    fault 0.5 s after the steering commands pass 0.3 x 12 rad/s, near cycle
    8 + 100: 40 cycles stay clear of it.)"""
    ctrl, driver, clock, _ = make()
    arm(ctrl, clock)
    for _ in range(40):
        ctrl.set_command((0.0, 0.5, 0.0))
        run(ctrl, clock)
    assert ctrl.state is ControllerState.ARMED, ctrl.fault
    assert ctrl.saturation < 1.0
    np.testing.assert_allclose(ctrl.torque.ref_twist, ctrl.twist_command, rtol=1e-12)
    rates = ctrl.model.inverse(POSITIONS, ctrl.torque.ref_twist)
    assert np.max(np.abs(rates) / ctrl.model.max_joint_velocity) == pytest.approx(1.0, abs=1e-9)


def test_a_trajectory_sample_is_tracked_directly():
    """follow(): the sample's pose, twist and acceleration are the reference
    (no limiter in between). Sample: pose (0.01, 0.02, 0.03) in odom, twist
    (0.1, 0, 0.2), acceleration (0.5, 0, 0); the base at the origin at rest.
    e = -(0.01, 0.02, 0.03); e_dot = -(the reference twist turned by 0.03 rad
    into the base frame) = -(0.1 cos 0.03, 0.1 sin 0.03, 0.2)."""
    ctrl, driver, clock, dyn = make()
    arm(ctrl, clock)
    sample = ((0.01, 0.02, 0.03), (0.1, 0.0, 0.2), (0.5, 0.0, 0.0))
    ctrl.follow(lambda t: sample)
    run(ctrl, clock)
    f_star = [36.0 * 0.01 + 12.0 * 0.1 * math.cos(0.03) + 0.5,
              25.0 * 0.02 + 10.0 * 0.1 * math.sin(0.03),
              16.0 * 0.03 + 8.0 * 0.2]
    tau = expected_torques(dyn, f_star)
    assert within_limits(tau) < 1.0
    np.testing.assert_allclose(driver.efforts_written()[-1], tau, rtol=1e-9, atol=1e-12)


def test_a_sample_beyond_the_torque_limits_is_scaled_keeping_its_direction():
    """A 20 m/s^2 sample asks for more than the drives have: every torque is
    scaled by one factor, the largest then at its limit."""
    ctrl, driver, clock, dyn = make()
    arm(ctrl, clock)
    ctrl.follow(lambda t: ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (20.0, 0.0, 0.0)))
    run(ctrl, clock)
    raw = expected_torques(dyn, [20.0, 0.0, 0.0])
    worst = within_limits(raw)
    assert worst > 1.0
    written = driver.efforts_written()[-1]
    np.testing.assert_allclose(written, raw / worst, rtol=1e-9, atol=1e-12)
    assert within_limits(written) == pytest.approx(1.0, abs=1e-12)


# a hold sample off the base's pose: its first-cycle velocity pull,
# TRAJECTORY_GAIN (4/s) times the offset = (0.008, 0.004, 0.012), is within the
# first cycle's acceleration allowance (0.01, 0.01, 0.03), and the next
# cycle's deceleration allowance (0.01, 0.01, 0.04) brings it back to 0
HOLD_OFF = ((0.002, 0.001, 0.003), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
# F* on it: Kp times the offset (no twist, no acceleration)
HOLD_F_STAR = [36.0 * 0.002, 25.0 * 0.001, 16.0 * 0.003]


def test_the_reference_restarts_at_the_base_when_a_trajectory_ends():
    """The cycle after the last sample: back on cmd_vel (none: rest) with
    the reference at the measured pose, so no torque; a reference left at
    the last sample would pull with Kp times its offset."""
    ctrl, driver, clock, dyn = make()
    arm(ctrl, clock)
    ctrl.follow(lambda t: HOLD_OFF if t < 0.5 * ctrl.dt else None)
    run(ctrl, clock)
    np.testing.assert_allclose(driver.efforts_written()[-1],
                               expected_torques(dyn, HOLD_F_STAR), rtol=1e-9, atol=1e-12)
    run(ctrl, clock)
    assert np.all(ctrl.twist_command == 0.0)
    assert list(driver.efforts_written()[-1]) == [0.0] * 8


def test_arming_again_restarts_the_reference_at_the_base():
    ctrl, driver, clock, dyn = make()
    arm(ctrl, clock)
    ctrl.follow(lambda t: HOLD_OFF)
    run(ctrl, clock)
    np.testing.assert_allclose(driver.efforts_written()[-1],
                               expected_torques(dyn, HOLD_F_STAR), rtol=1e-9, atol=1e-12)
    ctrl.request_enable(False)
    run(ctrl, clock)
    arm(ctrl, clock)
    # the arming cycle: no command, the reference at the base: no torque
    assert list(driver.efforts_written()[-1]) == [0.0] * 8


def test_a_failed_torque_write_faults_and_disarms():
    ctrl, driver, clock, _ = make()
    arm(ctrl, clock)
    driver.fail_writes = DriverCommunicationError("no answer within 10 ms",
                                                  device="front_left_wheel_joint")
    ctrl.set_command((0.3, 0.0, 0.0))
    assert run(ctrl, clock) == [False]
    assert ctrl.state is ControllerState.FAULT
    assert "no answer within 10 ms" in ctrl.fault
    assert not driver.armed
    assert ctrl.counters["driver_errors"] == 1
    assert np.all(ctrl.twist_command == 0.0) and np.all(ctrl.joint_command == 0.0)


def test_velocity_mode_has_no_torque_law_and_writes_velocities():
    cfg = load_config("xr4000", {"driver": "mock"})
    clock = FakeClock()
    driver = EffortRecorder(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock)
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=clock)
    assert ctrl.torque is None
    arm(ctrl, clock)
    ctrl.set_command((0.3, 0.0, 0.0))
    run(ctrl, clock, 2)
    assert [kind for kind, _ in driver.written] == ["velocities"] * 3
