"""The control loop's own process: drivers, controllers and (for the
simulator) the pybullet world, run at a fixed rate, ROS-free.

The ROS node (``base_controller_node``) is a shell around it; they talk
through three kinds of channel (:mod:`holonomic_bringup.loop_wire`):

* commands, node -> loop: one pipe per robot of fixed 32-byte records
  ``(vx, vy, wz, received)``; the loop drains it every cycle, after the
  cycle's reading and immediately before the control law uses the command
  (:meth:`BaseController.step`'s ``take_command``), and the latest command
  wins;
* state, loop -> node: one pipe per robot of fixed-size records (the
  cycle's reading, odometry, command; :class:`~loop_wire.RecordLayout`)
  written every ``publish_rate`` cycle; the node blocks on it and publishes;
* control, both ways: a ``SOCK_SEQPACKET`` socket of pickled messages
  (arm/disarm/reset requests and their answers, the controller status
  (:meth:`BaseController.status`) and loop timing once a second, log lines);

plus a heartbeat, a 64-bit cycle counter in shared memory that the node's
watchdog reads. Why pipes and not a seqlock'd shared-memory block, in
docs/realtime.md: a pipe write is one system call (a full memory barrier on
every CPU, ARM included, and it wakes the reader: no polling), atomic for
records under PIPE_BUF, and never blocks the loop (non-blocking: a full pipe
drops the record and counts it).

``python -m holonomic_bringup.loop_host SOCKET_FD HEARTBEAT_FD`` is the
process; :func:`run_host` also runs in a thread of the node's process for
drivers that cannot leave it (``loop.process: false``).
"""

from __future__ import annotations

import gc
import mmap
import os
import pickle
import signal
import socket
import sys
import time
from dataclasses import dataclass

import numpy as np

from holonomic_bringup import loop_wire as wire

#: how long before each deadline the loop stops sleeping and busy-waits [s].
#: A sleep to the deadline wakes late by the scheduler's wake-up latency
#: (``woke late`` in the 1 kHz loop rows of docs/benchmarks.md, ``make
#: bench``); spinning longer covers more of it but burns more of a core at
#: real-time priority (the core DDS and the node share, and real-time time
#: the kernel throttles at 95 %). 60 µs covers the usual lateness under
#: SCHED_FIFO with a 1 µs timer slack for 6 % of a core at 1 kHz.
LOOP_SPIN = 6e-5
#: consecutive failed cycles after which the loop gives up (motors stay off)
MAX_CONSECUTIVE_ERRORS = 50


@dataclass
class RobotSetup:
    """One robot of a host: its flat config (file + overrides, validated
    again in the host), and its channels' host-side file descriptors."""

    flat: dict
    source: str
    command_fd: int = -1
    state_fd: int = -1


@dataclass
class HostSetup:
    """What the host runs: robots, for a fleet one shared world
    (``shared_world``), and whether it runs in the node's process
    (``in_process``: no real-time request, it would apply to the node)."""

    robots: list[RobotSetup]
    shared_world: bool = False
    in_process: bool = False


