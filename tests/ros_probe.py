"""Test helpers for the real stack: a holonomic-bringup subprocess handle,
and the product's RobotClient (as ``Probe``) for talking to it."""

from __future__ import annotations

import shutil
import signal
import subprocess
from pathlib import Path

from holonomic_bringup.robot_client import RobotClient as Probe  # noqa: F401
from holonomic_bringup.robot_client import relative_pose, wait_until  # noqa: F401


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
