"""The simulator's physics in a process of its own (``sim.physics_process``).

On a real robot the plant is not in the control loop's process: the loop
writes setpoints to the drives and reads their latest feedback, and a slow
loop delays neither the motors nor the floor. With the physics stepped
inside :meth:`SimDriver.read <holonomic_sim.sim_driver.SimDriver.read>`
(the default), a pybullet step with the drive model runs inside the loop's
cycle (XR4000 at 1 kHz: 23-27 % of a core, docs/realtime.md) and a late
step makes a late cycle. Here it runs apart:

* the **physics process** (``python -m holonomic_sim.physics_plant``,
  :func:`holonomic_sim.physics_plant.serve`) owns an ordinary in-process :class:`SimDriver` (its own
  pybullet world, the drive model, the spreads, the encoder zeros, the
  tip-over check) and steps it on the wall clock, one control period of
  physics every control period: it applies the latest command, advances
  ``physics_rate / control_rate`` physics steps, then writes the state;
  after a late wake-up it catches up at most :data:`MAX_CATCH_UP` periods
  and skips the rest (sim time then falls behind the wall clock rather than
  jumping);
* the **loop's** :class:`PhysicsLink` (inside the loop's SimDriver) writes
  commands and takes the latest state without ever waiting for the physics:
  a late or slow physics step delays the plant, not the loop.

Channels (the reasoning of :mod:`holonomic_bringup.loop_wire`: a pipe write
is one system call, a full memory barrier on every CPU, atomic under
PIPE_BUF; no seqlock'd shared memory, which needs explicit barriers on ARM):

* commands, loop -> physics: a pipe of fixed records ``(mode, value_1..n)``
  (:data:`HOLD`, :data:`VELOCITY` [rad/s], :data:`EFFORT` [N m]); the
  physics drains it at the start of each period and the latest record wins
  (each record is the whole command, so none is lost by skipping older ones);
* state, physics -> loop: a pipe of fixed records (:class:`StateLayout`:
  sim time, joint positions / velocities / efforts as the drives report
  them, ground truth, a fault flag); the loop drains it each cycle and keeps
  the last, and re-uses it when none is new (the reading's stamp then does
  not advance: the controller's reading monitor tolerates that up to
  ``safety.reading_timeout``);
* control, both ways: a ``SOCK_SEQPACKET`` socket of pickled messages
  (:mod:`holonomic_core.control_socket`, as between the node and the loop: the
  set-up, ``ready`` with what configure learnt, fault texts, wheel-contact
  requests and replies).

Lifetime: the physics process exits when either channel from the loop
reaches end-of-file, i.e. when the loop closes the driver or its process
dies (the kernel closes a dead process's descriptors), and on SIGTERM; a
Linux parent-death signal backs that up. When the physics process dies, the
loop's next read raises :class:`~holonomic_core.driver.DriverCommunicationError`
naming it and its exit status: the controller faults and disarms (there are
no motors left to move).

Scheduling (:func:`holonomic_sim.physics_plant.plant_priority`): when the loop runs real-time (its own
process, ``loop.realtime``), the physics process asks for SCHED_FIFO one
step below the loop (``loop.priority - 1``), otherwise it stays SCHED_OTHER
like the loop. Below: it never preempts the loop. Real-time at all: a plant
starved by the ROS node, DDS or other load stops the readings, and the
controller faults after ``safety.reading_timeout`` (50 ms) as it would on a
silent drive -- which a plant at SCHED_OTHER on a loaded machine does. It
costs 13-27 % of a core (XR4000, 1 kHz), so the node and DDS keep
the rest and the real-time budget (95 % of each second) is far off.
"""

from __future__ import annotations

import os
import select
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass

import numpy as np

from holonomic_core.control_socket import receive, send
from holonomic_core.driver import DriverCommunicationError, GroundTruth, JointReading
from holonomic_core.schema import ConfigError

#: command modes: brakes on (disarmed), joint speeds [rad/s], joint torques [N m]
HOLD, VELOCITY, EFFORT = 0.0, 1.0, 2.0
#: control periods the physics catches up after a late wake-up; beyond, the
#: time is lost (sim time falls behind the wall clock)
MAX_CATCH_UP = 20
#: how long [s] the loop waits for the physics process to build its world,
#: to answer a wheel-contact request, and to exit once told to
START_TIMEOUT = 60.0
REQUEST_TIMEOUT = 1.0
STOP_TIMEOUT = 5.0
#: the device name in driver errors
DEVICE = "physics process"


