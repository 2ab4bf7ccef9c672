"""Swerve kinematics: the command law against hand-derived values, the flip,
the cosine scaling, the zero-speed hold, the feed-forward, the
desaturation, the least-squares odometry and the geometry checks.

Geometry of most tests: config/swerve4.yaml, modules fl (0.25, 0.25),
rl (-0.25, 0.25), rr (-0.25, -0.25), fr (0.25, -0.25), r = 0.075 m,
k_s = 8 /s, hold speed 0.01 m/s."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.loop import ManualClock
from holonomic_core.model import load_model
from holonomic_core.schema import ConfigError
from swerve_base.steering_law import choose_heading, desaturate, drive_fraction, module_command
from swerve_base.swerve import Module, SwerveKinematics

R = 0.075


@pytest.fixture(scope="module")
def model():
    return load_model("swerve4")


def test_forward_twist_drives_every_wheel_at_v_over_r_without_steering(model):
    # modules at heading 0, twist (1, 0, 0): every v_i = (1, 0), on heading,
    # wheel 1 / 0.075 = 13.333 rad/s, no steering error, no steering
    rates = model.inverse(np.zeros(8), [1.0, 0.0, 0.0])
    assert rates[0::2] == pytest.approx([0.0] * 4, abs=1e-12)
    assert rates[1::2] == pytest.approx([1.0 / R] * 4)


def test_spin_turns_each_module_tangent_and_reverses_where_shorter(model):
    # twist (0, 0, 1): v_i = (-y_i, x_i): fl (-0.25, 0.25) -> theta = 135 deg.
    # From phi = 0 the nearer heading is 135 - 180 = -45 deg (45 deg away), wheel
    # reversed: error -pi/4, steering 8 * (-pi/4) = -6.2832 rad/s, wheel
    # -|v| cos(pi/4) / r = -(0.25 sqrt 2)(sqrt 2 / 2) / 0.075 = -3.3333 rad/s.
    # fr: v = (0.25, 0.25) -> theta = 45 deg, error +pi/4, wheel +3.3333.
    # (the wheels' wait for their modules off: swerve.drive_alignment 0)
    eager = load_model("swerve4", {"swerve.drive_alignment": 0.0})
    rates = eager.inverse(np.zeros(8), [0.0, 0.0, 1.0])
    fl, fr = rates[0:2], rates[6:8]
    assert fl == pytest.approx([-8 * math.pi / 4, -0.25 / R])
    assert fr == pytest.approx([8 * math.pi / 4, 0.25 / R])
    # with the default 10 deg window every module is 45 deg off: the
    # modules turn at the same rates, the wheels wait (fraction 0)
    rates, fraction = model.kinematics.command_and_fraction(np.zeros(8), np.array([0.0, 0.0, 1.0]))
    assert fraction == 0.0
    assert rates[0::2] == pytest.approx([-2 * math.pi, 2 * math.pi, -2 * math.pi, 2 * math.pi])
    assert rates[1::2] == pytest.approx([0.0] * 4, abs=1e-15)


def test_the_wheels_wait_for_the_worst_module_and_drive_on_as_it_aligns():
    # window 10 deg: full speed up to 2 deg, none from 10 deg, linear between:
    # 6 deg -> (10 - 6) / (10 - 2) = 0.5
    window = math.radians(10.0)
    assert drive_fraction(math.radians(2.0), window) == 1.0
    assert drive_fraction(math.radians(6.0), window) == pytest.approx(0.5)
    assert drive_fraction(math.radians(10.0), window) == 0.0
    assert drive_fraction(math.radians(45.0), window) == 0.0
    assert drive_fraction(math.radians(45.0), 0.0) == 1.0      # 0: never wait


def test_a_module_turns_towards_a_command_that_grows_from_rest_below_the_hold_speed(model):
    # 5 mm/s sideways from phi = 0.7, growing (a = (0, 1) m/s^2: v . a > 0):
    # the module steers towards 90 deg at 8 (pi/2 - 0.7) rad/s + no
    # feed-forward (a parallel to v); the wheels wait (52 deg off)
    q = np.array([0.7, 0.0] * 4)
    rates, fraction = model.kinematics.command_and_fraction(
        q, np.array([0.0, 0.005, 0.0]), np.array([0.0, 1.0, 0.0]))
    assert rates[0::2] == pytest.approx([8.0 * (math.pi / 2 - 0.7)] * 4)
    assert fraction == 0.0 and rates[1::2] == pytest.approx([0.0] * 4, abs=1e-15)
    # the same speed falling (a = (0, -1)): the module holds its heading
    rates = model.kinematics.command(q, np.array([0.0, 0.005, 0.0]), np.array([0.0, -1.0, 0.0]))
    assert rates[0::2] == pytest.approx([0.0] * 4, abs=1e-15)


def test_a_spin_from_rest_waits_for_the_modules_then_accelerates_within_its_limits():
    # the controller on ideal (mock) joints: the modules turn 45 deg first;
    # while any is more than 10 deg off the base is commanded no motion, then
    # the twist grows by at most the angular acceleration limit (3 rad/s^2)
    # per cycle, never with a jump
    cfg = load_config("swerve4", {"driver": "mock", "cmd_timeout": 0.0})
    clock = ManualClock()
    dt = 1.0 / cfg.controller.control_rate
    with cfg.driver_class(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock) as drv:
        ctrl = BaseController(cfg, drv, clock=clock)
        ctrl.request_enable(True)
        ctrl.step()
        wz, errors = [], []
        for _ in range(200):
            ctrl.set_command((0.0, 0.0, 1.0))
            clock.now += dt
            ctrl.step()
            wz.append(ctrl.twist_command[2])
            phi = ctrl.reading.positions[0::2]
            # the tangent headings (mod pi) are -45, 45, -45, 45 deg
            errors.append(max(abs(math.remainder(p - t, math.pi))
                              for p, t in zip(phi, np.radians([-45, 45, -45, 45]))))
    wz, errors = np.array(wz), np.array(errors)
    waiting = errors > math.radians(10.0) + 0.02
    assert waiting[:5].all() and np.all(wz[waiting] < 0.02)
    assert np.all(np.diff(wz) <= 3.0 * dt + 1e-9)
    assert wz[-1] == pytest.approx(1.0)


def test_a_reversal_flips_the_wheel_instead_of_turning_the_module(model):
    # modules at 0 rad, command (-1, 0, 0): theta = pi, the opposite heading 0
    # needs no travel: steering 0, wheel -1 / 0.075 = -13.333 rad/s
    rates = model.inverse(np.zeros(8), [-1.0, 0.0, 0.0])
    assert rates[0::2] == pytest.approx([0.0] * 4, abs=1e-12)
    assert rates[1::2] == pytest.approx([-1.0 / R] * 4)


def test_choose_heading_takes_the_least_travel_and_says_when_the_wheel_is_reversed():
    # theta 100 deg from phi 0: 100 deg forward or -80 deg reversed -> -80 deg
    heading, sign = choose_heading(math.radians(100), 0.0)
    assert (math.degrees(heading), sign) == (pytest.approx(-80.0), -1)
    # theta 80 deg: forward wins
    heading, sign = choose_heading(math.radians(80), 0.0)
    assert (math.degrees(heading), sign) == (pytest.approx(80.0), 1)
    # the wrap: phi = 350 deg (an unwound continuous joint), theta = 10 deg ->
    # 370 deg (20 deg of travel), not back to 10 deg
    heading, sign = choose_heading(math.radians(10), math.radians(350))
    assert (math.degrees(heading), sign) == (pytest.approx(370.0), 1)


def test_choose_heading_stays_inside_a_steering_range():
    # range (-pi/2, pi/2 + 0.1), phi = 80 deg, theta = 120 deg: 120 deg (40 deg
    # away) is outside; the reversed -60 deg is inside (140 deg of travel)
    rng = (-math.pi / 2, math.pi / 2 + 0.1)
    heading, sign = choose_heading(math.radians(120), math.radians(80), rng)
    assert (math.degrees(heading), sign) == (pytest.approx(-60.0), -1)
    # without the range the 40 deg turn forward
    heading, sign = choose_heading(math.radians(120), math.radians(80))
    assert (math.degrees(heading), sign) == (pytest.approx(120.0), 1)
    # a range narrower than pi cannot reach every direction
    with pytest.raises(ValueError, match="at least pi"):
        choose_heading(0.0, 0.0, (-1.0, 1.0))


def test_the_wheel_speed_is_scaled_by_the_cosine_of_the_steering_error():
    # v = (0, 1) m/s, phi = 30 deg: theta 90 deg, error 60 deg, wheel
    # 1 * cos 60 / 0.075 = 6.6667 rad/s (= v . e(phi) / r = sin 30 / r);
    # steering 8 * pi/3 = 8.3776 rad/s
    steer, wheel = module_command(0.0, 1.0, 0.0, 0.0, math.radians(30), R, 8.0, 0.01)
    assert wheel == pytest.approx(0.5 / R)
    assert steer == pytest.approx(8.0 * math.pi / 3)
    # at 90 deg error (module across the velocity) the wheel does not drive
    steer, wheel = module_command(0.0, 1.0, 0.0, 0.0, 0.0, R, 8.0, 0.01)
    assert wheel == pytest.approx(0.0, abs=1e-12)


def test_cosine_is_clipped_when_a_range_forces_a_long_turn():
    # range (0, pi + 0.1), phi = 0.05, v = (-1, -0.2): theta = atan2(-0.2, -1) =
    # -2.944 rad; of theta + k pi only k = 1, 0.197 rad (reversed), is inside:
    # error 0.147 rad, the wheel backwards at |v| cos(0.147) / r
    rng = (0.0, math.pi + 0.1)
    theta = math.atan2(-0.2, -1.0)
    steer, wheel = module_command(-1.0, -0.2, 0.0, 0.0, 0.05, R, 8.0, 0.01, rng)
    err = theta + math.pi - 0.05
    assert wheel == pytest.approx(-math.hypot(1.0, 0.2) * math.cos(err) / R)
    # range (0, 3.3), phi = 3.2, v = (0, -1): theta = -pi/2; inside only pi/2
    # (reversed), 1.63 rad away: beyond pi/2 the cosine is negative, so the
    # wheel waits (0) while the module turns at 8 (pi/2 - 3.2) rad/s
    steer, wheel = module_command(0.0, -1.0, 0.0, 0.0, 3.2, R, 8.0, 0.01, (0.0, 3.3))
    assert wheel == 0.0
    assert steer == pytest.approx(8.0 * (math.pi / 2 - 3.2))


def test_below_the_hold_speed_a_module_keeps_its_heading(model):
    # a zero command from phi = 0.7 rad: no steering, no wheel
    q = np.array([0.7, 0.0] * 4)
    assert model.inverse(q, [0.0, 0.0, 0.0]) == pytest.approx([0.0] * 8, abs=1e-15)
    # 5 mm/s sideways (below 0.01 m/s): the heading is kept, the wheel takes
    # v . e(0.7) = 0.005 sin 0.7 = 0.0032211 m/s -> 0.042948 rad/s
    rates = model.inverse(q, [0.0, 0.005, 0.0])
    assert rates[0::2] == pytest.approx([0.0] * 4, abs=1e-15)
    assert rates[1::2] == pytest.approx([0.005 * math.sin(0.7) / R] * 4)


def test_the_steering_feeds_the_twists_rate_forward(model):
    # module on target: v = (1, 0), a = (0, 2) m/s^2: theta_dot = (1 * 2 - 0) / 1
    # = 2 rad/s with no error; the wheel 1 / r
    steer, wheel = module_command(1.0, 0.0, 0.0, 2.0, 0.0, R, 8.0, 0.01)
    assert (steer, wheel) == (pytest.approx(2.0), pytest.approx(1.0 / R))
    # the whole base: a line in odom while spinning at wz = 1 with v_odom =
    # (1, 0) seen at heading 0: body twist (1, 0, 1), its rate d/dt R(-t) v =
    # (0, -1, 0). Module fl at (0.25, 0.25): v = (0.75, 0.25), a = (0, -1):
    # theta_dot = (0.75 * -1 - 0.25 * 0) / 0.625 = -1.2 rad/s
    phi = math.atan2(0.25, 0.75)
    q = np.array([phi, 0.0] * 4)
    rates = model.kinematics.command(q, np.array([1.0, 0.0, 1.0]), np.array([0.0, -1.0, 0.0]))
    assert rates[0] == pytest.approx(-1.2)


def test_desaturation_keeps_the_ratios_of_the_module_speeds():
    # wheels (30, -15, 10) against 20 rad/s: factor 20 / 30, (20, -10, 6.667)
    rates, factor = desaturate([30.0, -15.0, 10.0], [20.0, 20.0, 20.0])
    assert factor == pytest.approx(2 / 3)
    assert rates == pytest.approx([20.0, -10.0, 20.0 / 3])
    assert desaturate([1.0, 2.0], [20.0, 20.0]) == ([1.0, 2.0], 1.0)


def test_odometry_recovers_the_rigid_twist_from_aligned_modules(model):
    # the modules aligned with twist (0.3, -0.2, 0.5): fl at (0.25, 0.25) moves
    # (0.3 - 0.125, -0.2 + 0.125) = (0.175, -0.075); its wheel |v| / r along
    # that heading; the fit returns the twist, no residual
    twist = np.array([0.3, -0.2, 0.5])
    v = model.kinematics.module_velocities(twist)
    q = np.zeros(8)
    q[0::2] = np.arctan2(v[:, 1], v[:, 0])
    q[1::2] = np.hypot(v[:, 0], v[:, 1]) / R
    rates = np.zeros(8)
    rates[1::2] = q[1::2]
    for estimator in ("slip_min", "robust", "pinv"):
        est, res = model.kinematics.estimate(q, rates, estimator)
        assert est == pytest.approx(twist, abs=1e-12)
        assert res == pytest.approx([0.0] * 4, abs=1e-12)


def test_pinv_stays_bounded_when_the_modules_are_almost_parallel(model):
    # driving straight at 1 m/s, the modules' steering encoders 0.2 mrad apart
    # (+-0.1 mrad) and the wheels 1 % apart: the wheel rows alone cannot see
    # vy, and their plain inverse divides by the 0.2 mrad spread (vy of order
    # 0.01 / 2e-4 = 50 m/s); truncated, vy is the minimum-norm 0 and vx, wz
    # are the wheels' mean and difference: vx = 1.0, wz = 0 (fl, fr: +-0.005)
    q = np.zeros(8)
    q[0::2] = [1e-4, -1e-4, 1e-4, -1e-4]
    rates = np.zeros(8)
    rates[1::2] = np.array([1.005, 1.0, 1.0, 0.995]) / R
    twist, _ = model.kinematics.estimate(q, rates, "pinv")
    assert twist[0] == pytest.approx(1.0, abs=1e-3)
    assert abs(twist[1]) < 1e-3 and abs(twist[2]) < 0.05


def test_odometry_residual_is_the_slip_no_rigid_motion_explains(model):
    # all modules at heading 0, wheels 1/r except fl at 2/r: measured
    # velocities (2, 0), (1, 0), (1, 0), (1, 0). The centroid is the origin, so
    # the translation is the mean (1.25, 0) and wz = sum (x u_y - y u_x) /
    # sum |p|^2 = -(0.25 * 2 + 0.25 * 1 - 0.25 * 1 - 0.25 * 1) / (4 * 0.125) =
    # -0.5. Fitted (1.25 + 0.5 y, -0.5 x): fl (1.375, -0.125) against (2, 0)
    # leaves (0.625, 0.125); rl (1.375, 0.125) -> (-0.375, -0.125); rr
    # (1.125, 0.125) -> (-0.125, -0.125); fr (1.125, -0.125) -> (-0.125, 0.125)
    rates = np.zeros(8)
    rates[1::2] = [2.0 / R, 1.0 / R, 1.0 / R, 1.0 / R]
    twist, res = model.kinematics.estimate(np.zeros(8), rates, "slip_min")
    assert twist == pytest.approx([1.25, 0.0, -0.5])
    assert res == pytest.approx([math.hypot(0.625, 0.125), math.hypot(0.375, 0.125),
                                 math.hypot(0.125, 0.125), math.hypot(0.125, 0.125)])


def test_jacobian_is_the_least_squares_fit(model):
    q = np.array([0.3, 0.0, -1.0, 0.0, 2.0, 0.0, 0.1, 0.0])
    rates = np.array([5.0, 3.0, -4.0, 1.0, 0.0, -2.0, 9.0, 4.0])
    assert model.jacobian(q) @ rates == pytest.approx(model.forward(q, rates))
    assert model.jacobian(q)[:, 0::2] == pytest.approx(np.zeros((3, 4)))


@pytest.mark.parametrize("modules, key", [
    ([Module("a", 0.2, 0.0, 0.05)], "swerve.modules"),
    ([Module("a", 0.2, 0.0, 0.05), Module("b", 0.2, 0.005, 0.05)], "swerve.b.x"),
    ([Module("a", 0.2, 0.0, 0.05), Module("b", -0.2, 0.0, 0.0)], "swerve.b.wheel_radius"),
    ([Module("a", 0.2, 0.0, 0.05), Module("a", -0.2, 0.0, 0.05)], "swerve.modules"),
])
def test_bad_geometry_is_refused_naming_the_key(modules, key):
    with pytest.raises(ConfigError) as err:
        SwerveKinematics(modules)
    assert f"'{key}'" in str(err.value)


def test_torque_mode_is_refused_for_a_swerve_in_one_line():
    with pytest.raises(ConfigError) as err:
        load_config("swerve4", {"control_mode": "torque"})
    assert "'control_mode'" in str(err.value) and "swerve" in str(err.value)
    assert "\n" not in str(err.value)


def test_the_controller_drives_a_mock_swerve_sideways_after_turning_its_modules():
    # (0, 0.5, 0): every module turns from 0 to +90 deg (or -90 reversed: the
    # tie at exactly 90 deg goes to the forward heading), then drives at
    # 0.5 / 0.075 = 6.667 rad/s; the mock's ideal joints make the odometry see
    # a pure sideways motion once the modules are aligned
    cfg = load_config("swerve4", {"driver": "mock", "cmd_timeout": 0.0})
    clock = ManualClock()
    with cfg.driver_class(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock) as drv:
        ctrl = BaseController(cfg, drv, clock=clock)
        ctrl.request_enable(True)
        ctrl.step()
        ctrl.set_command((0.0, 0.5, 0.0))
        for _ in range(400):                  # 2 s at 200 Hz
            clock.now += ctrl.dt
            ctrl.step()
    steer = ctrl.reading.positions[0::2]
    assert np.abs(np.abs(steer) - math.pi / 2) == pytest.approx([0.0] * 4, abs=1e-3)
    assert np.abs(ctrl.joint_command[1::2]) == pytest.approx([0.5 / R] * 4, rel=1e-3)
    assert ctrl.odometry.twist == pytest.approx([0.0, 0.5, 0.0], abs=1e-3)


def test_the_kinematics_keep_each_module_inside_its_steering_range():
    # two modules; a's steering limited to (-pi/2, pi/2 + 0.1). At phi = 80 deg
    # a twist (cos 120, sin 120) deg at 1 m/s: a may not turn to 120 deg (40 deg
    # away) and reverses to -60 deg (140 deg away): steering 8 * (-140 deg)
    # = -19.548 rad/s, wheel -cos(140 deg) clipped to 0; b (no range) turns
    # +40 deg: 8 * 0.6981 = 5.585 rad/s, wheel cos 40 / r = 10.214 rad/s
    modules = [Module("a", 0.2, 0.0, R), Module("b", -0.2, 0.0, R)]
    # (the wheels' wait for the worst module off, to see each module's own law)
    kin = SwerveKinematics(modules, steering_ranges=[(-math.pi / 2, math.pi / 2 + 0.1), None],
                           drive_alignment=0.0)
    phi = math.radians(80)
    t = math.radians(120)
    rates = kin.inverse(np.array([phi, 0.0, phi, 0.0]), np.array([math.cos(t), math.sin(t), 0.0]))
    assert rates == pytest.approx([8.0 * math.radians(-140), 0.0,
                                   8.0 * math.radians(40), math.cos(math.radians(40)) / R])


def test_a_steering_range_narrower_than_pi_is_refused_naming_the_joint():
    modules = [Module("a", 0.2, 0.0, R), Module("b", -0.2, 0.0, R)]
    with pytest.raises(ConfigError) as err:
        SwerveKinematics(modules, steering_ranges=[None, (-1.0, 1.0)])
    assert "'joints.b_steer_joint.max_position'" in str(err.value)


def test_the_configured_steering_range_bounds_the_flip():
    # joints.fl_steer_joint range (-pi/2, pi/2 + 0.1) from the config keys, as
    # a params file sets it. At phi = 80 deg a pure translation along 120 deg
    # at 1 m/s: fl may not turn +40 deg to 120 deg (outside) and reverses to
    # -60 deg (-140 deg of travel): steering 8 * (-140 deg) = -19.548 rad/s,
    # wheel cos(140 deg) < 0 clipped to 0; rl (continuous) turns +40 deg:
    # 8 * 0.69813 = 5.585 rad/s, wheel cos 40 deg / r = 10.214 rad/s (the
    # wheels' wait for the worst module off, to see each module's own law)
    ranged = load_model("swerve4", {"joints.fl_steer_joint.min_position": -math.pi / 2,
                                    "joints.fl_steer_joint.max_position": math.pi / 2 + 0.1,
                                    "swerve.drive_alignment": 0.0})
    assert ranged.kinematics.steering_ranges == ((-math.pi / 2, math.pi / 2 + 0.1),
                                                 None, None, None)
    phi, t = math.radians(80), math.radians(120)
    rates = ranged.kinematics.inverse(np.array([phi, 0.0] * 4),
                                      np.array([math.cos(t), math.sin(t), 0.0]))
    assert rates[:4] == pytest.approx([8.0 * math.radians(-140), 0.0,
                                       8.0 * math.radians(40), math.cos(math.radians(40)) / R])
    # a range a module cannot flip inside is refused naming the key
    with pytest.raises(ConfigError, match="'joints.rr_steer_joint.max_position'"):
        load_model("swerve4", {"joints.rr_steer_joint.min_position": -1.0,
                               "joints.rr_steer_joint.max_position": 1.0})