class _Robot:
    """One robot in the host: controller, channels, decimation counters."""

    def __init__(self, index: int, config, controller, setup: RobotSetup, sim: bool):
        from holonomic_core.controller import ControllerState
        self.index = index
        self.config = config
        self.controller = controller
        self.layout = wire.RecordLayout.for_model(config.model)
        self.record = np.zeros(self.layout.size)
        self.command_fd = setup.command_fd
        self.state_fd = setup.state_fd
        ctrl = config.controller
        self.publish_every = max(1, round(ctrl.control_rate / ctrl.publish_rate))
        self.clock_every = max(1, round(ctrl.control_rate / 250.0)) if sim else 0
        self.diag_every = max(1, round(ctrl.control_rate))
        self.has_truth = controller.driver.ground_truth() is not None
        self.cycle = 0
        #: the cycle of each second [0, diag_every) that sends the status
        self.status_phase = 0
        #: when this cycle drained the command pipe [s, time.monotonic()]; None: not yet
        self.command_taken: float | None = None
        self.errors = 0
        self.dropped = 0
        self.pending: list = []         # (future, request id)
        self._states = {s: float(k) for k, s in enumerate(ControllerState)}

    def drain_commands(self) -> None:
        """Hand the commands the pipe holds to the controller (the latest
        wins). Called once a cycle, as late as the cycle allows (see
        :meth:`BaseController.step`): a command that arrives while the cycle
        reads the drives is still used by it."""
        self.command_taken = time.monotonic()
        try:
            data = os.read(self.command_fd, 1 << 16)
        except BlockingIOError:
            return
        for vx, vy, wz, received in wire.COMMAND.iter_unpack(data):
            self.controller.set_command((vx, vy, wz), received)

    def write_record(self, flags: int) -> None:
        c = self.controller
        odo, reading = c.odometry, c.reading
        r, lay = self.record, self.layout
        r[lay.flags] = flags
        r[lay.cycle] = self.cycle
        r[lay.stamp] = reading.stamp
        r[lay.command_taken] = self.command_taken
        r[lay.pose] = odo.pose
        r[lay.pose_cov] = odo.pose_covariance.ravel()
        r[lay.twist] = odo.twist
        r[lay.twist_cov] = odo.twist_covariance.ravel()
        r[lay.twist_command] = c.twist_command
        r[lay.positions] = reading.positions
        r[lay.velocities] = reading.velocities
        r[lay.efforts] = reading.efforts
        if lay.units:
            residual = odo.residual
            # no fit yet (before the second reading): no residual
            r[lay.residual] = residual if len(residual) == lay.units else np.nan
        r[lay.state] = self._states[c.state]
        r[lay.stale] = c.stale
        r[lay.saturation] = c.saturation
        truth = c.driver.ground_truth() if self.has_truth else None
        if truth is not None:
            r[lay.truth_valid] = 1.0
            r[lay.truth_pose] = truth.pose
            r[lay.truth_twist] = truth.twist
        else:
            r[lay.truth_valid] = 0.0
        try:
            os.write(self.state_fd, r.data)
        except BlockingIOError:
            self.dropped += 1   # the node is not reading: the loop does not wait for it


def _fail(sock, exc) -> None:
    """Report a ConfigError to the node (it raises the same)."""
    wire.send(sock, ("error", (exc.key, exc.value, exc.allowed, str(exc))))


def _build(setup: HostSetup, sock, before_drivers=None):
    """Configs, world, drivers and controllers; None after reporting an error.
    ``before_drivers(first config)`` runs once the configs are valid, before
    any driver or world exists."""
    from holonomic_core.config import config_from_flat
    from holonomic_core.controller import BaseController
    from holonomic_core.driver import DriverError
    from holonomic_core.nominal import driver_for
    from holonomic_core.schema import ConfigError

    configs = []
    for k, robot in enumerate(setup.robots):
        try:
            configs.append(config_from_flat(robot.flat, robot.source))
        except ConfigError as exc:
            _fail(sock, exc)
            return None
    if before_drivers is not None:
        before_drivers(configs[0])
    world = None
    if setup.shared_world:
        from holonomic_sim.world import SimWorld
        world = SimWorld(configs[0].values["sim.physics_rate"],
                         floor_tilt=configs[0].values["sim.floor_tilt"])
    robots, drivers = [], []
    try:
        for k, (cfg, robot) in enumerate(zip(configs, setup.robots)):
            extra = {"world": world} if world is not None else {}
            # a simulated robot is built from the robot's drawing (its config
            # file), not from the controller's calibrated belief
            driver = driver_for(cfg, **extra)
            drivers.append(driver)
            try:
                driver.configure()
            except DriverError as exc:
                _fail(sock, ConfigError("driver", cfg.controller.driver,
                                        f"a backend that configures ({exc})"))
                raise
            controller = BaseController(cfg, driver)
            robots.append(_Robot(k, cfg, controller, robot, driver.sim_time() is not None))
    except (DriverError, ConfigError) as exc:
        if isinstance(exc, ConfigError):
            _fail(sock, exc)
        for driver in drivers:
            driver.close()
        if world is not None:
            world.close()
        return None
    if world is not None:
        world.settle()
    return world, robots


