"""Test helpers for the real stack: a holonomic-bringup subprocess handle,
and the product's RobotClient (as ``Probe``) for talking to it."""

from __future__ import annotations

import fcntl
import math
import os
import pty
import select
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from holonomic_bringup.robot_client import RobotClient as Probe  # noqa: F401
from holonomic_bringup.robot_client import wait_until  # noqa: F401
from holonomic_core.se2 import relative_pose  # noqa: F401


_held_domain_locks = []


def spin_in_thread(node, context=None):
    """Spin ``node`` with its own executor in a daemon thread (``context``:
    rclpy's default one if None); returns a function that stops it."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    stop = threading.Event()
    ok = rclpy.ok if context is None else context.ok

    def spin():
        while not stop.is_set() and ok():
            executor.spin_once(timeout_sec=0.05)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()

    def finish():
        stop.set()
        thread.join(2.0)
        executor.shutdown()
    return finish


def claim_domain_id() -> int:
    """A ROS_DOMAIN_ID no other test run on this machine holds (file locks,
    held until this process exits)."""
    folder = Path(tempfile.gettempdir())
    for domain in range(11, 101):
        handle = open(folder / f"holonomic_test_ros_domain_{domain}.lock", "w")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _held_domain_locks.append(handle)
        return domain
    raise RuntimeError("no free ROS_DOMAIN_ID in 11..100 for the tests")


def drive_script(probe, script) -> tuple[float, float, float]:
    """Drive ``[(twist, seconds), ...]`` and come to rest.

    Returns (true path length [m], odometry position error [m], heading
    error [rad]) of the displacement over the script.
    """
    probe.wait_at_rest()
    odom0, truth0 = probe.latest_odom().pose, probe.latest_truth().pose
    t0 = time.monotonic()
    for twist, seconds in script:
        probe.drive(twist, seconds)
    probe.wait_at_rest()
    truth = probe.truth_since(t0)
    distance = sum(np.linalg.norm(b.pose[:2] - a.pose[:2]) for a, b in zip(truth, truth[1:]))
    moved_odom = relative_pose(odom0, probe.latest_odom().pose)
    moved_truth = relative_pose(truth0, probe.latest_truth().pose)
    error = float(np.linalg.norm(moved_odom[:2] - moved_truth[:2]))
    heading = abs(math.remainder(moved_odom[2] - moved_truth[2], 2 * math.pi))
    return float(distance), error, heading


class Bringup:
    """A ``holonomic-bringup`` subprocess, ended by its PID."""

    def __init__(self, args: list[str], log_path: Path, env: dict | None = None):
        """``env``: variables to set for the process (e.g. another ROS_DOMAIN_ID)."""
        exe = shutil.which("holonomic-bringup")
        if exe is None:
            raise RuntimeError("holonomic-bringup is not on PATH: run the tests with `make test`")
        self.log_path = log_path
        self._log = open(log_path, "w")
        self.proc = subprocess.Popen([exe] + args, stdout=self._log, stderr=subprocess.STDOUT,
                                     start_new_session=True, env={**os.environ, **(env or {})})

    def log(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text()

    def stop(self, sig=signal.SIGINT, timeout: float = 15.0) -> int:
        """Signal the process (only it) and wait; kill if it hangs."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if not self._log.closed:
            self._log.close()
        return self.proc.returncode


class Teleop:
    """holonomic-teleop in a pseudo-terminal (its stdin is a real tty)."""

    def __init__(self, *args: str):
        exe = shutil.which("holonomic-teleop")
        assert exe, "holonomic-teleop is not on PATH: run the tests with `make test`"
        self.master, slave = pty.openpty()
        self.proc = subprocess.Popen([exe, *args], stdin=slave, stdout=slave, stderr=slave,
                                     start_new_session=True)
        os.close(slave)
        self.output = b""

    def press(self, keys: str) -> None:
        os.write(self.master, keys.encode())
        self.drain()

    def drain(self) -> None:
        while select.select([self.master], [], [], 0)[0]:
            try:
                self.output += os.read(self.master, 4096)
            except OSError:
                return

    def hold(self, key: str, seconds: float, every: float = 0.05) -> None:
        """Key auto-repeat: the key pressed every ``every`` s."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.press(key)
            time.sleep(every)

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.drain()
        os.close(self.master)
        return self.proc.returncode
