"""Dynamically decoupled torque control of the PCV (Holmberg & Khatib,
Secs. 3-4): the operational-space model against the simulator, decoupling,
stabilisation, and torque mode through the controller and ROS."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.loop import ManualClock
from holonomic_core.schema import ConfigError
from holonomic_core.torque import OperationalSpaceController
from pcv_base.dynamics import PcvDynamics
from holonomic_testing.ros_probe import Bringup, Probe, wait_until


@pytest.fixture
def xr4000_sim():
    """An armed XR4000 in the simulator (grippy floor: the model has no slip),
    driven in velocity mode to a turning, translating state. Ideal motors:
    these tests check the rigid-body model against the physics, and the
    model knows neither the drives' rotor inertia nor their friction and
    delays."""
    cfg = load_config("xr4000", {"cmd_timeout": 0.0, "sim.wheel_friction": 2.0,
                                 "sim.ideal_motors": True})
    clock = ManualClock()
    driver = cfg.driver_class(cfg.model, cfg.values, cfg.controller.control_rate)
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=clock)
    ctrl.request_enable(True)
    for _ in range(400):
        ctrl.set_command((0.3, 0.1, 0.4))
        ctrl.step()
        clock.now = ctrl.reading.stamp
    yield cfg, driver, ctrl
    driver.close()


@pytest.mark.parametrize("robot", ["xr4000", "comr3"])
def test_mass_matrix_is_symmetric_positive_definite_and_bias_quadratic(robot):
    model = load_model_of(robot)
    dyn = PcvDynamics.from_model(model)
    rng = np.random.default_rng(4)
    chassis = np.diag([dyn.body.chassis_mass, dyn.body.chassis_mass, dyn.body.chassis_inertia])
    for _ in range(50):
        q = rng.uniform(-math.pi, math.pi, len(model.joint_names))
        lam = dyn.mass_matrix(q)
        assert np.allclose(lam, lam.T, atol=1e-12)
        assert np.linalg.eigvalsh(lam)[0] > 0.0
        # the casters add a positive semi-definite part to the chassis's own
        # diag(m, m, I) (a caster's bodies need not move with the base: a
        # wheel only rolls along its heading while the fork swings)
        assert np.linalg.eigvalsh(lam - chassis)[0] > -1e-9
        twist = rng.normal(0, 0.5, 3)
        assert np.allclose(dyn.bias(q, np.zeros(3)), 0.0)
        # centripetal and coriolis terms are quadratic in the speeds
        assert dyn.bias(q, 2 * twist) == pytest.approx(4 * dyn.bias(q, twist), rel=1e-6,
                                                       abs=1e-9)


def load_model_of(robot):
    from holonomic_core.model import load_model
    return load_model(robot)


def measured_acceleration(driver, torques, steps=5):
    """Apply joint torques for ``steps`` physics steps; the body-frame
    derivative of the true body twist [m/s^2, m/s^2, rad/s^2]."""
    robot, world = driver.plant.robot, driver.plant.world
    before = robot.body_twist()
    robot.command_efforts(torques)
    world.step(steps)
    return (robot.body_twist() - before) / (steps * world.dt)


def test_model_predicts_the_simulated_acceleration(xr4000_sim):
    cfg, driver, ctrl = xr4000_sim
    dyn = PcvDynamics.from_model(cfg.model)
    rng = np.random.default_rng(1)
    for _ in range(6):
        for _ in range(40):                       # keep it moving and turning
            ctrl.set_command((0.3, 0.1, 0.4))
            ctrl.step()
        q = ctrl.reading.positions.copy()
        twist = driver.plant.robot.body_twist()
        wrench = rng.normal(0, 1, 3) * np.array([25.0, 25.0, 5.0])
        torques = dyn.torque_distribution(q, wrench)            # F = C^T Gamma'
        predicted = dyn.acceleration(q, twist, wrench)           # Lambda^-1 (F - mu)
        measured = measured_acceleration(driver, torques)
        # pybullet's contacts are compliant and slip a little: 3 % of the
        # acceleration scale, not of each component
        assert np.abs(measured - predicted).max() < 0.03 * np.abs(predicted).max() + 0.01
        driver.plant.robot.command_velocities(ctrl.joint_command)


def test_unit_control_force_gives_the_commanded_acceleration(xr4000_sim):
    """Decoupling: F = Lambda F* + mu makes the base a unit mass per axis."""
    cfg, driver, ctrl = xr4000_sim
    dyn = PcvDynamics.from_model(cfg.model)
    for f_star in np.eye(3):
        for _ in range(40):
            ctrl.set_command((0.3, 0.1, 0.4))
            ctrl.step()
        q = ctrl.reading.positions.copy()
        twist = driver.plant.robot.body_twist()
        wrench = dyn.mass_matrix(q) @ f_star + dyn.bias(q, twist)
        measured = measured_acceleration(driver, dyn.torque_distribution(q, wrench))
        assert measured == pytest.approx(f_star, abs=0.05), (f_star, measured)
        driver.plant.robot.command_velocities(ctrl.joint_command)


def torque_robot(**overrides):
    cfg = load_config("xr4000", {"cmd_timeout": 0.0, "control_mode": "torque", **overrides})
    clock = ManualClock()
    driver = cfg.driver_class(cfg.model, cfg.values, cfg.controller.control_rate)
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=clock)
    ctrl.request_enable(True)
    ctrl.step()
    clock.now = ctrl.reading.stamp
    return driver, ctrl, clock


def run(ctrl, clock, twist, seconds):
    for _ in range(round(seconds / ctrl.dt)):
        ctrl.set_command(twist)
        ctrl.step()
        clock.now = ctrl.reading.stamp
        assert ctrl.fault is None, ctrl.fault


#: the accuracy the dynamic model gives when it is exact: ideal motors (with the
#: drive model's unmodelled rotor inertia, friction and delays the stabilisation
#: ends 7.7 mm off and a 0.5 rad/s turn runs 3 % slow; docs/torque_control.md)
EXACT_MODEL = {"sim.ideal_motors": True}


def test_torque_mode_stabilises_the_base_from_an_initial_offset():
    driver, ctrl, clock = torque_robot(**EXACT_MODEL)
    try:
        # the reference 8 cm / -5 cm / 0.1 rad away from where the base rests
        ctrl.torque.ref_pose = ctrl.odometry.pose + np.array([0.08, -0.05, 0.1])
        run(ctrl, clock, (0.0, 0.0, 0.0), 0.4)
        e_pose, _ = ctrl.torque.errors(ctrl.odometry.pose, ctrl.odometry.twist)
        assert np.abs(e_pose[:2]).max() > 0.01          # still on its way
        run(ctrl, clock, (0.0, 0.0, 0.0), 2.0)
        e_pose, e_twist = ctrl.torque.errors(ctrl.odometry.pose, ctrl.odometry.twist)
        assert np.abs(e_pose[:2]).max() < 0.003 and abs(e_pose[2]) < 0.003, e_pose
        assert np.abs(e_twist).max() < 0.01
        # and the truth agrees with the odometry it was steered by
        truth = driver.ground_truth().pose
        assert np.abs(truth - ctrl.odometry.pose).max() < 0.005
    finally:
        driver.close()


def test_torque_mode_follows_cmd_vel_and_stops_on_a_stale_command():
    driver, ctrl, clock = torque_robot(cmd_timeout=0.3, **EXACT_MODEL)
    try:
        run(ctrl, clock, (0.4, 0.2, 0.5), 3.0)
        assert driver.ground_truth().twist == pytest.approx([0.4, 0.2, 0.5], abs=0.01)
        # a command that stops coming: the reference decelerates to rest
        for _ in range(round(1.5 / ctrl.dt)):
            ctrl.step()
            clock.now = ctrl.reading.stamp
        assert ctrl.stale and np.abs(driver.ground_truth().twist).max() < 0.005
    finally:
        driver.close()


def test_torque_distribution_by_c_sharp_spreads_effort_more_evenly_than_pinv():
    """Same wrench, two left inverses: C#^T gives the least-squares contact
    forces (the paper's choice), pinv(C)^T does not."""
    model = load_model_of("xr4000")
    kin = model.kinematics
    slip_min = OperationalSpaceController(model, (1, 1, 1), (1, 1, 1), [1e9] * 8)
    plain = OperationalSpaceController(model, (1, 1, 1), (1, 1, 1), [1e9] * 8,
                                       distribution="pinv")
    rng = np.random.default_rng(2)
    for _ in range(20):
        q = rng.uniform(-math.pi, math.pi, 8)
        wrench = rng.normal(0, 30, 3)
        forces = []
        for law in (slip_min, plain):
            torques = law.distribute(q, wrench)
            assert kin.constraint_matrix(q).T @ torques == pytest.approx(wrench, abs=1e-9)
            # contact forces whose power matches the torques': f = C_q^T Gamma'
            forces.append(kin.contact_to_joint(q).T @ torques)
        assert np.sum(forces[0] ** 2) <= np.sum(forces[1] ** 2) + 1e-9


@pytest.mark.parametrize("robot,overrides,words", [
    ("hamr", {"control_mode": "torque"}, "dynamic model"),
    ("xr4000", {"control_mode": "torque", "driver": "mock"}, "no torque mode"),
    ("xr4000", {"control_mode": "torque", "torque.kp": [1.0, 2.0]}, "at least 3 entries"),
    ("xr4000", {"control_mode": "torque", "torque.kv": [1.0, 2.0, 3.0, 4.0]}, "exactly 3 gains"),
])
def test_torque_mode_where_it_cannot_work_is_refused(robot, overrides, words):
    with pytest.raises(ConfigError, match=words):
        load_config(robot, overrides)


def test_torque_mode_drives_the_simulated_xr4000_from_cmd_vel_over_ros(ros, tmp_path):
    robot = Bringup(["xr4000", "--namespace", "torque", "--enable",
                     "-p", "control_mode:=torque"], tmp_path / "bringup.log")
    probe = Probe(ros, "torque")
    try:
        probe.wait_ready()
        probe.drive((0.3, -0.2, 0.6), 2.5)
        twist = np.mean([s.twist for s in probe.truth[-10:]], axis=0)
        assert twist == pytest.approx([0.3, -0.2, 0.6], abs=0.02)
        probe.wait_at_rest()
        wait_until(lambda: probe.diagnostics is not None, 5, "diagnostics")
    finally:
        probe.close()
        assert robot.stop() == 0, robot.log()


@pytest.mark.parametrize("mode,motors", [("velocity", "drive model"),
                                         # the exact-model accuracy (EXACT_MODEL):
                                         # 10.7 mm max on the drive model
                                         ("torque C#^T", "ideal")])
def test_both_modes_follow_a_figure_eight_within_a_centimetre(mode, motors):
    """BaseController.follow, the precise-move input, in the simulator: the
    true pose stays within 1 cm of the figure-eight (0.8 m, 8 s laps)."""
    from holonomic_sim.torque_experiment import run as run_experiment
    result = run_experiment("xr4000", "figure-eight", mode, motors=motors)
    assert result["max_mm"] < 10.0 and result["max_heading_deg"] < 0.5, result


def test_derived_g_dot_matches_a_numeric_derivative():
    """The analytic dJ/dphi of every caster body against central differences."""
    dyn = PcvDynamics.from_model(load_model_of("xr4000"))
    h = 1e-6
    for i in range(4):
        for phi in np.linspace(-3.0, 3.0, 13):
            fork, wheel, d_fork, d_wheel = dyn._caster_jacobians(i, phi)
            plus, minus = dyn._caster_jacobians(i, phi + h), dyn._caster_jacobians(i, phi - h)
            assert d_fork == pytest.approx((plus[0] - minus[0]) / (2 * h), abs=1e-6)
            assert d_wheel == pytest.approx((plus[1] - minus[1]) / (2 * h), abs=1e-6)


# --- eqs. 5, 6 and the torque limits by hand, on a dynamics of known mass ---

class _KnownMass:
    """Lambda = diag(mass), mu = bias, and a distribution that gives the
    wrench itself as three "joint torques": eqs. 5-6 by hand, nothing else."""

    def __init__(self, mass=(2.0, 2.0, 0.5), bias=(0.0, 0.0, 0.0)):
        self.mass, self.bias = np.diag(mass), np.array(bias)

    def terms(self, positions, twist):
        return self.mass, self.bias

    def torque_distribution(self, positions, wrench):
        return np.array(wrench, dtype=float)


def _osc(kp=4.0, kv=2.0, max_efforts=(100.0, 100.0, 100.0), **kw):
    cfg = load_config("xr4000", {})
    return OperationalSpaceController(cfg.model, kp, kv, max_efforts, dynamics=_KnownMass(**kw))


def test_a_new_or_reset_controller_holds_a_reference_at_rest():
    """Before the first cycle: the reference at rest at the origin, no
    wrench. After reset(pose): at rest at that pose, so a base standing
    there has no error at all."""
    osc = _osc()
    e_pose, e_twist = osc.errors((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    np.testing.assert_array_equal(e_pose, np.zeros(3))
    np.testing.assert_array_equal(e_twist, np.zeros(3))
    np.testing.assert_array_equal(osc.wrench, np.zeros(3))
    osc.step(None, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.5, 0.0, 0.0), 0.1)
    osc.reset((1.0, 2.0, 0.5))
    e_pose, e_twist = osc.errors((1.0, 2.0, 0.5), (0.0, 0.0, 0.0))
    np.testing.assert_allclose(e_pose, np.zeros(3), atol=1e-15)
    np.testing.assert_array_equal(e_twist, np.zeros(3))


def test_the_pd_law_in_base_link_by_hand():
    """Reference at rest at the origin; base at (0.1, -0.05, 0.02) moving at
    vx = 0.2. The error x - x_d in base_link: the world offset (0.1, -0.05)
    turned by -0.02 rad, e = (0.1 c - 0.05 s, -0.1 s - 0.05 c, 0.02) with
    c, s = cos, sin 0.02; twist error (0.2, 0, 0); no reference
    acceleration. F* = -Kp e - Kv e_dot (eq. 6), F = Lambda F* + mu (eq. 5)
    with Lambda = diag(2, 2, 0.5), mu = (1, -1, 0.5)."""
    osc = _osc(kp=(4.0, 3.0, 5.0), kv=2.0, bias=(1.0, -1.0, 0.5))
    osc.reset((0.0, 0.0, 0.0))
    c, s = math.cos(0.02), math.sin(0.02)
    e = np.array([0.1 * c - 0.05 * s, -0.1 * s - 0.05 * c, 0.02])
    e_pose, e_twist = osc.errors((0.1, -0.05, 0.02), (0.2, 0.0, 0.0))
    np.testing.assert_allclose(e_pose, e, atol=1e-15)
    np.testing.assert_allclose(e_twist, [0.2, 0.0, 0.0], atol=1e-15)
    torques = osc.step(None, (0.1, -0.05, 0.02), (0.2, 0.0, 0.0), (0.0, 0.0, 0.0), 0.01)
    f_star = -np.array([4.0, 3.0, 5.0]) * e - 2.0 * np.array([0.2, 0.0, 0.0])
    expected = np.diag([2.0, 2.0, 0.5]) @ f_star + np.array([1.0, -1.0, 0.5])
    np.testing.assert_allclose(osc.wrench, expected, rtol=1e-12)
    np.testing.assert_allclose(torques, expected, rtol=1e-12)


def test_the_reference_twist_is_seen_from_the_base_frame():
    """Reference at (1, 1, pi/2) moving at body vx = 1 (i.e. +y in odom); the
    base at (1, 0, 0) at rest. In base_link the reference is 1 m to the left
    (e = (0, -1, -pi/2)) and its twist points along the base's +y: e_dot =
    0 - (0, 1, 0) after turning by rth - pth = pi/2."""
    osc = _osc()
    # set directly: track() would pull a reference this far to MAX_ERROR
    osc.ref_pose = np.array([1.0, 1.0, math.pi / 2])
    osc.ref_twist = np.array([1.0, 0.0, 0.0])
    e_pose, e_twist = osc.errors((1.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    np.testing.assert_allclose(e_pose, [0.0, -1.0, -math.pi / 2], atol=1e-15)
    np.testing.assert_allclose(e_twist, [0.0, -1.0, 0.0], atol=1e-15)


def test_the_reference_advances_by_the_mean_twist_and_feeds_forward_its_change():
    """dt = 0.1 s, the commanded twist from rest to vx = 1: the reference pose
    moves by the mean twist 0.5 m/s x 0.1 s = 0.05 m; the feed-forward
    x_ddot_d = (1 - 0) / 0.1 = 10 m/s^2, so with the base exactly on the
    reference (pose (0.05, 0, 0), twist (1, 0, 0)) F = Lambda (10, 0, 0)."""
    osc = _osc()
    osc.reset((0.0, 0.0, 0.0))
    osc.step(None, (0.05, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.1)
    np.testing.assert_allclose(osc.ref_pose, [0.05, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(osc.ref_twist, [1.0, 0.0, 0.0])
    np.testing.assert_allclose(osc.wrench, [20.0, 0.0, 0.0], atol=1e-12)
    # a given acceleration (a trajectory) replaces the difference: the
    # twist holds at vx = 1, the reference moves 0.1 m more, F = Lambda (0, 0, 3)
    osc.step(None, (0.15, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.1,
             reference_acceleration=(0.0, 0.0, 3.0))
    np.testing.assert_allclose(osc.ref_pose, [0.15, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(osc.wrench, [0.0, 0.0, 1.5], atol=1e-12)


def test_a_base_held_far_off_pulls_the_reference_to_max_error():
    """Base 1 m ahead of and 0.5 rad from a reference at rest at the origin:
    the position and heading errors are clipped to MAX_ERROR (0.15 m,
    0.3 rad) in F* (F*_x = -Kp 0.15, F*_th = -Kp 0.3), and the reference is
    pulled to the base minus the clipped error: compose((1, 0, 0.5),
    (-0.15, 0, -0.3)) = (1 - 0.15 cos 0.5, -0.15 sin 0.5, 0.2)."""
    osc = _osc(kp=4.0, kv=0.0, mass=(1.0, 1.0, 1.0))
    osc.reset((0.0, 0.0, 0.0))
    osc.track(None, (1.0, 0.0, 0.5), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
              (0.0, 0.0, 0.0))
    # e_y = -sin(0.5) * 1 m, beyond 0.15 too: clipped to -0.15 -> F*_y = +0.6
    np.testing.assert_allclose(osc.wrench, [-0.6, 0.6, -1.2], atol=1e-12)
    # e in base_link: (cos 0.5, -sin 0.5, 0.5), clipped to (0.15, -0.15, 0.3)
    np.testing.assert_allclose(osc.ref_pose, [1 - 0.15 * math.cos(0.5) - 0.15 * math.sin(0.5),
                                              -0.15 * math.sin(0.5) + 0.15 * math.cos(0.5),
                                              0.2], atol=1e-12)
    e_pose, _ = osc.errors((1.0, 0.0, 0.5), (0.0, 0.0, 0.0))
    np.testing.assert_allclose(e_pose, [0.15, -0.15, 0.3], atol=1e-12)
    # within MAX_ERROR (exactly at it included) the reference is left alone
    before = osc.ref_pose.copy()
    osc.track(None, (1.0, 0.0, 0.5), (0.0, 0.0, 0.0), before, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    np.testing.assert_array_equal(osc.ref_pose, before)


@pytest.mark.parametrize("wrench,expected", [
    ((4.0, -2.0, 1.0), (1.0, -0.5, 0.25)),          # worst 4x the limit: all / 4
    ((1.5, -0.75, 0.3), (1.0, -0.5, 0.2)),          # worst 1.5x: all / 1.5
    ((1.0, -0.5, 0.25), (1.0, -0.5, 0.25)),         # exactly at the limit: unchanged
    ((0.5, 0.2, -0.1), (0.5, 0.2, -0.1)),           # within: unchanged
    ((np.nan, 0.0, 0.0), (0.0, 0.0, 0.0)),          # NaN: no torque at all
    ((np.inf, 0.0, 0.0), (0.0, 0.0, 0.0)),
])
def test_torques_are_scaled_together_into_the_limits(wrench, expected):
    osc = _osc(max_efforts=(1.0, 1.0, 1.0))
    np.testing.assert_allclose(osc.distribute(None, np.array(wrench)), expected, atol=1e-15)


def test_the_pinv_distribution_produces_the_wrench_with_least_torque():
    """pinv(C)^T F: F = C^T Gamma (the torques make the wrench) and Gamma is
    in the row space of C^T (the minimum-norm solution, orthogonal to C^T's
    null space)."""
    cfg = load_config("xr4000", {})
    osc = OperationalSpaceController(cfg.model, 1.0, 1.0, np.full(len(cfg.model.joint_names), 1e3),
                                     dynamics=_KnownMass(), distribution="pinv")
    q = np.zeros(len(cfg.model.joint_names))
    C = cfg.model.kinematics.constraint_matrix(q)
    wrench = np.array([3.0, -1.0, 0.5])
    torques = osc.distribute(q, wrench)
    np.testing.assert_allclose(C.T @ torques, wrench, atol=1e-9)
    # minimum norm: no component in the null space of C^T
    null = np.linalg.svd(C.T)[2][3:]
    np.testing.assert_allclose(null @ torques, 0.0, atol=1e-9)


def test_an_unknown_distribution_is_refused():
    cfg = load_config("xr4000", {})
    with pytest.raises(ValueError, match="distribution"):
        OperationalSpaceController(cfg.model, 1.0, 1.0, np.ones(8), dynamics=_KnownMass(),
                                   distribution="even")
