"""--sim-drives: the real CAN drivers (ODrive CANSimple, CiA 402) against
emulated drives on a virtual bus whose motors are the simulator's joints.

The base moves in the simulator as commanded, odometry from the drives'
encoders agrees with the simulator's ground truth, and a robot's CAN YAML
that disagrees with the mechanism (a wrong direction, a wrong gear ratio)
faults naming the joint -- with the controller core here, over ROS with
holonomic-bringup at the end.
"""

from __future__ import annotations

import gc
import math
import re
import signal
import subprocess
import shutil
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController, ControllerState
from holonomic_core.driver import JointReading
from holonomic_core.loop import ControlLoop
from holonomic_core.schema import ConfigError
from holonomic_sim.joint_motor import SimulatedJointMotor, SimulatedJoints
from holonomic_testing.can_rig import with_loop_scheduling
from holonomic_testing.ros_probe import Probe, relative_pose


#: These tests are about motion and mapping, not timing: the drives may
#: answer 0.2 s late before the backends (or the controller's reading
#: monitor) call it a fault (default 0.05 s), and heartbeats (both ways) may
#: pause for 1 s, so that a test machine running many other jobs does not
#: stop the robot.
_SLACK = {"safety.reading_timeout": 0.2}
TIMING = {"odrive_can": {"odrive_can.feedback_timeout": 0.2,
                         "odrive_can.heartbeat_timeout": 1.0, **_SLACK},
          "cia402": {"cia402.feedback_timeout": 0.2, "cia402.heartbeat_timeout": 1.0,
                     "cia402.drive_watchdog": 1.0, **_SLACK}}


class SimDrivesRig:
    """A BaseController over ``backend`` with --sim-drives, stepped at its
    rate, scheduled as the loop process runs it (loop_host.run_host): the
    emulated drives, the physics and canopen's notifier are threads of the
    controller's process, built with SCHED_FIFO so that they inherit it, and
    the cycles run in the product's ControlLoop. On the normal scheduler, on
    a loaded machine, eight emulated CiA 402 drives (swerve4, about half a
    core) answered hundreds of ms late: the PDO deadline faulted, or the
    YAML check saw a stale joint. Like the loop process, and unlike the
    node's, Python's default switch interval: a short one made those
    threads hand the interpreter lock back and forth and answer later."""

    def __init__(self, backend: str, robot: str = "hamr", **overrides):
        # as in can_rig: a full collection could pause the emulated drives
        gc.collect()
        gc.freeze()
        self.config = load_config(robot, {"driver": backend, "sim_drives": True,
                                          **TIMING[backend], **overrides})
        self.driver = self.config.driver_class(self.config.model, self.config.values,
                                               self.config.controller.control_rate)
        # configured with the loop's scheduling: the threads it starts (the
        # emulated drives', the physics', canopen's notifier) inherit it
        _, self.realtime_refused = with_loop_scheduling(self.driver.configure)
        self.controller = BaseController(self.config, self.driver)

    def arm(self) -> None:
        future = self.controller.request_enable(True)
        self.controller.step()
        assert future.result(timeout=5.0) == (True, "motors armed")

    def run(self, seconds: float, twist) -> None:
        """Command ``twist`` for ``seconds`` of the wall clock, on which the
        simulated physics runs (or until a fault), in the product's
        ControlLoop on a thread with the loop's scheduling (after a stall it
        re-anchors instead of running the missed cycles back to back)."""
        done = threading.Event()
        errors: list[BaseException] = []
        start = time.monotonic()

        def cycle() -> None:
            if time.monotonic() - start >= seconds:
                done.set()
                return
            self.controller.set_command(np.asarray(twist, float))
            self.controller.step()
            if self.controller.fault is not None:
                done.set()

        def on_error(exc: BaseException) -> bool:
            errors.append(exc)
            done.set()
            return False

        loop = ControlLoop(self.controller.dt, cycle, on_error, name="sim_drives_rig_loop")
        with_loop_scheduling(loop.start)            # its thread inherits it
        try:
            if not done.wait(10.0 * seconds + 10.0):
                raise TimeoutError(f"{seconds:g} s of cycles did not end within "
                                   f"{10 * seconds + 10:g} s")
        finally:
            loop.stop()
        if errors:
            raise errors[0]

    def close(self) -> None:
        self.driver.close()


@pytest.fixture
def rig_factory():
    rigs = []

    def make(*args, **kwargs) -> SimDrivesRig:
        rig = SimDrivesRig(*args, **kwargs)
        rigs.append(rig)
        return rig

    yield make
    for rig in rigs:
        rig.close()


@pytest.mark.parametrize("backend,overrides", [
    ("odrive_can", {}), ("odrive_can", {"odrive_can.firmware": "0.5"}), ("cia402", {})])
