"""Direction-preserving limits and encoder odometry (ROS-free)."""

import math

import numpy as np
import pytest

from holonomic_core.limits import TwistLimiter, saturate_joint_rates
from holonomic_core.model import load_model
from holonomic_core.odometry import Odometry, OdometryNoise
from holonomic_core.se2 import compose_arc

LIMITER = TwistLimiter(max_velocity=(1.0, 0.5, 2.0), max_acceleration=(2.0, 1.0, 4.0),
                       max_deceleration=(4.0, 2.0, 8.0))


def unit(v):
    return np.asarray(v) / np.linalg.norm(v)


def test_velocity_limit_scales_the_whole_twist_and_keeps_its_direction():
    # y is limited to 0.5: (1.0, 1.0, 0) scales by 0.5 to (0.5, 0.5, 0), not (1.0, 0.5, 0)
    out, scale = LIMITER.limit_velocity(np.array([1.0, 1.0, 0.0]))
    np.testing.assert_allclose(out, [0.5, 0.5, 0.0])
    assert scale == pytest.approx(0.5)


def test_velocity_limit_by_hand():
    # (2, 0.25, 1): x is twice its 1.0 m/s limit, so everything is halved
    limited, scale = LIMITER.limit_velocity(np.array([2.0, 0.25, 1.0]))
    assert scale == 0.5 and limited.tolist() == [1.0, 0.125, 0.5]
    # within every limit: unchanged, scale exactly 1, and a copy
    within = np.array([0.5, -0.5, 2.0])
    limited, scale = LIMITER.limit_velocity(within)
    assert scale == 1.0 and limited.tolist() == within.tolist() and limited is not within


@pytest.mark.parametrize("limits", [
    dict(max_velocity=(1.0, 0.0, 2.0)),                  # a zero limit
    dict(max_velocity=(1.0, -0.5, 2.0)),                 # a negative one
    dict(max_velocity=(1.0, 0.5)),                       # two axes
    dict(max_acceleration=(2.0, math.inf, 4.0)),         # not finite
])
def test_limits_that_are_not_three_positive_numbers_are_refused(limits):
    args = dict(max_velocity=(1.0, 0.5, 2.0), max_acceleration=(2.0, 1.0, 4.0),
                max_deceleration=(4.0, 2.0, 8.0))
    args.update(limits)
    name = next(iter(limits))
    with pytest.raises(ValueError, match=rf"^TwistLimiter {name} must be 3 finite numbers > 0"):
        TwistLimiter(**args)


def test_an_axis_that_does_not_change_does_not_stop_the_others_being_limited():
    # x holds 0.5 m/s; y asks for 0 -> 1.0 m/s: 1.0 m/s^2 * 0.1 s = 0.1 m/s of it
    out = LIMITER.limit_acceleration(np.array([0.5, 1.0, 0.0]), np.array([0.5, 0.0, 0.0]), 0.1)
    np.testing.assert_allclose(out, [0.5, 0.1, 0.0], atol=1e-12)


def test_acceleration_ramps_along_the_commanded_direction():
    prev = np.zeros(3)
    target = np.array([0.5, 0.5, 1.0])  # within speed limits
    dt = 0.01
    # from rest: allowed changes per step 0.02, 0.01, 0.04 -> the y axis binds,
    # scale = 0.01 / 0.5 = 0.02 -> (0.01, 0.01, 0.02)
    out = LIMITER.limit_acceleration(target, prev, dt)
    np.testing.assert_allclose(out, [0.01, 0.01, 0.02])
    for _ in range(200):
        prev = LIMITER.limit_acceleration(target, prev, dt)
        np.testing.assert_allclose(unit(prev), unit(target), atol=1e-12)
    np.testing.assert_allclose(prev, target)


def test_deceleration_limit_applies_when_slowing_down():
    prev = np.array([1.0, 0.0, 0.0])
    out = LIMITER.limit_acceleration(np.zeros(3), prev, 0.01)
    # decel 4 m/s^2 * 0.01 s = 0.04
    np.testing.assert_allclose(out, [0.96, 0.0, 0.0])


def test_joint_saturation_scales_all_joints_by_one_factor():
    rates = np.array([30.0, -10.0, 2.0])
    out, scale = saturate_joint_rates(rates, np.array([20.0, 20.0, 4.0]))
    assert scale == pytest.approx(20.0 / 30.0)
    np.testing.assert_allclose(out, rates * scale)
    same, one = saturate_joint_rates(np.array([1.0, 2.0, 3.0]), np.array([20.0, 20.0, 4.0]))
    assert one == 1.0 and np.all(same == [1.0, 2.0, 3.0])


def test_joint_saturation_of_a_strafe_keeps_the_twist_direction():
    """Saturated joint rates map back (forward kinematics) to a twist
    parallel to the command: the path does not bend."""
    model = load_model("hamr")
    rng = np.random.default_rng(7)
    for _ in range(200):
        q = np.array([0.0, 0.0, rng.uniform(-math.pi, math.pi)])
        twist = rng.uniform(-3, 3, 3)
        rates, scale = saturate_joint_rates(model.inverse(q, twist), model.max_joint_velocity)
        assert np.all(np.abs(rates) <= model.max_joint_velocity + 1e-9)
        np.testing.assert_allclose(model.forward(q, rates), twist * scale, atol=1e-9)


def test_non_finite_rates_never_become_motion():
    out, scale = saturate_joint_rates(np.array([np.nan, 1.0, 1.0]), np.array([1.0, 1.0, 1.0]))
    assert scale == 0.0 and np.all(out == 0.0)


