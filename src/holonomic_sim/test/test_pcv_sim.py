"""The simulated powered-caster vehicles without ROS: the URDF's casters are
the kinematics' casters, the controller core drives them, and the friction
model really makes wheels slip."""

import math
import xml.etree.ElementTree as ET

import numpy as np
import pybullet as pb
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.description import generate_urdf
from holonomic_sim.sim_driver import SimDriver


class SimClock:
    now = 0.0

    def __call__(self):
        return self.now


class Run:
    """The controller core on the sim driver, stepped as fast as possible."""

    def __init__(self, robot, overrides=None):
        values = {"cmd_timeout": 0.0}
        values.update(overrides or {})
        self.cfg = load_config(robot, values)
        self.clock = SimClock()
        self.driver = SimDriver(self.cfg.model, self.cfg.values, self.cfg.controller.control_rate)
        self.driver.configure()
        self.ctrl = BaseController(self.cfg, self.driver, clock=self.clock)
        self.ctrl.request_enable(True)
        self.run((0.0, 0.0, 0.0), 0.05)

    def run(self, twist, seconds):
        truths = []
        for _ in range(int(round(seconds * self.cfg.controller.control_rate))):
            self.ctrl.set_command(twist)
            self.ctrl.step()
            self.clock.now = self.ctrl.reading.stamp
            truths.append(self.driver.ground_truth())
        return truths

    def close(self):
        self.driver.close()


def test_urdf_casters_are_the_kinematics_casters():
    cfg = load_config("xr4000")
    kin = cfg.model.kinematics
    robot = ET.fromstring(generate_urdf(cfg.model))
    joints = {j.get("name"): j for j in robot.iter("joint")}
    for caster in kin.casters:
        steer, wheel = joints[caster.steer_joint], joints[caster.wheel_joint]
        xyz = [float(v) for v in steer.find("origin").get("xyz").split()]
        assert xyz[:2] == pytest.approx(caster.axis, abs=1e-5)
        assert steer.find("axis").get("xyz").split() == ["0", "0", "1"]
        xyz = [float(v) for v in wheel.find("origin").get("xyz").split()]
        assert xyz[:2] == pytest.approx([-caster.caster_offset, 0.0])   # trails the axis
        assert wheel.find("axis").get("xyz").split() == ["0", "1", "0"]


@pytest.mark.parametrize("robot", ["xr4000", "comr3"])
def test_simulated_contact_points_are_where_the_kinematics_put_them(robot):
    cfg = load_config(robot)
    kin = cfg.model.kinematics
    rng = np.random.default_rng(11)
    with SimDriver(cfg.model, cfg.values, 200.0) as driver:
        body, cid = driver.plant.robot.body, driver.plant.world.client
        q = np.zeros(len(cfg.model.joint_names))
        q[0::2] = rng.uniform(-math.pi, math.pi, len(kin.casters))
        for idx, angle in zip(driver.plant.robot.joint_indices[0::2], q[0::2]):
            pb.resetJointState(body, idx, angle, physicsClientId=cid)
        for _ in range(20):
            reading = driver.read()
        assert reading.positions[0::2] == pytest.approx(q[0::2], abs=1e-3)
        expected = kin.contact_points(reading.positions)
        pos, orn = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
        inv_pos, inv_orn = pb.invertTransform(pos, orn)
        for i, idx in enumerate(driver.plant.robot.joint_indices[1::2]):
            contacts = pb.getContactPoints(bodyA=body, linkIndexA=idx, physicsClientId=cid)
            assert contacts, f"wheel {kin.casters[i].name} does not touch the floor"
            world = np.mean([c[5] for c in contacts], axis=0)
            local, _ = pb.multiplyTransforms(inv_pos, inv_orn, world.tolist(), [0, 0, 0, 1])
            assert local[:2] == pytest.approx(expected[i], abs=2e-3)
        # the chassis rests level on its wheels alone
        assert abs(driver.ground_truth().pose[2]) < 1e-3
        assert driver.plant.robot.tilt() < 0.01


@pytest.mark.parametrize("robot", ["xr4000", "comr3"])
def test_controller_drives_the_casters_with_the_commanded_twist(robot):
    run = Run(robot)
    try:
        for twist in [(0.0, 0.5, 0.0), (0.0, 0.0, 1.0), (0.3, 0.2, 0.6), (-0.4, 0.3, 0.0)]:
            run.run(twist, 2.5)                       # the casters turn, then run
            truths = run.run(twist, 1.0)
            achieved = np.mean([t.twist for t in truths], axis=0)
            v, w = np.linalg.norm(twist[:2]), abs(twist[2])
            assert np.linalg.norm(achieved[:2] - twist[:2]) <= 0.05 * max(v, 0.1), (twist, achieved)
            assert abs(achieved[2] - twist[2]) <= 0.05 * max(w, 0.3), (twist, achieved)
            assert run.ctrl.fault is None
    finally:
        run.close()


