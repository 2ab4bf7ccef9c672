"""The physics process's own side (``python -m holonomic_sim.physics_plant``).

Started by the loop's :class:`holonomic_sim.physics_process.PhysicsLink`
(whose module describes the channels, the lifetime and the scheduling): it
builds an ordinary in-process :class:`~holonomic_sim.sim_driver.SimDriver`
from the set-up message and steps it on the wall clock, one control period
of physics every control period, reading the newest command record and
writing a state record after each period it stepped.
"""

from __future__ import annotations

import os
import signal
import socket
import sys
import time

import numpy as np

from holonomic_core.control_socket import receive, send
from holonomic_core.schema import ConfigError
from holonomic_sim.physics_process import (FLAGS, HOLD, LOST, MAX_CATCH_UP, STAMP, VELOCITY,
                                           StateLayout, read_newest)
from holonomic_sim.sim_driver import SimDriver


def _die_with_parent() -> None:
    """SIGTERM this process when the loop's process dies (Linux prctl): a
    backup to the end-of-file on its channels."""
    import ctypes
    import ctypes.util
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        libc.prctl(1, signal.SIGTERM)        # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _write_state(driver, state_fd: int, record: np.ndarray, layout: StateLayout,
                 reading, fault: bool) -> None:
    record[FLAGS] = 1.0 if fault else 0.0
    # a reading's own stamp: the time it describes (the drives' feedback delay)
    record[STAMP] = driver.sim_time() if reading is None else reading.stamp
    if reading is not None:
        record[layout.positions()] = reading.positions
        record[layout.velocities()] = reading.velocities
        record[layout.efforts()] = reading.efforts
    truth = driver.ground_truth()
    record[layout.truth_pose()] = truth.pose
    record[layout.truth_twist()] = truth.twist
    try:
        os.write(state_fd, record.data)
    except BlockingIOError:
        pass            # the loop is not reading: it takes the newest when it does


def plant_priority(params) -> int | None:
    """The physics process's SCHED_FIFO priority for the validated
    ``params``: one below the loop's when the loop runs real-time in its own
    process; None (SCHED_OTHER) otherwise, or when the loop is at priority 1."""
    if not (params.get("loop.realtime") and params.get("loop.process", True)):
        return None
    priority = int(params["loop.priority"]) - 1
    return priority if priority >= 1 else None


def serve(sock: socket.socket, cmd_fd: int, state_fd: int) -> int:
    """Build the SimDriver from the set-up message, answer ``ready``, then
    step it on the wall clock until the loop goes. Returns the exit code
    (0: the loop closed the channels; 2: the driver did not configure)."""
    from holonomic_core.config import build_model
    from holonomic_core.driver import DriverError
    from holonomic_core.realtime import set_fifo, set_normal

    setup = receive(sock)
    if setup is None:               # the loop went before sending the set-up
        return 0
    flat, params, rate = setup
    params["sim.physics_process"] = False
    priority = plant_priority(params)
    # started by the loop process, which asked for its scheduling before
    # building its drivers: a real-time policy is inherited and replaced here
    if priority is None:
        set_normal()
    refused = None if priority is None else set_fifo(priority)
    scheduling = ("SCHED_OTHER" if priority is None else f"SCHED_FIFO {priority}"
                  if refused is None else f"SCHED_OTHER ({refused})")
    model = build_model(flat)[0]
    driver = SimDriver(model, params, rate)
    try:
        driver.configure()
    except ConfigError as exc:      # the loop raises the same (bad sim.* values)
        send(sock, ("config_error", (exc.key, exc.value, exc.allowed)))
        return 2
    except DriverError as exc:
        send(sock, ("error", str(exc)))
        return 2
    send(sock, ("ready", {"hidden_truth": driver.hidden_truth,
                          "wheel_radii": driver.wheel_radii,
                          "friction": driver.friction, "scheduling": scheduling}))
    layout = StateLayout(len(model.joint_names))
    record = np.zeros(layout.size)
    width = 8 * (1 + layout.joints)
    period = 1.0 / rate
    last_fault = None
    fault = False
    reading = driver.read()
    _write_state(driver, state_fd, record, layout, reading, False)
    stepped_to = time.monotonic()
    sock.setblocking(False)
    try:
        while True:
            try:                           # requests; end-of-file: the loop is gone
                message = receive(sock)
                if message is None:
                    return 0
                if message[0] == "contacts":
                    send(sock, ("contacts", driver.wheel_contacts()))
            except BlockingIOError:
                pass
            data = read_newest(cmd_fd, width)
            if data == b"":
                return 0
            if data is not None:
                command = np.frombuffer(data, dtype=np.float64)
                if command[0] == HOLD:
                    driver.deactivate()
                else:
                    if not driver.armed:
                        driver.activate()
                    if command[0] == VELOCITY:
                        driver.write_velocities(command[1:])
                    else:
                        driver.write_efforts(command[1:])
            periods = int((time.monotonic() - stepped_to) / period)
            if periods > MAX_CATCH_UP:
                stepped_to += (periods - MAX_CATCH_UP) * period      # time lost
                record[LOST] += periods - MAX_CATCH_UP
                periods = MAX_CATCH_UP
            for _ in range(periods):
                try:
                    reading = driver.read()
                    fault = False
                except DriverError as exc:          # e.g. tipped over: the world steps on
                    fault = True
                    if str(exc) != last_fault:
                        last_fault = str(exc)
                        send(sock, ("fault", last_fault))
            if periods:
                stepped_to += periods * period
                _write_state(driver, state_fd, record, layout, reading, fault)
            delay = stepped_to + period - time.monotonic()
            if delay > 0.0:
                time.sleep(delay)
    finally:
        driver.close()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parent = os.getppid()
    # a terminal's SIGINT is the node's to handle: it stops the loop, which
    # closes this process's channels
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    _die_with_parent()
    if os.getppid() != parent:       # the loop died before prctl
        return 0
    try:
        # whatever the spawning thread had; serve() decides (plant_priority)
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (AttributeError, OSError):
        pass
    sock = socket.socket(fileno=int(argv[0]))
    cmd_fd, state_fd = int(argv[1]), int(argv[2])
    os.set_blocking(cmd_fd, False)
    os.set_blocking(state_fd, False)
    return serve(sock, cmd_fd, state_fd)


if __name__ == "__main__":
    sys.exit(main())
