"""The pybullet stand-in, without ROS: URDF from the config, the motor model,
ground truth and the driver lifecycle."""

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.description import generate_urdf
from holonomic_core.driver import DriverStateError
from holonomic_core.schema import ConfigError
from holonomic_sim.sim_driver import SimDriver


def make_driver(overrides=None, control_rate=200.0):
    cfg = load_config("hamr", overrides or {})
    return cfg, SimDriver(cfg.model, cfg.values, control_rate)


def drive_open_loop(cfg, driver, twist, seconds):
    """Joint rates from the exact inverse kinematics, every control period."""
    reading = driver.read()
    for _ in range(int(seconds * driver.control_rate)):
        driver.write_velocities(cfg.model.inverse(reading.positions, twist))
        reading = driver.read()
    return reading


def test_urdf_geometry_is_the_controllers_geometry():
    cfg = load_config("hamr")
    k = cfg.model.kinematics
    robot = ET.fromstring(generate_urdf(cfg.model))
    joints = {j.get("name"): j for j in robot.iter("joint")}
    assert set(cfg.model.joint_names) <= set(joints)
    for side, y in (("left", k.a), ("right", -k.a)):
        joint = joints[f"{side}_wheel_joint"]
        xyz = [float(v) for v in joint.find("origin").get("xyz").split()]
        # the axle midpoint is b behind the turret axis; wheels at +-a
        assert xyz[:2] == pytest.approx([-k.b, y])
        assert joint.find("axis").get("xyz").split() == ["0", "1", "0"]
        link = next(l for l in robot.iter("link") if l.get("name") == f"{side}_wheel")
        radii = [float(c.get("radius")) for c in link.iter("cylinder")]
        assert radii and radii == pytest.approx([k.r] * len(radii))
    # turret angle = turret relative to drive base: the drive base hangs on -z
    assert joints["turret_joint"].find("axis").get("xyz").split() == ["0", "0", "-1"]
    limit = joints["turret_joint"].find("limit")
    assert float(limit.get("velocity")) == pytest.approx(4.712)
    for link in robot.iter("link"):
        assert link.find("inertial") is not None, link.get("name")
        assert float(link.find("inertial/mass").get("value")) > 0


@pytest.mark.parametrize("twist", [(0.5, 0.0, 0.0), (0.0, 0.5, 0.0), (0.3, -0.3, 0.0),
                                   (0.0, 0.0, 2.0), (0.3, 0.2, 0.6)])
def test_inverse_kinematics_moves_the_simulated_base_with_the_twist(twist):
    cfg, driver = make_driver()
    with driver:
        driver.activate()
        drive_open_loop(cfg, driver, twist, 1.5)
        samples = []
        for _ in range(100):
            reading = drive_open_loop(cfg, driver, twist, 0.01)
            samples.append(driver.ground_truth().twist)
        achieved = np.mean(samples, axis=0)
    assert achieved == pytest.approx(twist, abs=0.01)
    # and the encoders see what the base does
    assert cfg.model.forward(reading.positions, reading.velocities) == pytest.approx(twist, abs=0.01)


def test_each_read_advances_the_simulation_by_one_control_period():
    cfg, driver = make_driver({"control_rate": 250.0, "sim.physics_rate": 1000.0}, 250.0)
    with driver:
        stamps = [driver.read().stamp for _ in range(5)]
    assert driver.substeps == 4
    assert np.diff(stamps) == pytest.approx([0.004] * 4)


def test_physics_rate_must_be_an_integer_multiple_of_the_control_rate():
    cfg = load_config("hamr", {"sim.physics_rate": 1100.0})
    with pytest.raises(ConfigError, match="sim.physics_rate"):
        SimDriver(cfg.model, cfg.values, 200.0)


def test_ground_truth_starts_at_identity_wherever_the_robot_is_placed():
    cfg, driver = make_driver({"sim.start_pose": [1.0, -2.0, 2.5]})
    with driver:
        truth = driver.ground_truth()
        assert truth.pose == pytest.approx([0, 0, 0], abs=1e-4)
        driver.activate()
        drive_open_loop(cfg, driver, (0.4, 0.0, 0.0), 1.0)
        pose = driver.ground_truth().pose
    # forward in base_link, whatever the world heading
    assert pose[0] > 0.25 and abs(pose[1]) < 0.01 and abs(pose[2]) < 0.01


def test_motor_model_enforces_speed_and_torque_limits():
    cfg, driver = make_driver()
    limits = cfg.model.max_joint_velocity
    with driver:
        driver.activate()
        for _ in range(200):
            driver.write_velocities(np.array([100.0, 100.0, 0.0]))
            reading = driver.read()
        assert np.abs(reading.velocities[:2]) == pytest.approx(limits[:2], rel=0.02)
        max_effort = np.array([j.max_effort for j in cfg.model.joint_limits])
        driver.write_efforts(np.array([100.0, -100.0, 0.0]))
        reading = driver.read()
        assert reading.efforts == pytest.approx([max_effort[0], -max_effort[1], 0.0])


def test_disarmed_sim_holds_still_and_refuses_commands():
    cfg, driver = make_driver()
    with driver:
        for _ in range(50):
            reading = driver.read()
        assert np.abs(reading.velocities).max() < 1e-3
        with pytest.raises(DriverStateError):
            driver.write_velocities(np.array([5.0, 5.0, 0.0]))
        driver.activate()
        drive_open_loop(cfg, driver, (0.5, 0.0, 0.0), 1.0)
        driver.deactivate()           # disarm while moving: the motors brake
        for _ in range(100):
            reading = driver.read()
        assert np.abs(reading.velocities).max() < 1e-2
        assert np.linalg.norm(driver.ground_truth().twist) < 1e-2


def test_wheel_friction_spread_is_reproducible_from_its_seed():
    def frictions(seed):
        _, driver = make_driver({"sim.friction_spread": 0.3, "sim.seed": seed})
        with driver:
            return driver.friction.copy()

    a, b, c = frictions(7), frictions(7), frictions(8)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert np.all(np.abs(a - 1.0) <= 0.3)


def test_a_tipped_over_base_is_a_driver_error():
    from holonomic_core.driver import DriverCommunicationError
    cfg, driver = make_driver()
    with driver:
        import pybullet as pb
        robot = driver.plant.robot
        pb.resetBasePositionAndOrientation(
            robot.body, [0, 0, 0.5], pb.getQuaternionFromEuler([math.pi / 2, 0, 0]),
            physicsClientId=driver.plant.world.client)
        with pytest.raises(DriverCommunicationError, match="tipped over"):
            driver.read()
