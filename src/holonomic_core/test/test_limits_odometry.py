"""Direction-preserving limits and encoder odometry (ROS-free)."""

import math

import numpy as np
import pytest

from holonomic_core.limits import TwistLimiter, joint_rate_saturation
from holonomic_core.model import load_model
from holonomic_core.odometry import Odometry, OdometryNoise
from holonomic_core.se2 import compose_arc

#: every test here runs on both implementations of the cycle's closed forms
#: ([pure], [compiled]: the hot_path_mode fixture of holonomic_testing)
pytestmark = pytest.mark.usefixtures("hot_path_mode")



def limiter():
    """The limits of these tests, built in the test (under its hot_path_mode)."""
    return TwistLimiter(max_velocity=(1.0, 0.5, 2.0), max_acceleration=(2.0, 1.0, 4.0),
                        max_deceleration=(4.0, 2.0, 8.0))


def saturate_joint_rates(rates, max_rates):
    """The joint-rate saturation the hot_path_mode selects (limits picks it at import)."""
    return joint_rate_saturation()(rates, max_rates)


def unit(v):
    return np.asarray(v) / np.linalg.norm(v)


def test_velocity_limit_scales_the_whole_twist_and_keeps_its_direction():
    # y is limited to 0.5: (1.0, 1.0, 0) scales by 0.5 to (0.5, 0.5, 0), not (1.0, 0.5, 0)
    out, scale = limiter().limit_velocity(np.array([1.0, 1.0, 0.0]))
    np.testing.assert_allclose(out, [0.5, 0.5, 0.0])
    assert scale == pytest.approx(0.5)


def test_velocity_limit_by_hand():
    # (2, 0.25, 1): x is twice its 1.0 m/s limit, so everything is halved
    limited, scale = limiter().limit_velocity(np.array([2.0, 0.25, 1.0]))
    assert scale == 0.5 and limited.tolist() == [1.0, 0.125, 0.5]
    # within every limit: unchanged, scale exactly 1, and a copy
    within = np.array([0.5, -0.5, 2.0])
    limited, scale = limiter().limit_velocity(within)
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
    out = limiter().limit_acceleration(np.array([0.5, 1.0, 0.0]), np.array([0.5, 0.0, 0.0]), 0.1)
    np.testing.assert_allclose(out, [0.5, 0.1, 0.0], atol=1e-12)


def test_acceleration_ramps_along_the_commanded_direction():
    prev = np.zeros(3)
    target = np.array([0.5, 0.5, 1.0])  # within speed limits
    dt = 0.01
    # from rest: allowed changes per step 0.02, 0.01, 0.04 -> the y axis binds,
    # scale = 0.01 / 0.5 = 0.02 -> (0.01, 0.01, 0.02)
    out = limiter().limit_acceleration(target, prev, dt)
    np.testing.assert_allclose(out, [0.01, 0.01, 0.02])
    for _ in range(200):
        prev = limiter().limit_acceleration(target, prev, dt)
        np.testing.assert_allclose(unit(prev), unit(target), atol=1e-12)
    np.testing.assert_allclose(prev, target)


def test_limit_is_the_speed_limit_then_the_acceleration_ramp_in_one_call():
    """TwistLimiter.limit, the call the controller makes each cycle (compiled
    or pure). (2, 0.25, 1) from rest over 0.1 s: the speed limits halve it to
    (1, 0.125, 0.5); from rest the ramp allows 0.2, 0.1, 0.4 per step
    (2, 1, 4 m/s^2 x 0.1 s), so x binds: scale 0.2 -> (0.2, 0.025, 0.1).
    Slowing from there to rest: 4, 2, 8 m/s^2 x 0.1 s allow 0.4, 0.2, 0.8,
    more than the changes: rest at once. A reversal, (-1, 0, 0) from
    (0.2, 0, 0), is bounded by the deceleration: 0.4 of the 1.2 change ->
    -0.2 m/s."""
    lim = limiter()
    out = lim.limit(np.array([2.0, 0.25, 1.0]), np.zeros(3), 0.1)
    np.testing.assert_allclose(out, [0.2, 0.025, 0.1], rtol=1e-12)
    np.testing.assert_array_equal(lim.limit(np.zeros(3), out, 0.1), [0.0, 0.0, 0.0])
    np.testing.assert_allclose(lim.limit(np.array([-1.0, 0.0, 0.0]), np.array([0.2, 0.0, 0.0]),
                                         0.1), [-0.2, 0.0, 0.0], rtol=1e-12)