@dataclass(frozen=True)
class StateLayout:
    """Offsets in one state record (float64) for ``joints`` joints: flags
    (1: the physics' read failed, the text is on the control socket), sim
    time [s], periods lost so far, positions [rad], velocities [rad/s],
    efforts [N m], ground-truth pose (x, y, yaw) [m, m, rad] in odom and
    twist (vx, vy, wz) in base_link [m/s, m/s, rad/s]."""

    joints: int

    @property
    def size(self) -> int:
        return 3 + 3 * self.joints + 6

    def positions(self) -> slice:
        return slice(3, 3 + self.joints)

    def velocities(self) -> slice:
        return slice(3 + self.joints, 3 + 2 * self.joints)

    def efforts(self) -> slice:
        return slice(3 + 2 * self.joints, 3 + 3 * self.joints)

    def truth_pose(self) -> slice:
        return slice(3 + 3 * self.joints, 6 + 3 * self.joints)

    def truth_twist(self) -> slice:
        return slice(6 + 3 * self.joints, 9 + 3 * self.joints)


#: the record's first three slots: flags, sim time [s], periods lost
FLAGS, STAMP, LOST = 0, 1, 2


def read_newest(fd: int, size: int) -> bytes | None:
    """The newest ``size``-byte record waiting in non-blocking pipe ``fd``
    (every one before it is read and dropped: the latest wins); None when
    none is waiting, b"" at end-of-file. Each record was one write under
    PIPE_BUF (atomic), so reads of a multiple of ``size`` return whole
    records."""
    newest = None
    while True:
        try:
            data = os.read(fd, 64 * size)
        except BlockingIOError:
            return newest
        if not data:
            return newest if newest is not None else b""
        newest = data[-size:]


