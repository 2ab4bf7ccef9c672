"""A base controller on emulated CAN drives, modelled as on a robot.

``CanRig(backend, robot)`` starts one emulated drive per joint in a process
of its own at real-time priority (:mod:`holonomic_testing.drive_host`: a
real drive is never starved by a busy host), on a private bus that crosses
processes (python-can interface ``holonomic_ipc``,
:mod:`holonomic_testing.ipc_can`); the product's driver, unchanged, opens it
as it opens socketcan. A sniffer records every frame with its send time.
``run(seconds, twist)`` steps the BaseController at its rate in the
product's ControlLoop, on a thread with the loop process's scheduling
(SCHED_FIFO at the default priority, tight timer slack), and records when
each cycle started. ``devices`` are the drives (Remote objects: attributes
and methods of the device in its process).
"""

from __future__ import annotations

import gc
import itertools
import os
import shutil
import struct
import sys
import tempfile
import threading
import time

import can
import numpy as np

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.driver import emulated_drive_class
from holonomic_core.loop import ControlLoop
from holonomic_core.realtime import DEFAULT_PRIORITY, set_fifo, tighten_timer_slack
from holonomic_core.se2 import arc_between
from holonomic_drivers import cia402_protocol as co
from holonomic_drivers import odrive_protocol as proto
from holonomic_testing.drive_host import DriveHost
from holonomic_testing.ipc_can import IpcBus

_channels = itertools.count()


def unique_channel(tag: str) -> str:
    return f"{tag}-{os.getpid()}-{next(_channels)}"


def with_loop_scheduling(action, realtime: bool = True):
    """``action()`` in a short-lived thread given the loop process's
    scheduling (loop_host.run_host: tight timer slack, SCHED_FIFO at the
    default priority if ``realtime``); the threads it starts inherit it, the
    test's own threads keep theirs. Not mlockall: it would lock the whole
    pytest session's memory for every later test (and a page fault is not
    what starves a loaded machine's test, the CPU is). Returns ``(what
    action returned, why SCHED_FIFO was refused or None)``; raises what
    ``action`` raised."""
    outcome: list = []
    refused: list = [None]

    def body() -> None:
        tighten_timer_slack()
        if realtime:
            refused[0] = set_fifo(DEFAULT_PRIORITY)
        try:
            outcome.append((True, action()))
        except BaseException as exc:        # raised in the caller's thread
            outcome.append((False, exc))

    thread = threading.Thread(target=body, name="can_rig_scheduled")
    thread.start()
    thread.join()
    ok, value = outcome[0]
    if not ok:
        raise value
    return value, refused[0]