def test_deceleration_limit_applies_when_slowing_down():
    prev = np.array([1.0, 0.0, 0.0])
    out = limiter().limit_acceleration(np.zeros(3), prev, 0.01)
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
    # the distance term alone (the default latency term would add
    # latency_variance x (1 m/s)^2 along the track while moving)
    odo = Odometry(model, noise=OdometryNoise(linear_variance_per_meter=1e-3,
                                              latency_variance=0.0))
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


# --- the covariance model and the twist window, term by term (OdometryNoise) ---

def _noise(**terms):
    """An OdometryNoise with every term zero except ``terms``."""
    zero = dict(linear_variance_per_meter=0.0, angular_variance_per_radian=0.0,
                angular_variance_per_meter=0.0, slip_position_gain=0.0, slip_heading_gain=0.0,
                twist_variance=(0.0, 0.0, 0.0), twist_slip_gain=(0.0, 0.0, 0.0),
                twist_lag_gain=(0.0, 0.0, 0.0), latency_variance=0.0, slip4_position_gain=0.0,
                slip4_heading_gain=0.0)
    zero.update(terms)
    return OdometryNoise(**zero)


def test_the_default_noise_is_the_xr4000_profile_of_its_config():
    """The docstring promises the defaults are config/xr4000.yaml's calibrated
    profile: a user who builds Odometry(model) without a noise gets those numbers."""
    import pathlib
    import yaml

    root = pathlib.Path(__file__).resolve().parents[3]
    with open(root / "config" / "xr4000.yaml") as f:
        config = yaml.safe_load(f)

    def find(node):
        if isinstance(node, dict):
            if "odometry" in node and isinstance(node["odometry"], dict):
                return node["odometry"]
            for value in node.values():
                found = find(value)
                if found is not None:
                    return found
        return None

    profile = find(config)
    default = OdometryNoise()
    for key, value in profile.items():
        if key == "twist_window":
            continue
        assert getattr(default, key) == (tuple(value) if isinstance(value, list) else value), key


@pytest.mark.parametrize("window", [-0.01, math.nan, math.inf, -math.inf])
def test_a_twist_window_that_is_not_a_finite_non_negative_time_is_refused(window):
    with pytest.raises(ValueError, match="twist_window"):
        Odometry(load_model("hamr"), twist_window=window)


def test_a_zero_twist_window_is_valid_and_uses_the_last_two_readings():
    model = load_model("hamr")
    odo = Odometry(model, twist_window=0)
    assert odo.twist_window == 0.0 and isinstance(odo.twist_window, float)
    odo.update(np.zeros(3), 0.0)
    # 0.01 m forward in 0.01 s, then 0.03 m in the next 0.01 s: the two-reading
    # difference is 3 m/s (a longer window would average it with the 1 m/s)
    q1 = model.inverse([0, 0, 0], [1.0, 0, 0]) * 0.01
    odo.update(q1, 0.01)
    odo.update(q1 * 4.0, 0.02)
    assert odo.twist[0] == pytest.approx(3.0, rel=1e-9)
    # with a window, the third reading is fitted with both earlier ones: the
    # line through (0, 0), (0.01, 0.01), (0.02, 0.04) has slope
    # sum (t - 0.01)(x - x_mean) / sum (t - 0.01)^2 = 0.0004 / 0.0002 = 2 m/s
    odo = Odometry(model, twist_window=0.05)
    odo.update(np.zeros(3), 0.0)
    odo.update(q1, 0.01)
    odo.update(q1 * 4.0, 0.02)
    assert odo.twist[0] == pytest.approx(2.0, rel=1e-9)