class PhysicsLink:
    """The loop's end: starts the physics process for a SimDriver's
    ``model`` (the simulated body's nominal description, its ``body``) and
    validated ``params`` (``sim.physics_process`` set false
    for the inner driver) at ``control_rate`` [Hz], then carries commands
    and the latest state. It is the SimDriver's plant
    (:class:`holonomic_sim.sim_driver.Plant`), as the in-process world is.
    Not thread-safe: the loop's thread only (as the driver)."""

    def __init__(self, model, params, control_rate: float):
        self.layout = StateLayout(len(model.joint_names))
        self._record = np.zeros(self.layout.size)
        self._command_record = np.zeros(1 + len(model.joint_names))
        self._fault_text = "the simulated base failed"
        self._sock, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        cmd_r, self._cmd_w = os.pipe()
        self._state_r, state_w = os.pipe()
        try:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "holonomic_sim.physics_plant",
                 str(theirs.fileno()), str(cmd_r), str(state_w)],
                pass_fds=(theirs.fileno(), cmd_r, state_w))
        finally:
            theirs.close()
            os.close(cmd_r)
            os.close(state_w)
        os.set_blocking(self._cmd_w, False)
        os.set_blocking(self._state_r, False)
        # the model as its flat keys (it holds modules: not picklable); the
        # physics process builds it again, as SimDriver does for its body
        send(self._sock, (dict(model.params), dict(params), float(control_rate)))
        #: what the physics' driver learnt configuring (hidden_truth, friction, ...)
        self.info = self._await_ready()

    @property
    def pid(self) -> int:
        return self.proc.pid

    def _await_ready(self) -> dict:
        deadline = time.monotonic() + START_TIMEOUT
        message = self._receive(deadline)
        if message is not None and message[0] == "config_error":
            self.close()
            raise ConfigError(*message[1])
        if message is None or message[0] != "ready":
            text = message[1] if message is not None and message[0] == "error" else (
                f"did not start{self._exit_text(STOP_TIMEOUT)}")
            self.close()
            raise DriverCommunicationError(text, DEVICE)
        # the first state: written right after "ready"
        while not self._drain():
            if not select.select([self._state_r], [], [], max(0.0, deadline - time.monotonic()))[0]:
                self.close()
                raise DriverCommunicationError("sent no state", DEVICE)
        return message[1]

    def _receive(self, deadline: float):
        """The next control message (None at end-of-file or the deadline);
        fault texts are kept, not returned."""
        while True:
            left = deadline - time.monotonic()
            if left <= 0.0 or not select.select([self._sock], [], [], left)[0]:
                return None
            message = receive(self._sock)
            if message is None:
                return None
            if message[0] == "fault":
                self._fault_text = message[1]
            else:
                return message

    def _exit_text(self, wait: float) -> str:
        try:
            code = self.proc.wait(wait)
        except subprocess.TimeoutExpired:
            return ""
        if code < 0:
            return f" (pid {self.proc.pid} killed by {signal.Signals(-code).name})"
        return f" (pid {self.proc.pid} exited with code {code})"

    def _drain(self) -> bool:
        """Take the newest state record; False when none was waiting.
        Raises DriverCommunicationError when the physics process is gone."""
        data = read_newest(self._state_r, self._record.nbytes)
        if data is None:
            return False
        if not data:
            raise DriverCommunicationError(
                f"the simulator's physics process ended{self._exit_text(0.2)}", DEVICE)
        self._record[:] = np.frombuffer(data, dtype=np.float64)
        return True

    def read(self) -> JointReading:
        """The newest state as a reading (stamp: sim time [s]); the last one
        again when the physics has not stepped since. The physics process
        applied the encoders' zero errors and the tip-over check."""
        self._drain()
        r, lay = self._record, self.layout
        if r[FLAGS]:
            while True:          # the fault text was sent before the record
                try:
                    message = receive(self._sock, wait=False)
                except BlockingIOError:
                    break
                if message is None:
                    break
                if message[0] == "fault":
                    self._fault_text = message[1]
            raise DriverCommunicationError(self._fault_text, "pybullet")
        # the reading's stamp: the sim time [s] of the newest state
        return JointReading(float(r[STAMP]), r[lay.positions()].copy(),
                            r[lay.velocities()].copy(), r[lay.efforts()].copy())

    @property
    def sim_time(self) -> float:
        """Sim time [s] of the newest state read."""
        return float(self._record[STAMP])

    @property
    def lost_periods(self) -> int:
        """Control periods the physics skipped so far (it could not keep up)."""
        return int(self._record[LOST])

    def ground_truth(self) -> GroundTruth:
        """Ground truth at the newest state read (the same instant as the
        reading, as in the in-process world)."""
        r, lay = self._record, self.layout
        return GroundTruth(float(r[STAMP]), r[lay.truth_pose()].copy(),
                           r[lay.truth_twist()].copy())

    def release(self) -> None:
        """Brakes released, every joint commanded to rest (activate)."""
        self._command(VELOCITY)

    def hold(self) -> None:
        """Brakes on: the joints held still (deactivate)."""
        self._command(HOLD)

    def command_velocities(self, velocities: np.ndarray) -> None:
        """Joint speeds [rad/s], one per joint."""
        self._command(VELOCITY, velocities)

    def command_efforts(self, efforts: np.ndarray) -> None:
        """Joint torques [N m], one per joint."""
        self._command(EFFORT, efforts)

    def status(self) -> dict[str, str]:
        """The physics process's line of the driver's status."""
        return {"physics_process": f"pid {self.pid}, {self.info['scheduling']}, "
                                   f"{self.lost_periods} periods lost"}

    def _command(self, mode: float, values=None) -> None:
        """Send a command: HOLD, or VELOCITY / EFFORT with one value per
        joint. A full pipe (the physics stalled) drops it: the next one
        carries the whole command again. A dead physics process is reported
        by the next read, not here (deactivate must not fail)."""
        c = self._command_record
        c[0] = mode
        c[1:] = 0.0 if values is None else values
        try:
            os.write(self._cmd_w, c.data)
        except (BlockingIOError, BrokenPipeError):
            pass

    def wheel_contacts(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The physics' wheel contacts (see SimDriver.wheel_contacts); a round
        trip of up to one control period, not for the cycle; None when the
        physics does not answer within REQUEST_TIMEOUT."""
        if not send(self._sock, ("contacts",)):
            return None
        message = self._receive(time.monotonic() + REQUEST_TIMEOUT)
        return message[1] if message is not None and message[0] == "contacts" else None

    def close(self) -> None:
        """End the physics process (end-of-file on both its inputs), wait for
        it, kill it if it does not go."""
        for close in (self._sock.close, lambda: os.close(self._cmd_w)):
            try:
                close()
            except OSError:
                pass
        try:
            self.proc.wait(STOP_TIMEOUT)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        try:
            os.close(self._state_r)
        except OSError:
            pass