def run_host(setup: HostSetup, sock: socket.socket, heartbeat: memoryview,
             stopping=None) -> int:
    """Build the robots, report ``ready``, run the loop until told to stop;
    then stop and disarm the motors, close the drivers. Returns the exit code
    (0: stopped on request or by SIGTERM; 1: the loop gave up after repeated
    failures; 2: the robots could not be built)."""
    from holonomic_core.loop import ControlLoop, LoopStats
    from holonomic_core.realtime import (current_policy, schedule_loop, tighten_timer_slack,
                                         warm_up_linear_algebra)

    beat = np.frombuffer(heartbeat, dtype=np.int64, count=1)
    clock = time.perf_counter
    def schedule(first) -> None:
        # before the drivers are built: the threads they start (canopen's
        # notifier, python-can's receive thread, which handle every drive's
        # answer) inherit the loop's scheduling; left on the normal scheduler
        # they answer late on a loaded computer and the driver faults ("PDOs
        # late"). The simulator's physics process sets its own priority.
        if setup.in_process:
            return
        # sleeps end within 1 µs of the deadline instead of the default 50 µs
        # (real-time threads get no slack anyway; normal ones do)
        tighten_timer_slack()
        for warning in schedule_loop(bool(first.values["loop.realtime"]),
                                     int(first.values["loop.priority"]),
                                     float(first.values["loop.slice"])):
            wire.send(sock, ("log", 0, "warn", warning))

    built = _build(setup, sock, schedule)
    if built is None:
        return 2
    world, robots = built
    first = robots[0].config
    rate = first.controller.control_rate
    substeps = round(first.values["sim.physics_rate"] / rate) if world is not None else 0
    wire.send(sock, ("ready", [
        {"sim": r.controller.driver.sim_time() is not None, "ground_truth": r.has_truth}
        for r in robots]))
    for r in robots:
        if r.config.controller.enable_on_start:
            r.pending.append((r.controller.request_enable(True), None))
    # The once-a-second work in different cycles, never stacked in one: each
    # robot's status at its own phase of the second, the collector halfway
    # between the first two (each takes a sizeable part of the 1 ms period:
    # together with a slow control step they would overrun it; ``status`` and
    # ``gc`` in the loop's cycle split, docs/benchmarks.md)
    diag_every = robots[0].diag_every
    for r in robots:
        r.status_phase = (r.index * r.diag_every) // len(robots)
    gc_phase = diag_every // (2 * len(robots))
    sock.setblocking(False)
    state = {"give_up": False, "loop": None}

    def handle(message) -> None:
        kind = message[0]
        if kind == "stop":
            state["loop"].stop(timeout=0.0)
        elif kind == "enable":
            _, k, enable, rid = message
            robots[k].pending.append((robots[k].controller.request_enable(enable), rid))
        elif kind == "reset_odometry":
            _, k, rid = message
            robots[k].pending.append((robots[k].controller.request_reset_odometry(), rid))
        elif kind == "unwind":
            _, k, rid = message
            robots[k].pending.append((robots[k].controller.request_unwind(), rid))
        elif kind == "estop":
            _, k, pressed, source, received, rid = message
            robots[k].controller.request_estop(pressed, source, received)
            wire.send(sock, ("reply", rid, (True, "pressed" if pressed else "released")))
        elif kind == "set_pose":
            _, k, pose, covariance, rid = message
            robots[k].pending.append((robots[k].controller.request_set_pose(pose, covariance),
                                      rid))

    def poll_control() -> None:
        while True:
            try:
                message = wire.receive(sock)
            except BlockingIOError:
                return
            if message is None:     # the node is gone: stop the motors
                state["loop"].stop(timeout=0.0)
                return
            handle(message)

    def answer(r: _Robot) -> None:
        still = []
        for future, rid in r.pending:
            if not future.done():
                still.append((future, rid))
            elif rid is not None:
                wire.send(sock, ("reply", rid, future.result()))
            else:
                ok, text = future.result()
                wire.send(sock, ("log", r.index, "info" if ok else "error",
                                 f"enable_on_start: {text}"))
        r.pending = still

    def status(r: _Robot) -> None:
        loop = state["loop"]
        wire.send(sock, ("status", r.index, r.controller.status(),
                         {**loop.stats.summary(), "dropped_records": r.dropped,
                          "scheduling": state["policy"]}))

    def robot_cycle(r: _Robot) -> None:
        r.cycle += 1
        r.command_taken = None
        t = clock()
        r.controller.step(r.drain_commands)
        add_part("controller", clock() - t)
        if r.command_taken is None:     # a cycle that failed before its control law
            r.drain_commands()
        if r.pending:
            answer(r)
        if r.controller.reading is not None:
            flags = wire.PUBLISH if r.cycle % r.publish_every == 0 else 0
            if r.clock_every and r.cycle % r.clock_every == 0:
                flags |= wire.CLOCK
            if flags:
                t = clock()
                r.write_record(flags)
                add_part("state_write", clock() - t)
        if r.index == 0 and not setup.in_process and r.cycle % diag_every == gc_phase:
            # the collector runs here, once a second, timed, instead of
            # whenever an allocation count says so (it is disabled below)
            t = clock()
            gc.collect()
            add_part("gc", clock() - t)
        if r.cycle % r.diag_every == r.status_phase:
            t = clock()
            status(r)
            add_part("status", clock() - t)

    def cycle() -> None:
        poll_control()
        if world is not None:
            t = clock()
            world.step(substeps)
            add_part("physics", clock() - t)
        for r in robots:
            try:
                robot_cycle(r)
                r.errors = 0
            except Exception as exc:            # this robot stops; the others go on
                r.errors += 1
                wire.send(sock, ("log", r.index, "error",
                                 f"control cycle failed: {exc!r}; stopping the motors"))
                r.controller.raise_fault(f"internal error: {exc!r}")
                if r.errors >= MAX_CONSECUTIVE_ERRORS and len(robots) == 1:
                    state["give_up"] = True
                    state["loop"].stop(timeout=0.0)
        beat[0] += 1

    def on_error(exc: BaseException) -> bool:    # the world's step failed
        wire.send(sock, ("log", 0, "error", f"control cycle failed: {exc!r}; "
                                            "stopping the motors"))
        for r in robots:
            r.controller.raise_fault(f"internal error: {exc!r}")
        state["give_up"] = True
        return False

    loop = ControlLoop(1.0 / rate, cycle, on_error=on_error, name="control_loop",
                       spin=LOOP_SPIN)
    state["loop"] = loop
    add_part = loop.stats.add_part
    if stopping is not None:
        stopping.append(loop)
    state["policy"] = current_policy() + ("" if not setup.in_process else " (thread)")
    # The start-up objects out of the collector's way, and no collection
    # triggered by allocation counts in the middle of a cycle: the loop
    # collects once a second itself (`gc` in the cycle split). In a
    # thread of the node's process (in_process) the collector is the node's.
    # The first status costs many periods (numpy's percentile and pickle set
    # themselves up on first use): pay it here, not in the cycle a second in.
    # So is numpy's BLAS work buffer: mapped by the first matrix product
    # that needs it, page by page under mlockall; otherwise the PCV's drift
    # watch would pay it in a cycle about 2 s after the base first moves.
    warm_up_linear_algebra()
    warm = LoopStats(window=2)
    warm.add(0.0, 0.0)
    warm.add_part("warm_up", 0.0)
    for r in robots:
        pickle.dumps((r.controller.status(), warm.summary()))
    gc.freeze()
    if not setup.in_process:
        gc.disable()
    try:
        loop.run()
    finally:
        for r in robots:
            try:
                r.controller.shutdown()
            except Exception as exc:     # noqa: BLE001 -- report it, close the others
                wire.send(sock, ("log", r.index, "error", f"shutdown: {exc!r}"))
        if world is not None:
            world.close()
        wire.send(sock, ("stopped", 1 if state["give_up"] else 0))
    return 1 if state["give_up"] else 0