def _sums(n):
    """For n equal steps h of straight motion with heading variance c h per
    step, the written-out P' = F P F^T + Q with F = [[1, 0, -wy], [0, 1, wx],
    [0, 0, 1]] gives exactly, after n steps (p22 = c h k before step k):
    p_theta,pos = c h^2 sum_{k<n} k = c h^2 n (n - 1) / 2 along n_perp,
    p_pos,pos = c h^3 sum_{k<n} k^2 = c h^3 (n - 1) n (2n - 1) / 6 along n_perp n_perp^T
    (the continuum c L^2 / 2 and c L^3 / 3 of a heading error growing along
    the path, which swings the end point sideways by (L - s) dtheta)."""
    return n * (n - 1) / 2, (n - 1) * n * (2 * n - 1) / 6


def test_heading_drift_from_translation_swings_the_position_across_the_track():
    """angular_variance_per_meter c, a 1 m diagonal (45 deg) strafe at heading 0:
    n_perp = (-1, 1) / sqrt(2), so p00 = p11 = -p01 = c S3 h^3 / 2,
    p02 = -p12 = -c S2 h^2 / sqrt(2), p22 = c L; plus the isotropic
    linear_variance_per_meter k: + k L on p00 and p11 only."""
    model = load_model("hamr")
    c, k = 2e-3, 5e-4
    odo = Odometry(model, noise=_noise(angular_variance_per_meter=c,
                                       linear_variance_per_meter=k))
    odo.update(np.zeros(3), 0.0)
    s = math.sqrt(0.5)
    drive(model, odo, np.zeros(3), np.array([s, s, 0.0]), 1.0)   # 200 steps, h = 5 mm
    n, h = 200, 0.005
    s2, s3 = _sums(n)
    pp, pt = c * s3 * h ** 3 / 2, c * s2 * h ** 2 * s
    expected = np.array([[pp + k, -pp, -pt], [-pp, pp + k, pt], [-pt, pt, c * 1.0]])
    # the encoder path drives 1 m to ~1e-6 (sub-stepped inverse kinematics)
    np.testing.assert_allclose(odo.pose_covariance, expected, rtol=1e-4, atol=1e-12)
    assert odo.distance == pytest.approx(1.0, rel=1e-5)
    # the drive() path ends 1.3e-4 m off the diagonal (measured; sub-stepped
    # inverse kinematics of the turning turret): 5e-4
    np.testing.assert_allclose(odo.pose, [s, s, 0.0], atol=5e-4)


def test_heading_variance_per_radian_counts_a_clockwise_turn_too():
    """angular_variance_per_radian a: a turn on the spot of -1 rad (clockwise)
    adds a * |-1| rad to the heading variance and nothing to the position (no
    displacement, F = I)."""
    model = load_model("hamr")
    odo = Odometry(model, noise=_noise(angular_variance_per_radian=3e-3))
    odo.update(np.zeros(3), 0.0)
    drive(model, odo, np.zeros(3), np.array([0.0, 0.0, -1.0]), 1.0)
    assert odo.pose[2] == pytest.approx(-1.0, abs=1e-6)
    expected = np.diag([0.0, 0.0, 3e-3])
    np.testing.assert_allclose(odo.pose_covariance, expected, rtol=1e-5, atol=1e-12)


