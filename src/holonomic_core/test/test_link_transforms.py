"""Every link placed from the joint positions (holonomic_core.link_transforms),
the URDF standing on the floor, and the simulator agreeing with both."""

import math

import numpy as np
import pybullet as pb
import pytest

from holonomic_core.config import load_config
from holonomic_core.description import base_height, generate_urdf
from holonomic_core.link_transforms import LinkTree, rotate
from holonomic_core.model import load_model
from holonomic_sim.sim_driver import SimDriver


def yaw_of(q):
    x, y, z, w = q
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def tree_of(robot):
    model = load_model(robot)
    return model, LinkTree.from_urdf(generate_urdf(model))


def test_hamr_links_follow_the_turret_and_the_wheels():
    model, tree = tree_of("hamr")
    k = model.kinematics
    assert tree.root == "base_link"
    assert set(tree.moving_joint_names) == set(model.joint_names)
    theta, phi = math.pi / 2, 0.8
    poses = tree.poses_in_root({"turret_joint": theta, "left_wheel_joint": phi,
                                "right_wheel_joint": 0.0})
    # CONTRACT: turret_joint is the turret's angle relative to the drive base,
    # so the drive base is turned by -theta in base_link (the turret).
    assert yaw_of(poses["drive_base"].rotation) == pytest.approx(-theta)
    # The axle midpoint lies b behind the turret axis along the drive base's
    # forward axis, at axle height r above the floor (base_link is on the
    # floor). Left wheel: (-b, +a) in the drive base, rotated by -90 deg:
    # (x, y) -> (y, -x) gives (a, b).
    assert poses["left_wheel"].translation == pytest.approx((k.a, k.b, k.r), abs=1e-9)
    assert poses["right_wheel"].translation == pytest.approx((-k.a, k.b, k.r), abs=1e-9)
    # The wheel spins about its axle (the drive base's y axis) by its angle:
    # relative to the drive base, q = (0, sin(phi/2), 0, cos(phi/2)).
    local = {t.child: t for t in tree.transforms({"turret_joint": theta,
                                                   "left_wheel_joint": phi,
                                                   "right_wheel_joint": 0.0})}
    assert local["left_wheel"].rotation == pytest.approx(
        (0.0, math.sin(phi / 2), 0.0, math.cos(phi / 2)))
    assert local["right_wheel"].rotation == pytest.approx((0.0, 0.0, 0.0, 1.0))


@pytest.mark.parametrize("robot", ["xr4000", "comr3"])
def test_pcv_wheels_touch_the_floor_where_the_kinematics_put_the_contacts(robot):
    model, tree = tree_of(robot)
    kin = model.kinematics
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-math.pi, math.pi, len(model.joint_names))
        poses = tree.poses_in_root(dict(zip(model.joint_names, q)))
        contacts = kin.contact_points(q)
        # the URDF writes 6 significant digits: geometry agrees to ~2e-7 m
        for i, caster in enumerate(kin.casters):
            wheel = poses[f"{caster.name}_wheel"]
            # wheel centre one radius above the floor (base_link's z = 0) ...
            assert wheel.translation[2] == pytest.approx(caster.wheel_radius, abs=1e-6)
            # ... right above the contact point p_i = s_i - b e_i of the model
            assert wheel.translation[:2] == pytest.approx(tuple(contacts[i]), abs=1e-6)
            # the fork's heading is the steering joint angle (CONTRACT)
            fork = poses[f"{caster.name}_fork"]
            assert math.remainder(yaw_of(fork.rotation) - q[2 * i], 2 * math.pi) \
                == pytest.approx(0.0, abs=1e-9)


def test_swerve_wheels_touch_the_floor_under_their_steering_axes():
    # swerve4: no caster offset, so each wheel's centre is one radius (0.075 m)
    # above the floor right under the module's (x, y), whatever the angles
    model, tree = tree_of("swerve4")
    rng = np.random.default_rng(4)
    for _ in range(5):
        q = rng.uniform(-math.pi, math.pi, len(model.joint_names))
        poses = tree.poses_in_root(dict(zip(model.joint_names, q)))
        for i, module in enumerate(model.kinematics.modules):
            wheel = poses[f"{module.name}_wheel"]
            assert wheel.translation == pytest.approx((module.x, module.y, 0.075), abs=1e-6)
            yoke = poses[f"{module.name}_yoke"]
            assert math.remainder(yaw_of(yoke.rotation) - q[2 * i], 2 * math.pi) \
                == pytest.approx(0.0, abs=1e-9)


