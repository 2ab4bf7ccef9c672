"""The node with the simulator's physics in its own process
(sim.physics_process): it runs and publishes, and when the physics process
dies the robot faults with one log line and an ERROR in diagnostics while
the node and its loop stay up; stopping the node ends the physics process."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticStatus

from holonomic_testing.ros_probe import Probe, wait_until


def _driver_values(probe) -> dict:
    if probe.diagnostics is None:
        return {}
    status = next((s for s in probe.diagnostics.status if s.name.endswith("driver")), None)
    if status is None:
        return {}
    return {"level": status.level, "message": status.message,
            **{kv.key: kv.value for kv in status.values}}


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(") ", 1)[1][0] != "Z"
    except FileNotFoundError:
        return False


def _physics_pid(probe) -> int:
    """The physics process's pid from the driver's diagnostics
    (``physics_process: pid 1234, SCHED_FIFO 49, 0 periods lost``); it is alive."""
    probe.wait_ready()
    values = wait_until(lambda: "physics_process" in _driver_values(probe)
                        and _driver_values(probe), 20.0, "the physics process's pid")
    pid = int(values["physics_process"].split()[1].rstrip(","))
    assert _alive(pid)
    return pid


def test_a_dead_physics_process_faults_the_robot_once_and_the_node_stays_up(
        ros, start_bringup):
    ns = "physdead"
    # a loaded machine may stall an unprivileged (SCHED_OTHER) physics
    # process past the 50 ms reading timeout: widened, so that the fault
    # is the process's death
    proc = start_bringup("xr4000", "--enable", "--namespace", ns, "-p", "cmd_timeout:=0.0",
                         "-p", "sim.physics_process:=true", "-p", "safety.reading_timeout:=2.0")
    probe = Probe(ros, ns)
    try:
        pid = _physics_pid(probe)
        probe.drive((0.3, 0.0, 0.0), 0.5)
        os.kill(pid, signal.SIGKILL)

        def reported():
            v = _driver_values(probe)
            return v.get("level") == DiagnosticStatus.ERROR and \
                "physics process ended" in v.get("message", "") and v
        try:
            values = wait_until(reported, 10.0, "an ERROR naming the physics process")
        except TimeoutError:
            raise AssertionError(f"{_driver_values(probe)}\n{proc.log()}")
        assert values["controller_state"] == "fault" and "SIGKILL" in values["message"]
        assert proc.proc.poll() is None          # the node (and its loop) stay up
        answer = probe.enable(True)              # re-arming fails: no plant to drive
        assert not answer.success
    finally:
        probe.close()
    assert proc.stop(signal.SIGINT) == 0
    log = proc.log()
    # one line for the cause (a refused re-arm says why on its own)
    assert log.count("motors stopped: ") == 1 and "physics process ended" in log, log
    assert "Traceback" not in log, log


def _parent(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(") ", 1)[1].split()[1])


@pytest.mark.parametrize("victim", ["node", "loop"])
def test_the_physics_process_ends_with_the_node_or_its_loop_process(ros, start_bringup, victim):
    ns = f"physend{victim}"
    proc = start_bringup("xr4000", "--namespace", ns, "-p", "sim.physics_process:=true")
    probe = Probe(ros, ns)
    try:
        pid = _physics_pid(probe)
        loop = _parent(pid)
        assert _parent(loop) == proc.proc.pid        # node -> loop process -> physics
        if victim == "loop":
            os.kill(loop, signal.SIGKILL)            # no clean-up in the loop
            wait_until(lambda: not _alive(pid), 10.0, "the physics process to end")
    finally:
        probe.close()
    assert proc.stop(signal.SIGTERM) == 0
    wait_until(lambda: not _alive(pid), 10.0, "the physics process to end")