def test_heading_uncertainty_swings_the_position_on_a_step_that_adds_no_noise():
    """A heading variance s2 already accumulated (a turn on the spot, per-radian
    term only) must carry into the position on a straight run that adds no
    noise of its own (equal wheel increments, turret still: dtheta exactly 0,
    no per-metre term). Each step's F = I + E with E non-zero only in the
    heading column (-wy, wx); E_i E_j = 0, so the steps compose to one F with
    (-Dy, Dx) and P' = F P F^T: p00 = Dy^2 s2, p11 = Dx^2 s2, p01 = -Dx Dy s2,
    p02 = -Dy s2, p12 = Dx s2, p22 = s2. (The update once returned early on a
    step with no added noise and left the position variance at 0.)"""
    model = load_model("hamr")
    odo = Odometry(model, noise=_noise(angular_variance_per_radian=1e-2))
    odo.update(np.zeros(3), 0.0)
    q, t = drive(model, odo, np.zeros(3), np.array([0.0, 0.0, 1.0]), 1.0)
    s2 = odo.pose_covariance[2, 2]
    assert s2 == pytest.approx(1e-2, rel=1e-5)
    start = odo.pose.copy()
    for k in range(100):                     # 5 cm of wheel a step: 0.31 m in all
        q = q + np.array([0.05, 0.05, 0.0])
        odo.update(q, t + 0.01 * (k + 1))
    dx, dy = odo.pose[:2] - start[:2]
    assert odo.pose[2] == start[2] and math.hypot(dx, dy) > 0.3
    expected = s2 * np.array([[dy * dy, -dx * dy, -dy], [-dx * dy, dx * dx, dx], [-dy, dx, 1.0]])
    np.testing.assert_allclose(odo.pose_covariance, expected, rtol=1e-9, atol=1e-15)


def test_the_unexplained_contact_velocity_grows_pose_and_twist_variance():
    """XR4000 (8 joints, 3 dof): one wheel turns 0.02 rad more than a rigid
    base allows in 0.01 s. slip = RMS of the residual over its entries; one
    increment from P = 0 adds exactly Q: position slip_position_gain rho^2 dt
    on x and y, heading slip_heading_gain rho^2 dt; the twist variance (window
    0: no lag term) is twist_variance + twist_slip_gain rho^2 per axis."""
    model = load_model("xr4000")
    noise = _noise(slip_position_gain=0.3, slip_heading_gain=2.0,
                   twist_variance=(1e-6, 2e-6, 3e-6), twist_slip_gain=(0.5, 0.25, 4.0),
                   twist_lag_gain=(7.0, 7.0, 7.0))
    odo = Odometry(model, noise=noise)
    q0 = np.zeros(len(model.joint_names))
    odo.update(q0, 0.0)
    q1 = q0.copy()
    wheel = next(i for i, name in enumerate(model.joint_names) if "steer" not in name)
    q1[wheel] = 0.02
    assert odo.update(q1, 0.01) is True
    residual = odo.residual
    assert residual.size > 0
    rho = math.sqrt(float(residual @ residual) / residual.size)
    assert odo.slip == pytest.approx(rho, rel=1e-12) and rho > 1e-3
    P = odo.pose_covariance
    assert P[0, 0] == pytest.approx(0.3 * rho ** 2 * 0.01, rel=1e-9)
    assert P[1, 1] == pytest.approx(0.3 * rho ** 2 * 0.01, rel=1e-9)
    assert P[2, 2] == pytest.approx(2.0 * rho ** 2 * 0.01, rel=1e-9)
    assert P[0, 1] == P[0, 2] == P[1, 2] == 0.0
    np.testing.assert_allclose(np.diag(odo.twist_covariance),
                               np.array([1e-6, 2e-6, 3e-6]) + np.array([0.5, 0.25, 4.0]) * rho ** 2,
                               rtol=1e-9)


