"""The node's side of the control loop process (:mod:`loop_host`): start it,
hand it commands and requests, receive its state records and status, and
watch it -- a loop that ends or stops cycling is reported, and a hung one
is killed so that the drives' own watchdogs stop the motors.

One :class:`LoopClient` runs one host (one robot, or a whole fleet in one
simulated world); each robot has a :class:`RobotLink`. The client's reader
thread calls the link's ``on_record(StateRecord)``, ``on_status(status,
loop)`` and ``on_lost(reason)`` handlers.
"""

from __future__ import annotations

import concurrent.futures
import fcntl
import itertools
import os
import selectors
import signal
import socket
import subprocess
import sys
import threading
import time
from typing import Callable

import numpy as np

from holonomic_bringup import loop_wire as wire
from holonomic_bringup.loop_host import HostSetup, RobotSetup, run_host
from holonomic_core.schema import ConfigError

#: how long the host may take to build its robots (pybullet, CAN drives) [s]
START_TIMEOUT = 60.0
#: how long a stopping host may take to stop and close its drivers [s]
STOP_TIMEOUT = 10.0
_PIPE_SIZE = 1 << 20     # [bytes] ~1 s of 1 kHz state records of an XR4000


class LoopLost(RuntimeError):
    """The control loop is not running (it ended, or was killed when hung)."""


class RobotLink:
    """One robot's channels, node side."""

    def __init__(self, client: "LoopClient", index: int, layout: wire.RecordLayout):
        self.client = client
        self.index = index
        self.layout = layout
        self.command_fd = -1           # node writes
        self.state_fd = -1             # node reads
        self.info: dict = {}
        self.on_record: Callable[[wire.StateRecord], None] = lambda record: None
        self.on_status: Callable[[object, dict], None] = lambda status, loop: None
        self.on_lost: Callable[[str], None] = lambda reason: None
        #: log lines from the loop before a handler is set (real-time refused, ...)
        self.early_logs: list[tuple[str, str]] = []
        self.on_log: Callable[[str, str], None] = lambda level, text: self.early_logs.append(
            (level, text))
        self._buffer = b""

    def send_command(self, twist, received: float) -> None:
        """The latest command (vx, vy, wz) [m/s, m/s, rad/s] in base_link,
        received at ``received`` [s, time.monotonic()]; never blocks."""
        try:
            os.write(self.command_fd, wire.COMMAND.pack(twist[0], twist[1], twist[2], received))
        except (BlockingIOError, BrokenPipeError, OSError):
            pass   # the loop is not reading (gone or hung): the watchdog reports it

    def request_enable(self, enable: bool) -> concurrent.futures.Future:
        """Arm/disarm; the future resolves to (success, message)."""
        return self.client.request(("enable", self.index, bool(enable)))

    def request_reset_odometry(self) -> concurrent.futures.Future:
        return self.client.request(("reset_odometry", self.index))

    def request_unwind(self) -> concurrent.futures.Future:
        """Start the unwind maneuver; resolves to (success, plan or why not)."""
        return self.client.request(("unwind", self.index))
    def request_estop(self, pressed: bool, source: str, received: float) -> None:
        """One emergency_stop message (received at ``received`` [s,
        time.monotonic()], the loop's clock: the heartbeat is timed there)."""
        self.client.request(("estop", self.index, bool(pressed), str(source), float(received)))

    def request_set_pose(self, pose, covariance) -> concurrent.futures.Future:
        """Set the odometry pose (x, y, yaw) and its 9-value covariance."""
        return self.client.request(("set_pose", self.index, tuple(pose), tuple(covariance)))

    def read_records(self) -> bool:
        """Read what the state pipe holds; ``on_record`` each whole record
        (the client's reader thread) until :meth:`LoopClient.stop` is
        called. False at the pipe's end (the loop is gone)."""
        try:
            data = os.read(self.state_fd, _PIPE_SIZE)
        except BlockingIOError:
            return True
        if not data:
            return False
        data = self._buffer + data
        size = self.layout.nbytes
        whole = len(data) // size * size
        self._buffer = data[whole:]
        if whole:
            block = np.frombuffer(data[:whole], dtype=np.float64).reshape(-1, self.layout.size)
            for row in block:
                if self.client.stopping:
                    # the node is tearing down its publishers: the loop's
                    # backlog (up to a second of records when the machine
                    # is loaded) is not published into them
                    break
                self.on_record(wire.StateRecord(row, self.layout))
        return True


def loop_environment() -> dict[str, str]:
    """The loop process's environment: this one's, with numpy's OpenBLAS
    single-threaded unless the user chose otherwise. OpenBLAS starts a pool of
    worker threads when numpy is imported, on the normal scheduler; a
    real-time loop that handed them a matrix product large enough to split
    would wait for threads any other process can preempt (a priority
    inversion). The cycle's matrices are small: one thread does them. The
    simulator's physics process inherits this environment."""
    env = dict(os.environ)
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    return env