def test_a_strafe_from_casters_facing_forward_is_slowed_not_bent():
    """The steering saturates at the start of a strafe: the base moves
    slowly but sideways while the casters swing round, never forward.

    At the configured 2 m/s^2 ramp the casters swing round within their
    12 rad/s steering limit (9.6 rad/s measured) and nothing saturates; a
    20 m/s^2 ramp asks them for more, so the whole command is scaled down
    (measured: to 0.71) and the path stays sideways (3 mm of x in 0.29 m)."""
    run = Run("xr4000", {"limits.linear.y.max_acceleration": 20.0})
    try:
        truths, scales, steer_rates = [], [], []
        for _ in range(80):                               # 0.4 s, cycle by cycle
            truths += run.run((0.0, 1.0, 0.0), 0.005)
            scales.append(run.ctrl.saturation)
            steer_rates.append(np.max(np.abs(run.ctrl.joint_command[0::2])))
        path = np.array([t.pose for t in truths])
        assert abs(path[-1, 0]) < 0.1 * abs(path[-1, 1]) + 0.002
        # slowed: the casters' swing asks for more than the steering limit
        # (12 rad/s, xr4000.yaml) so the whole command is scaled down ...
        assert min(scales) < 1.0, min(scales)
        # ... and no steering joint is ever told to exceed its limit
        assert max(steer_rates) <= 12.0 + 1e-9, max(steer_rates)
    finally:
        run.close()


def test_low_friction_makes_the_wheels_slip():
    """The friction model is real: on a slippery floor the base does not go
    where its encoders say. (Velocity-controlled casters that all spin
    alike show no residual: the slip is consistent with a rigid motion, and
    no estimator can see it -- see docs/odometry_experiment.md.)"""
    def drive(mu):
        run = Run("xr4000", {"sim.wheel_friction": mu, "sim.friction_spread": 0.5,
                             "sim.seed": 3})
        try:
            for twist in [(1.2, 0.0, 0.0), (-1.2, 0.5, 2.5), (0.0, -1.2, -2.5), (0.0, 0.0, 0.0)]:
                run.run(twist, 0.75)
            truth, odo = run.driver.ground_truth().pose, run.ctrl.odometry.pose
            return np.linalg.norm(truth[:2] - odo[:2])
        finally:
            run.close()

    err_grip, err_ice = drive(1.0), drive(0.08)
    assert err_grip < 0.01
    assert err_ice > 5 * err_grip and err_ice > 0.02, (err_grip, err_ice)


def test_tyre_radius_spread_changes_the_simulated_wheels_only():
    from holonomic_core.schema import ConfigError
    cfg = load_config("xr4000", {"sim.wheel_radius_spread": 0.02, "sim.seed": 5})
    with SimDriver(cfg.model, cfg.values, 200.0) as driver:
        radii = np.array(driver.wheel_radii)
        assert np.all(np.abs(radii / 0.055 - 1.0) <= 0.02) and np.ptp(radii) > 1e-4
        assert "simulated_wheel_radii" in driver.status()
    assert cfg.model.kinematics.r == pytest.approx([0.055] * 4)     # the controller's model
    # a DDROT's two wheels differ too; a caster offset spread needs casters
    hamr = load_config("hamr", {"sim.wheel_radius_spread": 0.02, "sim.seed": 5})
    with SimDriver(hamr.model, hamr.values, 200.0) as driver:
        radii = np.array(driver.wheel_radii)
        assert np.all(np.abs(radii / 0.0615 - 1.0) <= 0.02) and np.ptp(radii) > 1e-5
        assert set(driver.hidden_truth) == {"ddrot.left_wheel_radius",
                                            "ddrot.right_wheel_radius"}
    hamr = load_config("hamr", {"sim.caster_offset_spread": 0.1})
    with pytest.raises(ConfigError, match="sim.caster_offset_spread"):
        SimDriver(hamr.model, hamr.values, 200.0).configure()


def test_steering_encoder_zero_errors_shift_only_the_readings():
    """Two drivers with the same seed: the same physics (the friction draws
    come first), so the readings differ by exactly the encoder errors, which
    hidden_truth reports (negated) as the zero_correction a calibration
    must find."""
    plain = load_config("xr4000", {"sim.seed": 3})
    faulty = load_config("xr4000", {"sim.seed": 3, "sim.steer_zero_spread": 0.05,
                                    "sim.caster_offset_spread": 0.1})
    with SimDriver(plain.model, plain.values, 200.0) as a, \
            SimDriver(faulty.model, faulty.values, 200.0) as b:
        truth = b.hidden_truth
        zeros = -np.array([truth[f"joints.{j}.zero_correction"]
                          for j in plain.model.joint_names[0::2]])
        offsets = np.array([truth[f"pcv.{c}.caster_offset"]
                            for c in plain.model.kinematics.caster_names])
        assert np.all(np.abs(zeros) <= 0.05) and np.ptp(zeros) > 1e-3
        assert np.all(np.abs(offsets / 0.02 - 1) <= 0.1) and np.ptp(offsets) > 1e-4
        ra, rb = a.read(), b.read()
    # the body with other offsets settles the steering a little differently:
    # compare against the zero errors to 1e-3 rad, far below their spread
    assert rb.positions[0::2] - ra.positions[0::2] == pytest.approx(zeros, abs=1e-3)


def test_the_controller_subtracts_the_configured_encoder_zeros():
    from holonomic_core.mock_driver import MockDriver
    cfg = load_config("comr3", {"driver": "mock", "joints.c2_steer_joint.zero_correction": 0.3})
    with MockDriver(cfg.model, cfg.values, 200.0) as driver:
        ctrl = BaseController(cfg, driver, clock=lambda: 0.0)
        ctrl.step()
        raw = driver.read().positions
    # mock joints rest at 0: the controller sees +0.3 rad on c2's steering only
    assert ctrl.reading.positions == pytest.approx(raw + [0, 0, 0.3, 0, 0, 0])
