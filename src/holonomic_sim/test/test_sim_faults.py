"""Driver faults with the simulator in the loop (ROS-free): a motor that
cannot follow, an encoder glitch, a joint that stops reporting, a drive fault
mid-motion. Each is detected, stops the base for real (ground truth), is
reported, and the base moves again once the fault clears and it is re-armed."""

import numpy as np
import pybullet as pb
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController, ControllerState
from holonomic_core.driver import DriverFault, JointReading
from holonomic_sim.sim_driver import SimDriver


class FaultySimDriver(SimDriver):
    """The sim driver with faults injected into what the controller reads."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.spike_joint = None      # add a velocity spike to this joint, once
        self.freeze = False          # keep returning the same (stale) reading
        self.fault_once = False      # raise a drive fault on the next read
        self._last = None

    def _on_read(self) -> JointReading:
        if self.fault_once:
            self.fault_once = False
            super()._on_read()
            raise DriverFault("over-current (injected)", self.model.joint_names[0])
        reading = super()._on_read()
        if self.freeze and self._last is not None:
            return self._last
        if self.spike_joint is not None:
            velocities = reading.velocities.copy()
            velocities[self.spike_joint] += 4000.0
            reading = JointReading(reading.stamp, reading.positions, velocities, reading.efforts)
            self.spike_joint = None
        self._last = reading
        return reading


class Rig:
    def __init__(self, robot="hamr", **overrides):
        # glitch_policy fault: one spike faults (test_sim_glitches.py: drop)
        self.cfg = load_config(robot, dict({"cmd_timeout": 0.0, "safety.glitch_policy": "fault"},
                                           **overrides))
        self.now = 0.0
        self.driver = FaultySimDriver(self.cfg.model, self.cfg.values,
                                      self.cfg.controller.control_rate)
        self.driver.configure()
        self.ctrl = BaseController(self.cfg, self.driver, clock=lambda: self.now)
        self.arm()

    def arm(self):
        future = self.ctrl.request_enable(True)
        self.run(None, 0.01)
        return future.result(0)

    def run(self, twist, seconds):
        for _ in range(int(round(seconds * 200))):
            if twist is not None:
                self.ctrl.set_command(twist)
            self.ctrl.step()
            # the sim clock runs on even when the controller sees a frozen stamp
            self.now = self.driver.sim_time()

    def speed(self):
        return float(np.linalg.norm(self.driver.ground_truth().twist[:2]))

    def close(self):
        self.driver.close()


@pytest.fixture
def rig():
    r = Rig()
    yield r
    r.close()


def assert_stopped_then_recovers(rig, what):
    assert what, "name the fault text the user sees"
    assert rig.ctrl.state is ControllerState.FAULT and what in rig.ctrl.fault, rig.ctrl.fault
    assert not rig.driver.armed
    rig.run((0.5, 0.0, 0.0), 1.0)          # commands are ignored while faulted
    assert rig.speed() < 0.01
    ok, message = rig.arm()
    assert ok, message
    rig.run((0.5, 0.0, 0.0), 1.5)
    assert rig.ctrl.state is ControllerState.ARMED and rig.speed() > 0.4


def test_a_base_pinned_in_place_saturates_the_motors_and_faults(rig):
    rig.run((0.5, 0.0, 0.0), 1.0)
    cid, body = rig.driver.plant.world.client, rig.driver.plant.robot.body
    pos, orn = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
    pin = pb.createConstraint(body, -1, -1, -1, pb.JOINT_FIXED, [0, 0, 0], [0, 0, 0], pos,
                              childFrameOrientation=orn, physicsClientId=cid)
    pb.changeConstraint(pin, maxForce=1e6, physicsClientId=cid)
    # wheels that grip (a pinned base with ordinary grip just spins them)
    wheels = rig.driver.plant.robot.joint_indices[:2]
    for link in wheels:
        pb.changeDynamics(body, link, lateralFriction=50.0, physicsClientId=cid)
    rig.run((0.5, 0.0, 0.0), 1.5)          # > tracking_timeout (0.5 s)
    assert rig.ctrl.fault is not None and "wheel_joint" in rig.ctrl.fault
    pb.removeConstraint(pin, physicsClientId=cid)
    for link in wheels:
        pb.changeDynamics(body, link, lateralFriction=1.0, physicsClientId=cid)
    assert_stopped_then_recovers(rig, "cannot follow its command")


def test_an_encoder_spike_faults_and_the_odometry_does_not_jump(rig):
    rig.run((0.5, 0.0, 0.0), 1.0)
    rig.driver.spike_joint = 0
    poses = [rig.ctrl.odometry.pose.copy()]
    for _ in range(100):                     # 0.5 s from the glitch on
        rig.run((0.5, 0.0, 0.0), 0.005)
        poses.append(rig.ctrl.odometry.pose.copy())
    assert "left_wheel_joint" in rig.ctrl.fault and "glitch" in rig.ctrl.fault
    # 4000 rad/s for one 5 ms cycle would be 1.2 m of odometry; not one step
    # moved more than the base can in a cycle (0.5 m/s * 5 ms, with margin)
    steps = np.linalg.norm(np.diff(np.array(poses)[:, :2], axis=0), axis=1)
    assert steps.max() < 0.005
    # the motors were disarmed (braked): the wheels skid a little, which no
    # encoder sees, but the odometry stays within centimetres of the truth
    truth, odo = rig.driver.ground_truth().pose, rig.ctrl.odometry.pose
    assert np.linalg.norm(truth[:2] - odo[:2]) < 0.05
    assert_stopped_then_recovers(rig, "left_wheel_joint: velocity reading")


def test_a_joint_that_stops_reporting_faults(rig):
    rig.run((0.5, 0.0, 0.0), 1.0)
    rig.driver.freeze = True
    rig.run((0.5, 0.0, 0.0), 0.2)            # > reading_timeout (0.05 s)
    assert rig.ctrl.state is ControllerState.FAULT
    rig.run(None, 1.0)
    rig.driver.freeze = False
    assert_stopped_then_recovers(rig, "joint readings stopped updating")


def test_a_drive_fault_mid_motion_stops_the_base(rig):
    rig.run((0.5, 0.0, 0.0), 1.0)
    rig.driver.fault_once = True
    rig.run((0.5, 0.0, 0.0), 0.005)
    assert "over-current" in rig.ctrl.fault
    rig.run(None, 1.0)
    assert_stopped_then_recovers(rig, "over-current")