class LoopClient:
    """Runs a control loop host for ``setups`` (flat configs) in a process
    of its own (``process``) or a thread; see the module docstring."""

    def __init__(self, setups: list[tuple[dict, str, object]], process: bool = True,
                 shared_world: bool = False, watchdog_timeout: float = 2.0):
        """``setups``: per robot ``(flat, source, model)``, the model for
        the record layout."""
        self.process = process
        self.watchdog_timeout = watchdog_timeout
        self.links = [RobotLink(self, k, wire.RecordLayout.for_model(model))
                      for k, (_, _, model) in enumerate(setups)]
        self._setups = setups
        self._shared_world = shared_world
        self._ids = itertools.count(1)
        self._pending: dict[int, concurrent.futures.Future] = {}
        self._pending_lock = threading.Lock()
        self._lost: str | None = None
        self._stopping = False
        self._exit_code: int | None = None
        self._proc: subprocess.Popen | None = None
        self._thread: threading.Thread | None = None
        self._reader: threading.Thread | None = None
        self._sock: socket.socket | None = None
        self._host_fds: list[int] = []
        self._heartbeat = None

    # -- start ------------------------------------------------------------------------
    def start(self) -> None:
        """Start the host and wait until its robots are built. Raises
        ConfigError when it cannot build them (a driver that does not
        configure), LoopLost when it ends on the way."""
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        for sock in (ours, theirs):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, wire.MAX_MESSAGE)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, wire.MAX_MESSAGE)
        self._sock = ours
        robots = []
        for link, (flat, source, _) in zip(self.links, self._setups):
            cmd_r, cmd_w = os.pipe()
            state_r, state_w = os.pipe()
            for fd in (cmd_r, state_w):
                try:
                    fcntl.fcntl(fd, fcntl.F_SETPIPE_SZ, _PIPE_SIZE)
                except OSError:
                    pass   # the system's pipe-max-size: the default 64 KiB works, drops sooner
            os.set_blocking(cmd_w, False)
            link.command_fd, link.state_fd = cmd_w, state_r
            robots.append(RobotSetup(flat, source, cmd_r, state_w))
            self._host_fds += [cmd_r, state_w]
        setup = HostSetup(robots, shared_world=self._shared_world, in_process=not self.process)
        beat_fd = os.memfd_create("holonomic_loop_heartbeat")
        os.ftruncate(beat_fd, wire.HEARTBEAT_SIZE)
        import mmap
        self._heartbeat = mmap.mmap(beat_fd, wire.HEARTBEAT_SIZE)
        self._beat = np.frombuffer(self._heartbeat, dtype=np.int64, count=1)
        if self.process:
            fds = [theirs.fileno(), beat_fd, *self._host_fds]
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "holonomic_bringup.loop_host",
                 str(theirs.fileno()), str(beat_fd)],
                pass_fds=fds, start_new_session=True, env=loop_environment())
            wire.send(ours, setup)         # read by the host at start
            theirs.close()
            for fd in self._host_fds:
                os.close(fd)
            os.close(beat_fd)
        else:
            for r in setup.robots:
                os.set_blocking(r.command_fd, False)
                os.set_blocking(r.state_fd, False)
            view = memoryview(self._heartbeat)

            def host():
                try:
                    self._exit_code = run_host(setup, theirs, view)
                finally:
                    theirs.close()
            self._thread = threading.Thread(target=host, name="control_loop_host", daemon=True)
            self._thread.start()
            os.close(beat_fd)
        self._await_ready()
        for link in self.links:
            os.set_blocking(link.state_fd, False)
        self._reader = threading.Thread(target=self._read, name="control_loop_reader",
                                        daemon=True)
        self._reader.start()

    def _await_ready(self) -> None:
        deadline = time.monotonic() + START_TIMEOUT
        while True:
            if self._poll(0.1):
                message = wire.receive(self._sock)
                if message is None:
                    raise LoopLost(f"the control loop ended while starting{self._exit_text()}")
                if message[0] == "ready":
                    for link, info in zip(self.links, message[1]):
                        link.info = info
                    return
                if message[0] == "error":
                    self._wait_host(STOP_TIMEOUT)
                    key, value, allowed, text = message[1]
                    raise ConfigError(key, value, allowed, text)
                continue
            if not self._host_alive():
                raise LoopLost(f"the control loop ended while starting{self._exit_text()}")
            if time.monotonic() > deadline:
                self._kill()
                raise LoopLost(f"the control loop did not start within {START_TIMEOUT:g} s")

    def _poll(self, timeout: float) -> bool:
        with selectors.DefaultSelector() as sel:
            sel.register(self._sock, selectors.EVENT_READ)
            return bool(sel.select(timeout))

    # -- requests ---------------------------------------------------------------------
    def request(self, message: tuple) -> concurrent.futures.Future:
        future: concurrent.futures.Future = concurrent.futures.Future()
        if self._lost is not None:
            future.set_result((False, f"the control loop is not running ({self._lost})"))
            return future
        rid = next(self._ids)
        with self._pending_lock:
            self._pending[rid] = future
        if not wire.send(self._sock, (*message, rid)):
            with self._pending_lock:
                self._pending.pop(rid, None)
            future.set_result((False, "the control loop does not take requests"))
        return future

    @property
    def stopping(self) -> bool:
        """:meth:`stop` was called: records are no longer delivered."""
        return self._stopping

    @property
    def lost(self) -> str | None:
        """Why the loop is not running (None while it runs)."""
        return self._lost

    # -- the reader thread ---------------------------------------------------------------
    def _read(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self._sock, selectors.EVENT_READ, None)
        for link in self.links:
            sel.register(link.state_fd, selectors.EVENT_READ, link)
        last_beat, last_change = int(self._beat[0]), time.monotonic()
        next_lost_report = 0.0
        while True:
            events = sel.select(0.05)
            for key, _ in events:
                if key.data is not None:
                    if not key.data.read_records():
                        sel.unregister(key.fd)      # its end closed: no busy select
                elif not self._on_control():
                    if self._stopping:
                        sel.close()
                        return
                    # its socket closes while the process is still exiting:
                    # wait for the exit status to say how it ended
                    self._wait_host(1.0)
                    self._declare_lost(f"the control loop ended{self._exit_text()}")
                    sel.unregister(self._sock)
            now = time.monotonic()
            beat = int(self._beat[0])
            if beat != last_beat:
                last_beat, last_change = beat, now
            elif (self._lost is None and not self._stopping
                  and now - last_change > self.watchdog_timeout):
                self._kill()
                self._declare_lost(f"the control loop hung (no cycle for "
                                   f"{now - last_change:.2f} s)"
                                   + (": killed" if self.process else ""))
            if self._lost is not None and now >= next_lost_report:
                if self._stopping:
                    sel.close()
                    return
                next_lost_report = now + 1.0
                for link in self.links:
                    link.on_lost(self._lost)

    def _on_control(self) -> bool:
        message = wire.receive(self._sock)
        if message is None:
            return False
        kind = message[0]
        if kind == "reply":
            with self._pending_lock:
                future = self._pending.pop(message[1], None)
            if future is not None:
                future.set_result(message[2])
        elif kind == "status":
            self.links[message[1]].on_status(message[2], message[3])
        elif kind == "log":
            self.links[message[1]].on_log(message[2], message[3])
        elif kind == "stopped":
            self._exit_code = message[1]
        return True

    def _declare_lost(self, reason: str) -> None:
        if self._lost is not None:
            return
        self._lost = reason
        with self._pending_lock:
            pending, self._pending = self._pending, {}
        for future in pending.values():
            future.set_result((False, f"the control loop is not running ({reason})"))

    # -- liveness -------------------------------------------------------------------------
    def _host_alive(self) -> bool:
        if self._proc is not None:
            return self._proc.poll() is None
        return self._thread is not None and self._thread.is_alive()

    def _exit_text(self) -> str:
        if self._proc is not None and self._proc.poll() is not None:
            code = self._proc.returncode
            if code < 0:
                return f" (killed by {signal.Signals(-code).name})"
            return f" (exit code {code})"
        return ""

    def _kill(self) -> None:
        if self._proc is not None and self._proc.poll() is None:
            self._proc.kill()

    def _wait_host(self, timeout: float) -> bool:
        if self._proc is not None:
            try:
                self._proc.wait(timeout)
            except subprocess.TimeoutExpired:
                return False
            return True
        if self._thread is not None:
            self._thread.join(timeout)
            return not self._thread.is_alive()
        return True

    @property
    def pid(self) -> int | None:
        """The loop process's id (None: a thread of this process)."""
        return None if self._proc is None else self._proc.pid

    def stop(self) -> bool:
        """Stop the loop: the host stops and disarms the motors and closes
        the drivers. Returns True when it did so within STOP_TIMEOUT (else
        the process is killed: the drives' watchdogs stop the motors)."""
        self._stopping = True
        clean = True
        if self._sock is not None:
            wire.send(self._sock, ("stop",))
            clean = self._wait_host(STOP_TIMEOUT)
            if not clean:
                self._kill()
                self._wait_host(STOP_TIMEOUT)
        if self._reader is not None:
            self._reader.join(2.0)
        if self._sock is not None:
            self._sock.close()
        for link in self.links:
            for fd in (link.command_fd, link.state_fd):
                if fd >= 0:
                    os.close(fd)
            link.command_fd = link.state_fd = -1
        if self._thread is not None:
            for fd in self._host_fds:
                try:
                    os.close(fd)
                except OSError:
                    pass
        return clean and self._lost is None