def test_the_can_driver_drives_the_simulated_base_and_odometry_matches_ground_truth(
        rig_factory, backend, overrides):
    rig = rig_factory(backend, **overrides)
    rig.arm()
    rig.run(2.0, (0.3, 0.0, 0.0))
    assert rig.controller.state is ControllerState.ARMED, rig.controller.fault
    # not one reading the glitch policy dropped (a false glitch would be one)
    assert rig.controller.status().dropped_readings == 0, rig.controller.status().last_dropped
    truth = rig.driver.ground_truth().pose
    odom = rig.controller.odometry.pose
    # 0.3 m/s for 2 s after a 0.3 s ramp at 1 m/s^2 (hamr.yaml): 0.3 (2 - 0.15)
    # = 0.555 m of command; the drives' frames (one cycle late) and late
    # cycles on a loaded machine take some of it (measured 0.50..0.56)
    assert 0.45 < truth[0] < 0.6
    # the encoders, through the YAML's mapping, tell the truth (measured
    # |odom - truth| <= 4.5 mm over six runs)
    assert np.abs(odom - truth) == pytest.approx(np.zeros(3), abs=0.02)
    # the joints moved through the CAN driver: its frame counters grew
    assert int(rig.driver.status()["frames_sent"]) > 100


def _factor(fault: str) -> float:
    return float(re.search(r"reads ([-+]\d+\.\d+) times", fault).group(1))


def test_a_wrong_direction_in_the_yaml_faults_naming_the_joint(rig_factory):
    # hamr.yaml says the right wheel's motor turns backwards (direction -1);
    # the mechanism here turns it forwards
    rig = rig_factory("odrive_can", **{"sim_drives.joints.right_wheel_joint.direction": 1})
    rig.arm()
    rig.run(3.0, (0.3, 0.0, 0.0))
    fault = rig.controller.fault
    assert fault is not None and "right_wheel_joint (ODrive node 1)" in fault, fault
    # reading / true motion = (+1 x 1) / (-1 x 1) = -1
    assert _factor(fault) == pytest.approx(-1.0, abs=0.05)
    assert "odrive_can.joints.right_wheel_joint.direction" in fault
    # what the robot did meanwhile: the wheels turned against each other, the
    # base spun while the encoders said it drove straight (measured: odometry
    # 0.30 m ahead, heading -0.0004 rad; truth turned -1.83 rad)
    truth, odom = rig.driver.ground_truth().pose, rig.controller.odometry.pose
    assert abs(odom[2]) < 0.01 and abs(truth[2]) > 0.3
    # the controller stopped the drives: every axis idle
    assert rig.controller.state is ControllerState.FAULT
    assert not rig.driver.armed


def test_a_wrong_gear_ratio_in_the_yaml_faults_naming_the_joint(rig_factory):
    # the YAML claims a 1.25:1 gearbox on the left wheel; the mechanism is 1:1
    rig = rig_factory("cia402", **{"cia402.joints.left_wheel_joint.gear_ratio": 1.25,
                                   "sim_drives.joints.left_wheel_joint.gear_ratio": 1.0})
    rig.arm()
    rig.run(3.0, (0.3, 0.0, 0.0))
    fault = rig.controller.fault
    assert fault is not None and "left_wheel_joint (CANopen node 1)" in fault, fault
    # reading / true motion = (1 x 1) / (1 x 1.25) = 0.8 (measured 0.77)
    assert _factor(fault) == pytest.approx(0.8, abs=0.05)
    assert "1.25" in fault


def test_a_reversed_steering_joint_of_a_caster_base_faults_naming_it(rig_factory):
    # comr3.yaml: c1's steering motor +1 through 20:1; the mechanism turns it
    # the other way. The caster steers away from where the controller thinks;
    # the check fires once the steering joint has turned 0.5 rad.
    rig = rig_factory("odrive_can", "comr3", **{"sim_drives.joints.c1_steer_joint.direction": -1})
    rig.arm()
    rig.run(3.0, (0.2, 0.2, 0.4))
    fault = rig.controller.fault
    assert fault is not None and "c1_steer_joint (ODrive node 0)" in fault, fault
    # (-1 x 20) / (+1 x 20) = -1 (measured -1.00, after 60 cycles, three runs)
    assert _factor(fault) == pytest.approx(-1.0, abs=0.05)


@pytest.mark.parametrize("driver", ["sim", "mock"])
def test_sim_drives_is_refused_for_backends_without_can(driver):
    with pytest.raises(ConfigError, match="sim_drives"):
        load_config("hamr", {"driver": driver, "sim_drives": True})


