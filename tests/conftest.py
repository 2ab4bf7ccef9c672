"""Test-session set-up: a private ROS domain, localhost-only discovery, and
fixtures to run the real stack (holonomic-bringup subprocesses) against an
in-process probe node."""

from __future__ import annotations

import os
import tempfile
import threading
from pathlib import Path

import pytest

from ros_probe import Bringup, claim_domain_id


def pytest_configure(config):
    # Before anything imports rclpy; subprocesses inherit these.
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ["ROS_DOMAIN_ID"] = str(claim_domain_id())
    os.environ.setdefault("ROS_LOG_DIR", str(Path(tempfile.gettempdir()) / "holonomic_test_ros_log"))


@pytest.fixture(scope="session")
def ros():
    """rclpy initialised once for the session, with a probe node spun in a thread."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    rclpy.init()
    node = rclpy.create_node("holonomic_test_probe")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    stop = threading.Event()

    def spin():
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.05)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    yield node
    stop.set()
    thread.join(2.0)
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()


@pytest.fixture
def start_bringup(tmp_path):
    """Factory: start holonomic-bringup with arguments; stopped at teardown."""
    started: list[Bringup] = []

    def start(*args: str) -> Bringup:
        proc = Bringup(list(args), tmp_path / f"bringup_{len(started)}.log")
        started.append(proc)
        return proc

    yield start
    for proc in started:
        proc.stop()