def test_the_fourth_power_slip_terms_grow_sixteenfold_with_twice_the_slip():
    """The rho^4 terms: one increment from P = 0 adds slip4_position_gain
    rho^4 dt on x and y and slip4_heading_gain rho^4 dt on the heading, on
    top of the rho^2 terms; the same wheel error twice as large (twice the
    residual) adds 4x the rho^2 part and 16x the rho^4 part."""
    model = load_model("xr4000")
    noise = _noise(slip_position_gain=0.3, slip_heading_gain=2.0, slip4_position_gain=50.0,
                   slip4_heading_gain=700.0)
    wheel = next(i for i, name in enumerate(model.joint_names) if "steer" not in name)
    added = []
    for excess in (0.02, 0.04):
        odo = Odometry(model, noise=noise)
        q = np.zeros(len(model.joint_names))
        odo.update(q, 0.0)
        q[wheel] = excess
        assert odo.update(q, 0.01) is True
        rho = odo.slip
        P = odo.pose_covariance
        assert P[0, 0] == pytest.approx((0.3 * rho ** 2 + 50.0 * rho ** 4) * 0.01, rel=1e-9)
        assert P[1, 1] == pytest.approx(P[0, 0], rel=1e-12)
        assert P[2, 2] == pytest.approx((2.0 * rho ** 2 + 700.0 * rho ** 4) * 0.01, rel=1e-9)
        added.append((rho, P[2, 2]))
    (rho1, h1), (rho2, h2) = added
    assert rho2 == pytest.approx(2.0 * rho1, rel=1e-9)
    assert h2 == pytest.approx(4.0 * 2.0 * rho1 ** 2 * 0.01 + 16.0 * 700.0 * rho1 ** 4 * 0.01,
                               rel=1e-9)


def test_a_base_without_redundant_joints_has_no_slip_term():
    """HAMR: 3 joints for 3 dof, nothing left to disagree: slip 0, so the slip
    gains add nothing however large."""
    model = load_model("hamr")
    odo = Odometry(model, noise=_noise(slip_position_gain=1e3, slip_heading_gain=1e3,
                                       slip4_position_gain=1e3, slip4_heading_gain=1e3,
                                       twist_slip_gain=(1e3, 1e3, 1e3)))
    odo.update(np.zeros(3), 0.0)
    drive(model, odo, np.zeros(3), np.array([0.3, 0.1, 0.2]), 0.2)
    assert odo.slip == 0.0 and odo.residual.size == 0
    assert np.all(odo.pose_covariance == 0.0)
    assert np.all(odo.twist_covariance == 0.0)


def test_a_ramp_lags_half_the_window_and_shows_in_the_twist_variance():
    """Body vx = a t (a = 2 m/s^2), window W = 0.1 s at 200 Hz. The least-squares
    line through samples of a quadratic, symmetric about their mean time,
    has the quadratic's slope at that mean: the twist is a (t - W / 2) (a
    known delay of W / 2), and the window's acceleration (twist now minus
    twist at the window's start, over the span) is a. Variance of vx:
    twist_variance + twist_lag_gain (a W / 2)^2 = 1e-6 + 1.5 * 0.01."""
    model = load_model("hamr")
    odo = Odometry(model, noise=_noise(twist_variance=(1e-6, 1e-6, 1e-6),
                                       twist_lag_gain=(1.5, 1.5, 1.5)),
                   twist_window=0.1)
    a, rate, w = 2.0, 200.0, 0.1
    q = np.zeros(3)
    odo.update(q, 0.0)
    t = 0.0
    for _ in range(100):                       # 0.5 s: the window is full
        for i in range(10):
            tm = t + (i + 0.5) / rate / 10
            q = q + model.inverse(q, [a * tm, 0.0, 0.0]) / rate / 10
        t += 1.0 / rate
        odo.update(q, t)
    assert odo.twist[0] == pytest.approx(a * (t - w / 2), rel=1e-3)
    assert odo.twist[1:] == pytest.approx([0.0, 0.0], abs=1e-6)
    var = np.diag(odo.twist_covariance)
    assert var[0] == pytest.approx(1e-6 + 1.5 * (a * w / 2) ** 2, rel=1e-2)
    assert var[1:] == pytest.approx([1e-6, 1e-6], rel=1e-3)