@pytest.mark.parametrize("args", [["--sim-drives"], ["--driver", "mock", "--sim-drives"]])
def test_bringup_refuses_sim_drives_without_a_can_driver(args):
    done = subprocess.run([shutil.which("holonomic-bringup"), "hamr"] + args,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "--sim-drives needs --driver cia402 or --driver odrive_can" \
        in lines[0]


# swerve4 on CiA 402: eight emulated drives in the loop's process
@pytest.mark.parametrize("robot,backend", [
    ("hamr", "odrive_can"), ("hamr", "cia402"), ("swerve4", "cia402")])
def test_bringup_with_sim_drives_drives_the_robot_over_ros(ros, start_bringup, robot, backend):
    ns = f"simdrives_{robot}_{backend}"
    timing = [arg for key, value in TIMING[backend].items() for arg in ("-p", f"{key}:={value}")]
    proc = start_bringup(robot, "--driver", backend, "--sim-drives", "--enable",
                         "--namespace", ns, *timing)
    probe = Probe(ros, ns)
    try:
        probe.wait_ready()                      # ground_truth/odom is published
        probe.wait_at_rest()
        odom0, truth0 = probe.latest_odom().pose, probe.latest_truth().pose
        probe.drive((0.3, 0.0, 0.5), 2.0)
        probe.wait_at_rest()
        moved_truth = relative_pose(truth0, probe.latest_truth().pose)
        moved_odom = relative_pose(odom0, probe.latest_odom().pose)
        # an arc of 0.3 m/s and 0.5 rad/s for ~2 s: about 0.5 m and 0.9 rad
        # (swerve4, its modules turning first: 0.50-0.52 m and 0.85-0.90 rad)
        distance = np.linalg.norm(moved_truth[:2])
        assert distance > 0.35 and moved_truth[2] > 0.6
        # odometry from the drives' encoders agrees with the simulator
        # (measured over four runs: at most 1.1 mm and 2.1 mrad; swerve4 at
        # most 0.5 mm and 0.7 mrad)
        assert np.linalg.norm(moved_odom[:2] - moved_truth[:2]) < 0.01
        assert abs(math.remainder(moved_odom[2] - moved_truth[2], 2 * math.pi)) < 0.01
        status = next(s for s in probe.diagnostics.status if s.name.endswith("driver"))
        values = {v.key: v.value for v in status.values}
        assert "motors = simulated joints" in values["sim_drives"]
        if "real-time scheduling unavailable" not in proc.log():
            # the loop asks for SCHED_FIFO before it builds the drivers, so the
            # threads they start inherit it: the loop's own, the CAN driver's
            # receive thread (it handles every drive's answer) and the emulated
            # drives' thread. Asked after them (as before), only the loop's was
            # real-time, and on a loaded computer the answers came late.
            policies = _thread_policies(_loop_pid(proc.proc.pid))
            assert policies.count(_SCHED_FIFO) >= 3, policies
    finally:
        probe.close()
    assert proc.stop(signal.SIGINT) == 0, proc.log()


_SCHED_FIFO = 1


def _loop_pid(node_pid: int) -> int:
    """The loop process: the node's only child process."""
    (child,) = [int(c) for task in Path(f"/proc/{node_pid}/task").iterdir()
                for c in (task / "children").read_text().split()]
    return child


def _thread_policies(pid: int) -> list[int]:
    """The scheduling policy of each thread of ``pid`` (proc(5): field 41 of
    /proc/PID/task/TID/stat; 0 SCHED_OTHER, 1 SCHED_FIFO)."""
    return [int((task / "stat").read_text().rsplit(")", 1)[1].split()[38])
            for task in Path(f"/proc/{pid}/task").iterdir()]


class _RecordingSim:
    """Stands in for the simulator driver: records what SimulatedJoints writes,
    reads back fixed joint states."""

    def __init__(self, positions, velocities):
        self.reading = JointReading(0.0, np.array(positions, float),
                                    np.array(velocities, float), np.zeros(len(positions)))
        self.writes = []

    def write_velocities(self, v):
        self.writes.append(("velocity", np.array(v)))

    def write_efforts(self, e):
        self.writes.append(("effort", np.array(e)))

    def read(self):
        return self.reading


def test_a_simulated_joint_seen_from_the_motor_shaft():
    sim = _RecordingSim([1.0, -0.5], [2.0, 0.25])
    joints = SimulatedJoints(sim, max_efforts=np.array([6.0, 4.0]),
                             max_velocities=np.array([20.0, 10.0]))
    joints.step()
    # joint 0 behind a 10:1 gear, mirrored (direction -1), zero at 0.2 rad
    motor = SimulatedJointMotor(joints, 0, gear_ratio=10.0, direction=-1, position_offset=0.2)
    # q_motor = -1 * 10 * (1.0 - 0.2) = -8 rad; w_motor = -1 * 10 * 2 = -20 rad/s
    assert motor.position() == pytest.approx(-8.0)
    assert motor.velocity() == pytest.approx(-20.0)
    # both joints in velocity mode: motor -30 rad/s -> joint -30 / (-10) = 3 rad/s
    motor.command_velocity(-30.0)
    joints.step()
    assert sim.writes[-1][0] == "velocity"
    assert sim.writes[-1][1] == pytest.approx([3.0, 0.0])
    # joint 0 in torque mode: motor 0.5 N m -> joint -1 * 10 * 0.5 = -5 N m; joint 1
    # still in velocity mode (setpoint 0, moving at 0.25 rad/s) gets the
    # proportional loop: gain 4 / (0.1 * 10) = 4 N m/(rad/s) -> -1 N m
    motor.command_torque(0.5)
    joints.step()
    assert sim.writes[-1][0] == "effort"
    assert sim.writes[-1][1] == pytest.approx([-5.0, -1.0])


# eight drives on one bus: their SYNC answers (CiA 402: 16 TPDOs a cycle)
# must keep up with the loop as the robot's would
@pytest.mark.parametrize("backend", ["cia402", "odrive_can"])
def test_the_can_driver_steers_and_drives_a_simulated_swerve_base(rig_factory, backend):
    # sideways on swerve4: every module first turns 90 deg (at most the 8 rad/s
    # steering limit, about 0.3 s, while the saturation holds the wheels back),
    # then the base strafes at 0.3 m/s after a 0.3 s ramp at 1 m/s^2; 2.5 s
    # of command: y = 0.3 (2.5 - 0.15 - ~0.3) = ~0.6 m
    rig = rig_factory(backend, "swerve4")
    rig.arm()
    rig.run(2.5, (0.0, 0.3, 0.0))
    assert rig.controller.state is ControllerState.ARMED, rig.controller.fault
    truth = rig.driver.ground_truth().pose
    odom = rig.controller.odometry.pose
    assert 0.45 < truth[1] < 0.7, truth
    assert abs(truth[0]) < 0.03 and abs(truth[2]) < 0.03, truth
    # the steering encoders through the YAML's mapping: modules across the base
    steer = rig.controller.reading.positions[0::2]
    assert np.abs(np.abs(steer) - math.pi / 2) == pytest.approx([0.0] * 4, abs=0.03)
    assert np.abs(odom - truth) == pytest.approx(np.zeros(3), abs=0.02)


@pytest.mark.parametrize("backend,overrides", [
    ("cia402", {}), ("odrive_can", {}), ("odrive_can", {"odrive_can.firmware": "0.5"})])
def test_estop_sends_the_quick_stop_on_the_wire_and_the_base_stops(
        rig_factory, backend, overrides):
    from holonomic_drivers.cia402_protocol import State
    from holonomic_drivers.odrive_protocol import ESTOP_REQUESTED, AxisState

    rig = rig_factory(backend, **overrides)
    rig.arm()
    rig.run(1.0, (0.5, 0.0, 0.0))
    assert rig.controller.state is ControllerState.ARMED, rig.controller.fault
    rig.controller.request_estop(True, "test")
    rig.run(1.0, (0.5, 0.0, 0.0))          # commands go on: they are not followed
    assert rig.controller.fault is None
    assert rig.controller.status().estop == "emergency stop pressed by test"
    drives = rig.driver.drives
    if backend == "cia402":
        # controlword QUICK STOP reached every drive: QUICK STOP ACTIVE, then
        # (the emulated drives' option code 2) SWITCH ON DISABLED once at
        # rest -- a plain disarm ("disable operation") ends SWITCHED ON
        assert all(d.state(0) in (State.QUICK_STOP_ACTIVE, State.SWITCH_ON_DISABLED)
                   for d in drives), [d.state(0) for d in drives]
    elif overrides.get("odrive_can.firmware") == "0.5":
        # the braking ramp: closed loop at zero velocity
        assert all(d.axis_state == AxisState.CLOSED_LOOP_CONTROL for d in drives)
    else:
        # the Estop frame: every axis disarmed with ESTOP_REQUESTED
        assert all(d.disarm_reason & ESTOP_REQUESTED["0.6"] for d in drives)
        assert all(d.axis_state == AxisState.IDLE for d in drives)
    # the base is at rest after a second (measured stop from 1 m/s: 0.09 m,
    # bench/estop_stop.py)
    assert abs(rig.driver.ground_truth().twist[0]) < 0.01
    # enable is refused until released; a release does not re-arm
    future = rig.controller.request_enable(True)
    rig.controller.step()
    assert future.result(timeout=5.0)[0] is False
    rig.controller.request_estop(False, "test")
    rig.run(0.2, (0.5, 0.0, 0.0))
    assert rig.controller.state is ControllerState.DISARMED
    rig.arm()