def test_compose_arc_matches_the_analytic_circle():
    # constant twist vx = 1 m/s, wz = 1 rad/s for pi/2 s from heading 0:
    # a quarter circle of radius 1 from (0,0) ends at (1, 1)
    dx, dth = math.pi / 2, math.pi / 2
    wx, wy = compose_arc(np.zeros(3), dx, 0.0, dth)
    assert (wx, wy) == pytest.approx((1.0, 1.0), abs=1e-12)


def drive(model, odo, q0, twist, seconds, rate=200.0, stamp0=0.0):
    """Feed odometry encoder positions of a base driven by a constant twist
    (joint rates re-solved each step, integrated with small sub-steps)."""
    q = np.array(q0, dtype=float)
    dt = 1.0 / rate
    t = stamp0
    for _ in range(int(round(seconds * rate))):
        for _ in range(10):
            q = q + model.inverse(q, twist) * dt / 10
        t += dt
        odo.update(q, t)
    return q, t


def test_odometry_integrates_a_circle_exactly():
    model = load_model("hamr")
    odo = Odometry(model)
    odo.update(np.zeros(3), 0.0)
    # vx = 0.5 m/s, wz = 0.5 rad/s: radius 1 m, one full circle in 4 pi s
    drive(model, odo, np.zeros(3), np.array([0.5, 0.0, 0.5]), 4 * math.pi, rate=200)
    assert odo.pose[:2] == pytest.approx([0.0, 0.0], abs=2e-3)
    assert odo.pose[2] == pytest.approx(0.0, abs=2e-3)
    assert odo.distance == pytest.approx(2 * math.pi, rel=1e-3)
    np.testing.assert_allclose(odo.twist, [0.5, 0.0, 0.5], atol=1e-3)


def test_odometry_uses_displacement_so_stalls_and_backward_clocks_do_not_jump():
    model = load_model("hamr")
    odo = Odometry(model)
    odo.update(np.zeros(3), 10.0)
    # 0.2 m forward in one 200 ms stall
    q = model.inverse([0, 0, 0], [1.0, 0, 0]) * 0.2
    odo.update(q, 10.2)
    assert odo.pose[0] == pytest.approx(0.2, abs=1e-12)
    # clock jumps backwards while the wheels move 0.1 m more: pose follows the
    # wheels, no NaN, and the reported velocity is kept from before
    odo.update(q * 1.5, 5.0)
    assert odo.pose[0] == pytest.approx(0.3, abs=1e-12)
    assert np.all(np.isfinite(odo.twist))
    assert odo.twist[0] == pytest.approx(1.0)


def test_odometry_skips_non_finite_encoder_readings():
    model = load_model("hamr")
    odo = Odometry(model)
    odo.update(np.zeros(3), 0.0)
    assert odo.update(np.array([np.nan, 0.0, 0.0]), 0.01) is False
    assert np.all(odo.pose == 0.0)


def test_pose_covariance_grows_with_distance_and_resets():
    model = load_model("hamr")
    odo = Odometry(model, noise=OdometryNoise(linear_variance_per_meter=1e-3))
    odo.update(np.zeros(3), 0.0)
    drive(model, odo, np.zeros(3), np.array([1.0, 0.0, 0.0]), 1.0)
    first = odo.pose_covariance[1, 1]
    # along-track variance: 1e-3 m^2/m * 1 m
    assert odo.pose_covariance[0, 0] == pytest.approx(1e-3, rel=1e-3)
    q, t = drive(model, odo, model.inverse([0, 0, 0], [1.0, 0, 0]) * 1.0,
                 np.array([1.0, 0.0, 0.0]), 1.0, stamp0=1.0)
    assert odo.pose_covariance[1, 1] > first
    assert np.allclose(odo.pose_covariance, odo.pose_covariance.T)
    assert np.all(np.linalg.eigvalsh(odo.pose_covariance) >= -1e-15)
    odo.reset()
    assert np.all(odo.pose_covariance == 0.0) and np.all(odo.pose == 0.0)
    # after a reset the next reading is the new reference: no jump
    odo.update(q, t + 0.01)
    assert np.all(odo.pose == 0.0)


def test_compose_arc_is_the_chord_of_the_constant_twist_arc():
    """By hand: a constant body twist (dx, dy) per unit time with a turn of
    dtheta moves the body, in its start frame, by V (dx, dy) with
    V = [[sin t / t, -(1 - cos t) / t], [(1 - cos t) / t, sin t / t]], then
    rotated by the start heading. A quarter turn (t = pi/2): sin t / t =
    (1 - cos t) / t = 2 / pi."""
    k = 2.0 / math.pi
    assert compose_arc((0.0, 0.0, 0.0), 1.0, 0.0, math.pi / 2) == pytest.approx((k, k))
    assert compose_arc((0.0, 0.0, 0.0), 0.0, 1.0, math.pi / 2) == pytest.approx((-k, k))
    # started at heading pi/2: the body-frame (k, k) is (-k, k) in the world
    assert compose_arc((5.0, -3.0, math.pi / 2), 1.0, 0.0, math.pi / 2) == pytest.approx((-k, k))
    # below 1e-6 rad the series: sin t / t = 1 - t^2 / 6, (1 - cos t) / t = t / 2,
    # exact to float rounding against the closed forms (t = 9e-7: the t^2 / 6
    # term is 1.35e-13, a 1/7 in its place would be 1.9e-14 off)
    t = 9e-7
    x, y = compose_arc((0.0, 0.0, 0.0), 1.0, 0.0, t)
    assert x == pytest.approx(math.sin(t) / t, rel=0, abs=2e-15)
    # (1 - cos t) / t = t / 2 - t^3 / 24: t / 2 to 1e-13 relative (the
    # closed form itself loses 4 digits to cancellation here)
    assert y == pytest.approx(t / 2, rel=1e-9)