def _die_with_parent() -> None:
    """SIGTERM this process when the node's process dies (Linux prctl), so
    a killed node never leaves a loop commanding motors."""
    import ctypes
    import ctypes.util
    pr_set_pdeathsig = 1
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        libc.prctl(pr_set_pdeathsig, signal.SIGTERM)
    except (OSError, AttributeError):
        pass


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parent = os.getppid()
    # SIGINT from a terminal goes to the node (it stops this process through
    # the socket); SIGTERM to this process alone stops the loop cleanly.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    stopping: list = []

    def on_term(signum, frame):   # noqa: ARG001
        for loop in stopping:
            loop.stop(timeout=0.0)
    signal.signal(signal.SIGTERM, on_term)
    _die_with_parent()
    if os.getppid() != parent:       # the parent died before prctl
        return 0
    sock = socket.socket(fileno=int(argv[0]))
    heartbeat = mmap.mmap(int(argv[1]), wire.HEARTBEAT_SIZE)
    setup = wire.receive(sock)
    if setup is None:                # the node went before sending the set-up
        return 0
    for r in setup.robots:
        os.set_blocking(r.command_fd, False)
        os.set_blocking(r.state_fd, False)
    return run_host(setup, sock, memoryview(heartbeat), stopping)


if __name__ == "__main__":
    sys.exit(main())
