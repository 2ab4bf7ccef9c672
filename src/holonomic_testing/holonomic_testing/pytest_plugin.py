"""Test-session set-up: a private ROS domain, localhost-only discovery, and
fixtures to run the real stack (holonomic-bringup subprocesses) against an
in-process probe node.

The shared fixtures of every package's tests, in one place: a pytest plugin
registered through the ``pytest11`` entry point (setup.py), so that
``make test`` over all packages and ``colcon test --packages-select <pkg>``
load the same set-up.

``hot_path_mode``: the domain tests of the cycle's closed forms (kinematics,
odometry, limits, the reading monitor, the controller core) run twice, once
on each implementation (``[pure]``, ``[compiled]``): a module applies it
with ``pytestmark = pytest.mark.usefixtures("hot_path_mode")``.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

from holonomic_testing.ros_probe import Bringup, claim_domain_id, spin_in_thread


def pytest_configure(config):
    # Before anything imports rclpy; subprocesses inherit these.
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ["ROS_DOMAIN_ID"] = str(claim_domain_id())
    os.environ.setdefault("ROS_LOG_DIR",
                          str(Path(tempfile.gettempdir()) / "holonomic_test_ros_log"))


#: the paths hot_path_mode runs (HOLONOMIC_TEST_HOT_PATHS, comma-separated;
#: default both): scripts/mutation.py runs the pure one for a mutant of the
#: Python code, the compiled one for a mutant of the C code
TEST_HOT_PATHS = tuple(p.strip() for p in os.environ.get(
    "HOLONOMIC_TEST_HOT_PATHS", "pure,compiled").split(",") if p.strip())
if not TEST_HOT_PATHS or set(TEST_HOT_PATHS) - {"pure", "compiled"}:
    raise pytest.UsageError(
        f"HOLONOMIC_TEST_HOT_PATHS={os.environ.get('HOLONOMIC_TEST_HOT_PATHS')!r}: "
        "one or both of pure, compiled (comma-separated)")


@pytest.fixture(params=TEST_HOT_PATHS)
def hot_path_mode(request, monkeypatch):
    """Run the test with HOLONOMIC_HOT_PATH set to "pure", then to "compiled".

    The selection is read when a cycle object (a limiter, kinematics,
    odometry, a reading monitor, a controller) is built
    (holonomic_core.hot_path), so every object the test builds takes this
    path; objects built at import time do not, so such a module builds its
    objects in the tests. "compiled" fails (ImportError) where the extension
    is not built: run ``make setup``."""
    from holonomic_core import hot_path

    monkeypatch.setenv(hot_path.ENV, request.param)
    assert hot_path.name() == request.param
    return request.param


@pytest.fixture(scope="session")
def ros():
    """rclpy initialised once for the session, with a probe node spun in a thread."""
    import rclpy

    rclpy.init()
    node = rclpy.create_node("holonomic_test_probe")
    stop = spin_in_thread(node)
    yield node
    stop()
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
