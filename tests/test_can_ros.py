"""The real base controller node on emulated ODrives (in a process of their
own, on a bus between processes: holonomic_testing.drive_host; the node's
loop in its own process, as on a robot): cmd_vel reaches the wire through the inverse
kinematics, odometry comes from the encoders, a drive fault is an ERROR in
diagnostics naming the drive, ~/enable is refused until it clears, and
shutting the node down stops every drive."""

import contextlib
import json
import math
import os
import shutil
import signal
import struct
import tempfile
import threading
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from holonomic_bringup.base_controller_node import BaseControllerNode
from holonomic_core.model import load_model
from holonomic_core.se2 import arc_between
from holonomic_drivers import odrive_endpoints
from holonomic_drivers import odrive_protocol as proto
from holonomic_drivers.odrive_protocol import AxisState
from holonomic_testing.drive_host import DriveHost
from holonomic_testing.ipc_can import IpcBus
from holonomic_testing.ros_probe import Probe, wait_until

NS = "canbot"


@contextlib.contextmanager
def odrive_robot(ros, drive_kwargs=None, params=()):
    """The node (its loop in its own process) on three emulated ODrives
    (``drive_kwargs`` for each ``EmulatedOdriveAxis``), with ``params``
    (more ``Parameter``s); yields (node, probe, devices, sniffer)."""
    folder = tempfile.mkdtemp(prefix="holonomic-can-")
    bus = f"{folder}/bus"
    host = DriveHost([("odrive_can", n, dict(drive_kwargs or {})) for n in (0, 1, 2)],
                     bus)      # config/hamr.yaml
    devices = host.devices
    sniffer = IpcBus(channel=bus)
    node = BaseControllerNode(namespace=NS, parameter_overrides=[
        Parameter("robot_config", value="hamr"), Parameter("driver", value="odrive_can"),
        Parameter("odrive_can.interface", value="holonomic_ipc"),
        Parameter("odrive_can.channel", value=bus),
        # this test process publishes the commands: on a loaded machine it
        # stalls now and then for more than the 0.5 s default (measured: the
        # wire at 0.72 x the command, the base braking and re-accelerating,
        # with two busy loops at load 12-22); the timeout itself is tested
        # elsewhere (test_hamr_ros, test_foxglove)
        Parameter("cmd_timeout", value=3.0), *params])
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    probe = Probe(ros, ns=NS)
    try:
        probe.wait_ready(ground_truth=False)
        yield node, probe, devices, sniffer
    finally:
        probe.close()
        stop.set()
        spinner.join(2.0)
        node.shutdown()
        executor.shutdown()
        node.destroy_node()
        sniffer.shutdown()
        host.close()
        shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture
def can_robot(ros):
    with odrive_robot(ros) as robot:
        yield robot


def _sniff(sniffer, frames) -> list:
    """Every frame on the bus so far, at least all the loop sent before the call."""
    sniffer.barrier()
    while (msg := sniffer.recv(timeout=0.0)) is not None:
        frames.append(msg)
    return frames


def _wire_before(frames, t: float) -> tuple[dict, dict]:
    """Per ODrive node, the last velocity setpoint [motor rev/s] sent and the
    last encoder position [motor rev] reported before ``t`` [s, wall clock]."""
    setpoints, positions = {}, {}
    for msg in frames:
        if msg.timestamp > t:
            continue            # (several senders: not strictly in stamp order)
        node, cmd = proto.split_id(msg.arbitration_id)
        if cmd == proto.Cmd.SET_INPUT_VEL:
            setpoints[node] = struct.unpack("<f", msg.data[:4])[0]
        elif cmd == proto.Cmd.GET_ENCODER_ESTIMATES:
            positions[node] = struct.unpack("<f", msg.data[:4])[0]
    return setpoints, positions


def _mean_twist(samples) -> np.ndarray:
    """The constant body twist [m/s, m/s, rad/s] that takes the odometry
    from the first sample's pose to the last's over the time between their
    stamps (not the mean of the messages' twists: each holds between
    readings, so under stamp jitter their mean is not the mean velocity)."""
    first, last = samples[0], samples[-1]
    return arc_between(first.pose, last.pose) / (last.stamp - first.stamp)


