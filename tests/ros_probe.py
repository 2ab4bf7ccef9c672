"""Test helpers for the real stack: a holonomic-bringup subprocess handle,
and the product's RobotClient (as ``Probe``) for talking to it."""

from __future__ import annotations

import math
import shutil
import signal
import subprocess
import time
from pathlib import Path

import numpy as np

from holonomic_bringup.robot_client import RobotClient as Probe  # noqa: F401
from holonomic_bringup.robot_client import relative_pose, wait_until  # noqa: F401


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

    def __init__(self, args: list[str], log_path: Path):
        exe = shutil.which("holonomic-bringup")
        if exe is None:
            raise RuntimeError("holonomic-bringup is not on PATH: run the tests with `make test`")
        self.log_path = log_path
        self._log = open(log_path, "w")
        self.proc = subprocess.Popen([exe] + args, stdout=self._log, stderr=subprocess.STDOUT,
                                     start_new_session=True)

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