def test_a_new_odometry_reports_rest_and_uses_the_last_two_readings():
    """Before any motion: no slip, no residual, zero rate twist (what the
    controller's status and the torque controller read on the first cycle);
    the default twist window is 0 s (the line through the last two readings)."""
    odo = Odometry(load_model("xr4000"))
    assert odo.twist_window == 0.0
    assert odo.slip == 0.0 and odo.residual.size == 0
    np.testing.assert_array_equal(odo.rate_twist, np.zeros(3))
    np.testing.assert_array_equal(odo.twist, np.zeros(3))
    # the twist covariance before any motion: the noise floor of each axis
    np.testing.assert_array_equal(np.diag(odo.twist_covariance), OdometryNoise().twist_variance)
    # the first reading is only the reference: nothing integrated
    assert odo.update(np.zeros(len(odo.model.joint_names)), 0.0) is False


def test_a_repeated_stamp_moves_the_pose_but_not_the_twist_or_its_window():
    """hamr at 1 m/s along x, 100 Hz, window 0.05 s. A reading with the same
    stamp as the last but the wheels 0.01 m further: the pose follows the
    wheels, the twist (no time elapsed: no rate) stays 1 m/s, and the
    reading does not enter the window. The next reading (0.01 s later, 0.01 m
    further again) is fitted with the window's earlier readings: the least-
    squares line through (t, x) = (-0.04..0 step 0.01, same x) and
    (0.01, 0.02), np.polyfit's slope (not a clean 1 m/s, nor the 1 m/s of the
    last two readings alone)."""
    model = load_model("hamr")
    # the slip terms only (the random-walk terms grow with the distance)
    slip_only = OdometryNoise(linear_variance_per_meter=0.0, angular_variance_per_radian=0.0,
                              angular_variance_per_meter=0.0, latency_variance=0.0)
    odo = Odometry(model, noise=slip_only, twist_window=0.05)
    per_m = model.inverse([0, 0, 0], [1.0, 0, 0])          # joint [rad] per metre
    for k in range(11):                                     # t = -0.10 .. 0.00
        odo.update(per_m * (k - 10) * 0.01, (k - 10) * 0.01)
    assert odo.twist[0] == pytest.approx(1.0, rel=1e-9)
    np.testing.assert_allclose(odo.rate_twist, [1.0, 0.0, 0.0], atol=1e-9)
    assert odo.update(per_m * 0.01, 0.0) is True            # repeated stamp
    # no time elapsed: no slip term (rho^2 dt = 0), and HAMR adds nothing else
    np.testing.assert_array_equal(odo.pose_covariance, np.zeros((3, 3)))
    assert odo.pose[0] == pytest.approx(0.11, abs=1e-12)
    assert odo.twist[0] == pytest.approx(1.0, rel=1e-9)
    assert np.all(np.isfinite(odo.twist_covariance))
    odo.update(per_m * 0.02, 0.01)
    t = [-0.04, -0.03, -0.02, -0.01, 0.0, 0.01]
    x = [-0.04, -0.03, -0.02, -0.01, 0.0, 0.02]
    assert odo.twist[0] == pytest.approx(np.polyfit(t, x, 1)[0], rel=1e-6)


def test_the_noise_model_cannot_be_changed_under_a_running_odometry():
    """Odometry copies the coefficients once (the compiled path's arrays):
    a noise model changed afterwards would make the two paths disagree, so
    it is frozen."""
    import dataclasses

    noise = OdometryNoise()
    with pytest.raises(dataclasses.FrozenInstanceError):
        noise.slip_position_gain = 1.0


def test_every_noise_term_is_a_parameter_whose_default_is_the_noise_default():
    """A node started without odometry keys publishes the covariance of
    OdometryNoise(): each field has a ParamSpec, and its default is the field's."""
    import dataclasses

    from holonomic_core.config import CONTROLLER_SPECS

    specs = {spec.name: spec for spec in CONTROLLER_SPECS}
    default = OdometryNoise()
    for term in dataclasses.fields(OdometryNoise):
        spec = specs[f"odometry.{term.name}"]
        assert spec.default == getattr(default, term.name), term.name