def test_cmd_vel_drives_the_odrives_and_a_fault_is_reported_by_name(can_robot):
    node, probe, devices, sniffer = can_robot
    frames = []
    model = load_model("hamr")
    # disarmed at start: commands do not reach the motors
    probe.drive((0.3, 0.0, 0.0), 0.3)
    assert all(d.velocity_rev_per_s == 0.0 for d in devices)
    assert probe.enable(True).success

    twist = np.array([0.3, 0.15, 0.5])
    probe.drive(tuple(twist), 1.0)
    t0 = time.monotonic()
    probe.drive(tuple(twist), 1.0)
    commanded_until = time.time()
    measured = _mean_twist(probe.odom_since(t0))
    # what was on the wire while the command held (after it, the command
    # times out in 0.5 s and the base brakes: a starved test may look later)
    motor, rev = _wire_before(_sniff(sniffer, frames), commanded_until)
    # hamr.yaml: right wheel direction -1, turret gear 10 (no position offsets)
    joint = np.array([motor[0], -motor[1], motor[2] / 10.0]) * 2 * math.pi
    positions = np.array([rev[0], -rev[1], rev[2] / 10.0]) * 2 * math.pi
    assert model.forward(positions, joint) == pytest.approx(twist, abs=5e-3)
    assert measured == pytest.approx(twist, abs=0.01)

    devices[2].inject_error(0x1000)            # CURRENT_LIMIT_VIOLATION on the turret
    probe.drive(tuple(twist), 0.3)
    wait_until(lambda: probe.diagnostics is not None and any(
        s.level == DiagnosticStatus.ERROR for s in probe.diagnostics.status
        if s.name.endswith("driver")), 5.0, "an ERROR from the driver in diagnostics")
    status = next(s for s in probe.diagnostics.status if s.name.endswith("driver"))
    assert "turret_joint (ODrive node 2)" in status.message
    assert "CURRENT_LIMIT_VIOLATION" in status.message
    # the healthy motors stop (the driver's stop is prompt, test_can_drivers
    # checks within two cycles; here the emulated motors ramp down at
    # 200 rev/s^2 from ~1 rev/s: 5 ms)
    wait_until(lambda: all(d.velocity_rev_per_s == 0.0 for d in devices[:2]), 2.0,
               "the healthy drives at standstill")

    refused = probe.enable(True)
    assert not refused.success and "turret_joint" in refused.message
    devices[2].clear_condition()
    assert probe.enable(True).success
    probe.drive(tuple(twist), 0.8)
    t0 = time.monotonic()
    probe.drive(tuple(twist), 0.5)
    measured = _mean_twist(probe.odom_since(t0))
    assert measured == pytest.approx(twist, abs=0.01)

    t = time.time()
    node.shutdown()
    _sniff(sniffer, frames)
    idle = {proto.split_id(m.arbitration_id)[0] for m in frames if m.timestamp >= t
            and proto.split_id(m.arbitration_id)[1] == proto.Cmd.SET_AXIS_STATE
            and m.data[0] == proto.AxisState.IDLE}
    assert idle == {0, 1, 2}


def _loop_pid() -> int:
    """The node's loop process: the child of this test process running loop_host."""
    for task in Path(f"/proc/{os.getpid()}/task").iterdir():
        for pid in (task / "children").read_text().split():
            if b"holonomic_bringup.loop_host" in Path(f"/proc/{pid}/cmdline").read_bytes():
                return int(pid)
    raise AssertionError("no loop process")


def _driver_status(probe):
    if probe.diagnostics is None:
        return None
    return next((s for s in probe.diagnostics.status if s.name.endswith("driver")), None)


def test_killing_the_loop_process_stops_every_odrive_by_its_axis_watchdog(ros, tmp_path):
    """Issue 24's "a crash of the loop stops the motors" on ODrives: the
    driver enables each axis watchdog at configure (0.2 s, over RxSdo with
    the drives' endpoints file) and will not arm otherwise; the loop process
    is killed with SIGKILL while the base drives: nothing is left to command
    the drives, and each goes idle with WATCHDOG_TIMER_EXPIRED, 0.2 s after
    the last frame it got."""
    path = tmp_path / "flat_endpoints.json"
    path.write_text(json.dumps({"fw_version": "0.6.11", "hw_version": "4.4.58", "endpoints": {
        "axis0.config.enable_watchdog": {"id": 300, "type": "bool", "access": "rw"},
        "axis0.config.watchdog_timeout": {"id": 301, "type": "float", "access": "rw"}}}))
    table = odrive_endpoints.load(str(path))
    with odrive_robot(ros, {"endpoints": table}, [
            Parameter("odrive_can.endpoints", value=str(path)),
            Parameter("odrive_can.set_watchdog", value=0.2),
            Parameter("odrive_can.watchdog_check", value="refuse")]) as (_, probe, devices, _s):
        wait_until(lambda: _driver_status(probe) is not None, 10.0, "driver diagnostics")
        values = {kv.key: kv.value for kv in _driver_status(probe).values}
        for joint in ("left_wheel_joint", "right_wheel_joint", "turret_joint"):
            assert "watchdog on, 0.2 s (read over CAN, firmware 0.6.11)" in values[joint]
        assert probe.enable(True).success
        probe.drive((0.3, 0.0, 0.0), 0.5)
        assert all(abs(d.velocity_rev_per_s) > 0.1 for d in devices[:2])   # the wheels turn
        loop = _loop_pid()
        killed = time.time()
        os.kill(loop, signal.SIGKILL)
        wait_until(lambda: all(d.axis_state == AxisState.IDLE for d in devices), 5.0,
                   "every drive idle")
        for d in devices:
            assert d.axis_error == proto.WATCHDOG_TIMER_EXPIRED["0.6"]
            fed, detected = d.watchdog_expired
            assert fed <= killed + 0.01
            # 0.2 s after the last frame, not before; the drives' 1 ms tick
            # after it (test_odrive_watchdog measures 0.03-1.1 ms; 50 ms for a
            # drives' process without real-time priority on a loaded machine)
            assert 0.2 <= detected - fed <= 0.25
        wait_until(lambda: all(d.velocity_rev_per_s == 0.0 for d in devices), 5.0,
                   "every motor stopped")
        wait_until(lambda: _driver_status(probe) is not None and "killed by SIGKILL" in
                   _driver_status(probe).message, 10.0, "the node reporting the loop's end")
