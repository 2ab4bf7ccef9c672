"""Process-level safety of a running base: shutdown signals caught from the
first moment, and one base controller per namespace and ROS domain.

* :func:`install_signal_handlers` turns SIGINT/SIGTERM into :data:`STOP`,
  from the first line of ``main`` on -- before rclpy, the robot config or the
  driver exist -- so that a signal at any moment ends in the normal shutdown
  path (stop and disarm the motors, exit 0) instead of a KeyboardInterrupt
  somewhere in the middle of configuring a motor drive.
* :class:`InstanceLock` refuses a second base controller for the same node
  name, namespace and ROS_DOMAIN_ID on this machine: two controllers would
  both command the same motors (on real hardware, the same CAN bus). It is an
  advisory ``flock`` on a file named after them, released by the kernel when
  the process ends, however it ends (no stale lock after a crash).
"""

from __future__ import annotations

import fcntl
import os
import re
import signal
import tempfile
import threading
from pathlib import Path

#: set by SIGINT/SIGTERM once :func:`install_signal_handlers` has run
STOP = threading.Event()


def _on_signal(signum, frame) -> None:  # noqa: ARG001 (signal handler signature)
    STOP.set()


def install_signal_handlers() -> None:
    """Route SIGINT and SIGTERM to :data:`STOP` (idempotent)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _on_signal)


class InstanceConflict(RuntimeError):
    """Another process already runs this base controller."""


class InstanceLock:
    """Exclusive lock on (fully qualified node name, ROS domain) on this host.

    ``directory``: where the lock files live (default: $XDG_RUNTIME_DIR or the
    temp dir). Raises :class:`InstanceConflict` naming the other PID.
    """

    def __init__(self, node_name: str, domain_id: str | None = None,
                 directory: str | os.PathLike | None = None):
        domain = domain_id if domain_id is not None else os.environ.get("ROS_DOMAIN_ID", "0")
        domain = domain.strip() or "0"
        folder = Path(directory or os.environ.get("XDG_RUNTIME_DIR") or tempfile.gettempdir())
        safe = re.sub(r"[^A-Za-z0-9_]+", "_", node_name).strip("_") or "root"
        self.path = folder / f"holonomic_{safe}_domain{domain}.lock"
        self.description = f"{node_name} in ROS domain {domain}"
        self._handle = open(self.path, "a+")
        try:
            fcntl.flock(self._handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._handle.seek(0)
            other = self._handle.read().strip() or "unknown"
            self._handle.close()
            raise InstanceConflict(
                f"another base controller is already running as {self.description} "
                f"(pid {other}, lock {self.path}); two controllers would command the same "
                "motors. Stop it, or use another --namespace or ROS_DOMAIN_ID.") from None
        self._handle.seek(0)
        self._handle.truncate()
        self._handle.write(str(os.getpid()))
        self._handle.flush()

    def release(self) -> None:
        if not self._handle.closed:
            fcntl.flock(self._handle, fcntl.LOCK_UN)
            self._handle.close()
