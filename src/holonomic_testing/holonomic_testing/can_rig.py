"""A base controller on emulated CAN drives, in the test process.

``CanRig(backend, robot)`` opens a private python-can virtual channel,
starts one emulated drive per joint (background thread), a sniffer that
records every frame with its send time, the driver and a BaseController.
``run(seconds, twist)`` steps the controller at its rate in the product's
ControlLoop and records when each cycle started.
"""

from __future__ import annotations

import gc
import itertools
import math
import os
import struct
import sys
import threading
import time

import can
import numpy as np

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.loop import ControlLoop
from holonomic_drivers import cia402_protocol as co
from holonomic_drivers import odrive_protocol as proto
from holonomic_drivers.emulated_cia402 import EmulatedCia402Drive
from holonomic_drivers.emulation import EmulatedOdriveAxis, EmulatorThread

_channels = itertools.count()


def unique_channel(tag: str) -> str:
    return f"{tag}-{os.getpid()}-{next(_channels)}"


class CanRig:
    def __init__(self, backend: str, robot: str = "hamr", **overrides):
        # The emulated drives and the controller share this (large, long-lived)
        # test process: a full garbage collection here can pause both for tens
        # of ms and trip the drivers' feedback timeouts. The node freezes its
        # own start-up objects for the same reason (base_controller_node.main).
        gc.collect()
        gc.freeze()
        # ... and, like the node (base_controller_node.main), a short GIL
        # switch interval: the loop, canopen's notifier and the emulated
        # drives are threads of one process; with Python's default 5 ms a
        # SYNC -> answer -> notifier round trip can wait tens of ms for the
        # GIL on a busy machine and trip the 50 ms feedback timeout.
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(5e-4)
        self.backend = backend
        self.channel = unique_channel(backend)
        params = {"driver": backend, f"{backend}.interface": "virtual",
                  f"{backend}.channel": self.channel}
        params.update(overrides)
        self.config = load_config(robot, params)
        self.model = self.config.model
        self.driver = self.config.driver_class(self.model, self.config.values,
                                               self.config.controller.control_rate)
        self.node_ids = self.driver.joints.node_ids
        if backend == "odrive_can":
            firmware = self.config.values["odrive_can.firmware"]
            self.devices = [EmulatedOdriveAxis(n, self.channel, firmware=firmware)
                            for n in self.node_ids]
        else:
            # one emulated device per node, built from the joint's EDS (the
            # generic drive without one); its velocity unit is what the
            # file's 0x60A9 says, independent of the driver's parameters
            v = self.config.values
            self.devices = []
            for n in dict.fromkeys(self.node_ids):
                j = self.model.joint_names[self.node_ids.index(n)]
                eds = v[f"cia402.joints.{j}.eds"] or v["cia402.eds"] or None
                self.devices.append(EmulatedCia402Drive(
                    n, self.channel, eds,
                    encoder_resolution=int(v[f"cia402.joints.{j}.encoder_resolution"])))
        self.sniffer = can.Bus(interface="virtual", channel=self.channel)
        self.frames: list[can.Message] = []
        self.emulators = EmulatorThread(self.devices).start()
        self.controller = None
        self.cycle_starts: list[float] = []
        #: the odometry's twist after each cycle of ``run``
        self.odometry_twists: list[np.ndarray] = []
        #: (reading stamp [s], odometry pose [m, m, rad]) after each cycle of ``run``
        self.odometry_poses: list[tuple[float, np.ndarray]] = []

    def configure(self) -> "CanRig":
        self.driver.configure()
        self.controller = BaseController(self.config, self.driver)
        return self

    def arm(self) -> tuple[bool, str]:
        future = self.controller.request_enable(True)
        self.step()
        return future.result(timeout=5.0)

    def step(self) -> bool:
        self.cycle_starts.append(time.time())
        return self.controller.step()

    def run(self, seconds: float, twist=None) -> None:
        """Run ``seconds`` worth of cycles in the product's own ControlLoop
        (absolute deadlines; after a stall it re-anchors instead of running
        the missed cycles back to back, as the node does)."""
        cycles = round(seconds / self.controller.dt)
        done = threading.Event()
        errors: list[BaseException] = []
        count = 0

        def cycle() -> None:
            nonlocal count
            if count >= cycles:
                done.set()
                return
            if twist is not None:
                self.controller.set_command(twist)
            self.step()
            self.odometry_twists.append(self.controller.odometry.twist.copy())
            self.odometry_poses.append((self.controller.reading.stamp,
                                        self.controller.odometry.pose.copy()))
            count += 1

        def on_error(exc: BaseException) -> bool:
            errors.append(exc)
            done.set()
            return False

        loop = ControlLoop(self.controller.dt, cycle, on_error, name="can_rig_loop")
        loop.start()
        try:
            if not done.wait(10.0 * seconds + 10.0):
                raise TimeoutError(f"{cycles} cycles did not run within {10 * seconds + 10:g} s")
        finally:
            loop.stop()
        if errors:
            raise errors[0]

    def mean_odometry_twist(self, seconds: float) -> np.ndarray:
        """The constant body twist [m/s, m/s, rad/s] that takes the odometry
        from its pose read ``seconds`` before its last reading to its last pose,
        over the time between the two readings' stamps (the SE(2) logarithm
        of the pose change over that time). Not the mean of the per-cycle
        twists: each is held until the next sample, so when stamps jitter (a
        loaded machine) their mean is not the mean velocity."""
        t1, end = self.odometry_poses[-1]
        # the newest pose read at least ``seconds`` before the last one (by
        # the readings' stamps: after a stall of the drives several cycles
        # repeat a reading)
        t0, start = next(((t, p) for t, p in reversed(self.odometry_poses)
                          if t <= t1 - seconds), self.odometry_poses[0])
        dx, dy = end[0] - start[0], end[1] - start[1]
        c, s = math.cos(start[2]), math.sin(start[2])
        x, y = c * dx + s * dy, -s * dx + c * dy          # in the start pose's frame
        theta = math.remainder(end[2] - start[2], 2 * math.pi)
        # a constant twist (v, w) for time T moves by V(theta) v T, with
        # V = [[sin t / t, -(1 - cos t) / t], [(1 - cos t) / t, sin t / t]]
        if abs(theta) < 1e-9:
            a, b = 1.0, 0.0
        else:
            a, b = math.sin(theta) / theta, (1.0 - math.cos(theta)) / theta
        det = a * a + b * b
        vx, vy = (a * x + b * y) / det, (-b * x + a * y) / det
        return np.array([vx, vy, theta]) / (t1 - t0)

    def sniff(self) -> list[can.Message]:
        """Every frame on the bus so far (send time in ``timestamp``)."""
        while (msg := self.sniffer.recv(timeout=0.0)) is not None:
            self.frames.append(msg)
        return self.frames

    def cycles_between(self, t0: float, t1: float) -> int:
        """Control cycles that started in [t0, t1] (wall clock, time.time())."""
        return sum(t0 <= t <= t1 for t in self.cycle_starts)

    def close(self) -> None:
        try:
            self.driver.close()
        finally:
            self.emulators.stop()
            for device in self.devices:
                device.close()
            self.sniffer.shutdown()
            sys.setswitchinterval(self._switch_interval)

    # -- what the drives were told -----------------------------------------------------
    def velocity_setpoints(self, node: int, frames=None) -> list[tuple[float, float]]:
        """(send time, setpoint [motor rev/s]) sent to ``node``, and for CiA 402 only
        while the controlword enables operation (else the setpoint is 0)."""
        out = []
        for msg in frames if frames is not None else self.sniff():
            if self.backend == "odrive_can":
                if msg.arbitration_id == proto.frame_id(node, proto.Cmd.SET_INPUT_VEL):
                    out.append((msg.timestamp, struct.unpack("<f", msg.data[:4])[0]))
            elif msg.arbitration_id == co.RPDO[0] + node and len(msg.data) == 6:
                word, units = struct.unpack("<Hi", msg.data)
                i = self.node_ids.index(node)
                rev_s = units / self.driver._vel_units_per_rev_s[i]
                out.append((msg.timestamp, rev_s if word & 0x8F == 0x0F else 0.0))
        return out

    def stop_time(self, node: int, after: float) -> float | None:
        """Send time of the first "stop and disable" frame to ``node`` after ``after``."""
        for msg in self.sniff():
            if msg.timestamp < after:
                continue
            if self.backend == "odrive_can":
                if (msg.arbitration_id == proto.frame_id(node, proto.Cmd.SET_AXIS_STATE)
                        and msg.data[0] == proto.AxisState.IDLE):
                    return msg.timestamp
            elif (msg.arbitration_id == co.RPDO[0] + node
                  and struct.unpack("<Hi", msg.data) == (co.Control.SWITCH_ON, 0)):
                return msg.timestamp
        return None

    def motor_to_joint_positions(self) -> np.ndarray:
        """Joint positions from the emulated motors' own positions, through the
        mapping as the YAML states it (independent of the driver's JointMap)."""
        out = []
        for j, device in zip(self.model.joint_names, self.devices):
            base = f"{self.backend}.joints.{j}"
            v = self.config.values
            out.append(v[f"{base}.direction"] * 2 * np.pi * device.position_rev
                       / v[f"{base}.gear_ratio"] + v[f"{base}.position_offset"])
        return np.array(out)