def test_origin_rpy_axis_and_prismatic_joints_compose_as_urdf_says():
    urdf = """<robot name="t"><link name="a"/><link name="b"/><link name="c"/><link name="d"/>
    <joint name="j1" type="revolute"><parent link="a"/><child link="b"/>
      <origin xyz="1 0 0" rpy="0 0 1.5707963267948966"/><axis xyz="0 0 2"/></joint>
    <joint name="j2" type="prismatic"><parent link="b"/><child link="c"/>
      <origin xyz="0 0 0.5"/><axis xyz="1 0 0"/></joint>
    <joint name="j3" type="fixed"><parent link="c"/><child link="d"/>
      <origin xyz="0 1 0"/></joint></robot>"""
    tree = LinkTree.from_urdf(urdf)
    assert tree.root == "a" and tree.moving_joint_names == ("j1", "j2")
    poses = tree.poses_in_root({"j1": math.pi / 2, "j2": 2.0})
    # b: at (1, 0, 0), turned by the origin's 90 deg and the joint's 90 deg
    # (the axis is normalised) = 180 deg.
    assert poses["b"].translation == pytest.approx((1, 0, 0))
    assert yaw_of(poses["b"].rotation) == pytest.approx(math.pi)
    # c: 2 m along b's x (= -x of a) and 0.5 m up: (1 - 2, 0, 0.5)
    assert poses["c"].translation == pytest.approx((-1, 0, 0.5), abs=1e-12)
    # d: 1 m along c's y (= -y of a)
    assert poses["d"].translation == pytest.approx((-1, -1, 0.5), abs=1e-12)
    with pytest.raises(KeyError):
        tree.transforms({"j1": 0.0})


@pytest.mark.parametrize("urdf, what", [
    ('<robot name="t"><link name="a"/><link name="b"/></robot>', "one root"),
    ('<robot name="t"><link name="a"/><link name="b"/><joint name="j" type="floating">'
     '<parent link="a"/><child link="b"/></joint></robot>', "unsupported type"),
])
def test_a_urdf_the_tree_cannot_place_is_rejected(urdf, what):
    with pytest.raises(ValueError, match=what):
        LinkTree.from_urdf(urdf)


@pytest.mark.parametrize("robot", ["hamr", "xr4000", "swerve4"])
def test_simulator_rests_base_link_on_the_floor_and_places_links_as_the_tree(robot):
    """The pybullet robot is the URDF the tree reads: base_link's origin on
    the floor, and every link's frame where the tree puts it for the joint
    positions the simulator measures."""
    cfg = load_config(robot)
    model = cfg.model
    tree = LinkTree.from_urdf(generate_urdf(model))
    rng = np.random.default_rng(5)
    with SimDriver(model, cfg.values, 200.0) as driver:
        body, cid = driver.plant.robot.body, driver.plant.world.client
        steer = [j for j in model.joint_names if not j.endswith("wheel_joint")]
        for name in steer:
            idx = driver.plant.robot.joint_indices[model.joint_names.index(name)]
            pb.resetJointState(body, idx, rng.uniform(-math.pi, math.pi), physicsClientId=cid)
        for _ in range(40):
            reading = driver.read()
        com, orientation = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
        # base_link's origin = pybullet's inertial base minus the body's height
        # settled into the floor by 1.0e-5 m (measured, both robots): 1e-4
        assert com[2] == pytest.approx(base_height(model), abs=1e-4)
        x, y, yaw = driver.plant.robot.world_pose()
        origin_z = com[2] - rotate(orientation, (0.0, 0.0, base_height(model)))[2]
        assert origin_z == pytest.approx(0.0, abs=1e-4)
        poses = tree.poses_in_root(dict(zip(model.joint_names, reading.positions)))
        c, s = math.cos(yaw), math.sin(yaw)
        for index in range(pb.getNumJoints(body, physicsClientId=cid)):
            link = pb.getJointInfo(body, index, physicsClientId=cid)[12].decode()
            frame = pb.getLinkState(body, index, physicsClientId=cid)[4]   # URDF link frame
            px, py, pz = poses[link].translation
            expected = (x + c * px - s * py, y + s * px + c * py, pz)
            # measured: 1.0e-5 m (the same sink into the floor)
            assert frame == pytest.approx(expected, abs=1e-4), link