class CanRig:
    def __init__(self, backend: str, robot: str = "hamr", realtime: bool = True,
                 drive_eds: str | None = None, **overrides):
        """``realtime``: ask for SCHED_FIFO for the drives' process and the
        loop's thread (as the product's loop process does, default on); when
        the system refuses, ``realtime_refused`` says why (one line, also on
        stderr) and the rig runs without. ``drive_eds``: the file the
        emulated CiA 402 drives are built from when it is not the driver's
        (a drive that differs from its file)."""
        # The controller shares this (large, long-lived) test process with
        # canopen's notifier thread: a full garbage collection here can pause
        # both for tens of ms. The loop process freezes its own start-up
        # objects for the same reason (loop_host.run_host).
        gc.collect()
        gc.freeze()
        # ... and, like the node (base_controller_node.main), a short GIL
        # switch interval: the loop and canopen's notifier are threads of
        # one process; with Python's default 5 ms a SYNC -> answer ->
        # notifier round trip can wait tens of ms for the GIL.
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(5e-4)
        self.backend = backend
        self.realtime = realtime
        self._folder = tempfile.mkdtemp(prefix="holonomic-can-")
        #: the bus: the hub's socket in the drives' process
        self.channel = os.path.join(self._folder, "bus")
        # coast: a disarm request reaches the driver's disarm frames at once
        # (safety.disarm_mode hold would keep the drives at zero velocity)
        params = {"driver": backend, f"{backend}.interface": "holonomic_ipc",
                  f"{backend}.channel": self.channel, "safety.disarm_mode": "coast"}
        params.update(overrides)
        self.config = load_config(robot, params)
        self.model = self.config.model
        self.driver = self.config.driver_class(self.model, self.config.values,
                                               self.config.controller.control_rate)
        self.node_ids = self.driver.joints.node_ids
        # one emulated device per node (a multi-axis CiA 402 device serves
        # the joints that share its node id), as the YAML describes the
        # node's first joint; a CiA 402 drive's velocity unit is what its
        # file's 0x60A9 says, independent of the driver's parameters
        emulated = emulated_drive_class(backend)
        specs = []
        for n in dict.fromkeys(self.node_ids):
            settings = emulated.settings_for(
                self.config.values, self.model.joint_names[self.node_ids.index(n)])
            if drive_eds:
                settings["eds"] = drive_eds
            specs.append((backend, n, settings))
        try:
            self.host = DriveHost(specs, self.channel, realtime=realtime)
        except BaseException:
            shutil.rmtree(self._folder, ignore_errors=True)
            raise
        #: why real-time scheduling was refused (None: granted or not asked)
        self.realtime_refused = self.host.realtime if realtime else None
        self.devices = self.host.devices
        #: the drives' EmulatorThread (``stop()`` it to step the drives by hand)
        self.emulators = self.host.emulators
        self.sniffer = self.open_bus()
        self.frames: list[can.Message] = []
        self.controller = None
        self.cycle_starts: list[float] = []
        #: (reading stamp [s], odometry pose [m, m, rad]) after each cycle of ``run``
        self.odometry_poses: list[tuple[float, np.ndarray]] = []

    def open_bus(self, **kwargs) -> IpcBus:
        """Another node on the rig's bus (a test script; kwargs as for
        python-can's virtual bus, e.g. ``preserve_timestamps=True``)."""
        return IpcBus(channel=self.channel, **kwargs)

    def configure_driver(self) -> None:
        """The driver's configure, in a thread with the loop's scheduling:
        the threads it starts (canopen's notifier, which handles every
        answer of a CiA 402 drive) inherit it."""
        self._with_loop_scheduling(self.driver.configure)

    def configure(self) -> "CanRig":
        self.configure_driver()
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
            if self.controller.reading is not None:       # None: no reading yet (a fault)
                self.odometry_poses.append((self.controller.reading.stamp,
                                            self.controller.odometry.pose.copy()))
            count += 1

        def on_error(exc: BaseException) -> bool:
            errors.append(exc)
            done.set()
            return False

        loop = ControlLoop(self.controller.dt, cycle, on_error, name="can_rig_loop")
        self._with_loop_scheduling(loop.start)          # its thread inherits it
        try:
            if not done.wait(10.0 * seconds + 10.0):
                raise TimeoutError(f"{cycles} cycles did not run within {10 * seconds + 10:g} s")
        finally:
            loop.stop()
        if errors:
            raise errors[0]

    def _with_loop_scheduling(self, action):
        """``action()`` with the loop process's scheduling
        (:func:`with_loop_scheduling`); the first refusal is kept in
        ``realtime_refused`` and said on stderr."""
        value, refused = with_loop_scheduling(action, self.realtime)
        if refused is not None and self.realtime_refused is None:
            self.realtime_refused = refused
            print(f"can_rig: {refused}; the loop runs without", file=sys.stderr)
        return value

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
        return arc_between(start, end) / (t1 - t0)

    @staticmethod
    def wait_for(predicate, timeout: float, what: str) -> None:
        """Wait until ``predicate()`` is true, at most ``timeout`` [s] (then
        AssertionError naming ``what``): for what crosses between the
        processes (the drives' answers, their motors' state)."""
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
            time.sleep(0.01)

    def sniff(self) -> list[can.Message]:
        """Every frame on the bus so far (send time in ``timestamp``), at
        least all that the driver sent before the call."""
        self.sniffer.barrier()
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
            self.sniffer.shutdown()
            self.host.close()
            shutil.rmtree(self._folder, ignore_errors=True)
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
