"""The control loop in its own process (holonomic_bringup.loop_host): what
the node reports and does when that process crashes or hangs, that signals
stop both, the controller's status API the diagnostics are built from, and
the real-time request's fallback."""

from __future__ import annotations

import math
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus

from holonomic_core import realtime
from holonomic_core.config import load_config
from holonomic_core.controller import BaseController, ControllerState
from holonomic_core.loop import ManualClock
from holonomic_core.mock_driver import MockDriver
from holonomic_testing.ros_probe import Probe, wait_until

STOPPED = "motors stopped and disarmed"


# -- the status API (ROS-free) ---------------------------------------------------------------
def _controller():
    cfg = load_config("hamr", {"driver": "mock"})
    clock = ManualClock()
    driver = MockDriver(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock)
    driver.configure()
    return BaseController(cfg, driver, clock=clock), clock


def test_status_reports_counters_command_and_state():
    ctrl, clock = _controller()
    ctrl.step()
    status = ctrl.status()
    assert status.state is ControllerState.DISARMED and status.fault is None
    assert status.command_age == math.inf and status.stale
    # a command while disarmed: counted, and the status says so
    ctrl.set_command((0.2, 0.0, 0.0))
    clock.now += 0.5
    status = ctrl.status()
    assert status.commands_while_disarmed == 1 and status.commanded_while_disarmed
    assert status.command_age == pytest.approx(0.5)
    # a non-finite command: rejected and counted
    ctrl.set_command((math.nan, 0.0, 0.0))
    assert ctrl.status().rejected_commands == 1
    # armed: the driver's own status comes along
    ctrl.request_enable(True)
    clock.now += ctrl.dt
    ctrl.step()
    status = ctrl.status()
    assert status.state is ControllerState.ARMED
    assert status.driver["backend"] == "mock" and status.estimator == "slip_min"
    assert status.cycles == 2 and status.residual == ()       # the DDROT has no casters


def test_the_first_cycle_after_a_command_is_written_takes_it_after_its_reading():
    # the loop process (mock driver, 1 kHz, a record every cycle) drains the
    # command pipe once a cycle, after the reading and before the control
    # law, and says when in each record (command_taken): the first record
    # commanding the twist is the first cycle that drained the pipe after
    # the write, and its reading came before the take
    from holonomic_bringup.loop_client import LoopClient
    from holonomic_core.config import read_params_file, resolve_config

    path = resolve_config("hamr")
    flat = read_params_file(path)
    flat.update({"driver": "mock", "control_rate": 1000.0, "publish_rate": 1000.0,
                 "enable_on_start": True, "loop.realtime": False})
    cfg = load_config("hamr", {"driver": "mock"})
    client = LoopClient([(flat, str(path), cfg.model)])
    records = []
    client.links[0].on_record = records.append     # the client's reader thread
    client.start()
    try:
        armed = _STATE_INDEX[ControllerState.ARMED]
        wait_until(lambda: records and records[-1].state_index == armed, 10.0, "armed")
        client.links[0].send_command((0.2, 0.0, 0.0), time.monotonic())
        written = time.monotonic()
        wait_until(lambda: any(r.twist_command[0] > 0.0 for r in records[-50:]), 10.0,
                   "a cycle commanding the twist")
    finally:
        client.stop()
    first = next(k for k, r in enumerate(records) if r.twist_command[0] > 0.0)
    used, before = records[first], records[first - 1]
    assert used.cycle == before.cycle + 1            # consecutive cycles, none dropped
    # the cycle before drained the pipe before the write ended (else it
    # would have taken the command)
    assert before.command_taken < written
    # the mock stamps its readings on the same clock (time.monotonic): each
    # cycle took its command after its reading
    assert before.stamp <= before.command_taken < used.stamp <= used.command_taken


_STATE_INDEX = {s: k for k, s in enumerate(ControllerState)}


@pytest.mark.parametrize("users, expected", [(None, "1"), ("2", "2")])
def test_the_loop_process_runs_numpys_blas_single_threaded_unless_the_user_chose(
        monkeypatch, users, expected):
    # OpenBLAS's worker threads run on the normal scheduler: a real-time
    # loop must not wait for them (loop_client.loop_environment); a user's
    # own OPENBLAS_NUM_THREADS is kept
    from holonomic_bringup.loop_client import LoopClient
    from holonomic_core.config import read_params_file, resolve_config

    if users is None:
        monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OPENBLAS_NUM_THREADS", users)
    path = resolve_config("hamr")
    flat = read_params_file(path)
    flat.update({"driver": "mock", "loop.realtime": False})
    client = LoopClient([(flat, str(path), load_config("hamr", {"driver": "mock"}).model)])
    client.start()
    try:
        environ = Path(f"/proc/{client.pid}/environ").read_bytes().split(b"\0")
    finally:
        client.stop()
    assert f"OPENBLAS_NUM_THREADS={expected}".encode() in environ


def test_a_fault_raised_from_outside_disarms_and_the_first_cause_stays():
    ctrl, clock = _controller()
    ctrl.request_enable(True)
    ctrl.step()
    ctrl.set_command((0.3, 0.0, 0.0))
    clock.now += ctrl.dt
    ctrl.step()
    assert np.any(ctrl.joint_command != 0.0)
    ctrl.raise_fault("internal error: ZeroDivisionError()")
    ctrl.raise_fault("a consequence")
    status = ctrl.status()
    assert status.state is ControllerState.FAULT
    assert status.fault == "internal error: ZeroDivisionError()"
    assert not ctrl.driver.armed and np.all(ctrl.joint_command == 0.0)
    assert status.twist_command == (0.0, 0.0, 0.0)
    # an outside fault is not a driver error
    assert status.driver_errors == 0


# -- real-time request -------------------------------------------------------------------------
def test_refused_real_time_is_one_warning_line_naming_how_to_grant_it(monkeypatch):
    def refuse(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    assert realtime.set_fifo(50) == "SCHED_FIFO priority 50 not permitted (Operation not permitted)"
    monkeypatch.setattr(realtime, "lock_memory", lambda: "mlockall not permitted (EPERM)")
    warning = realtime.request_realtime(50)
    assert "\n" not in warning
    for words in ("SCHED_FIFO priority 50", "mlockall", "limits.conf", "loop.realtime:=false"):
        assert words in warning


# -- the loop process under the node ----------------------------------------------------------
def _loop_pid(bringup) -> int:
    """The loop process: the child of the bringup running loop_host."""
    found = {}

    def child():
        for task in Path(f"/proc/{bringup.proc.pid}/task").iterdir():
            for pid in (task / "children").read_text().split():
                cmd = Path(f"/proc/{pid}/cmdline").read_bytes()
                if b"holonomic_bringup.loop_host" in cmd:
                    found["pid"] = int(pid)
                    return True
        return False
    wait_until(child, 30.0, "the loop process")
    return found["pid"]


def _gone(pid: int) -> bool:
    """The process has ended (no such process, or a zombie not yet reaped)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] == "Z"
    except FileNotFoundError:
        return True


def _driver_status(probe):
    if probe.diagnostics is None:
        return None
    return next((s for s in probe.diagnostics.status if s.name.endswith("driver")), None)


def _values(status) -> dict:
    return {kv.key: kv.value for kv in status.values}


def _loop_error(probe, words: str) -> bool:
    status = _driver_status(probe)
    return status is not None and status.level == DiagnosticStatus.ERROR and words in status.message


@pytest.mark.parametrize("how, words", [
    (signal.SIGKILL, "control loop ended (killed by SIGKILL)"),      # a crash
    (signal.SIGSTOP, "control loop hung"),                           # a hang: the watchdog
])
def test_a_crashed_or_hung_loop_process_stops_the_base_and_is_reported(
        ros, start_bringup, how, words):
    ns = f"loopfail{int(how)}"
    proc = start_bringup("hamr", "--enable", "--namespace", ns, "-p", "cmd_timeout:=0.0")
    probe = Probe(ros, ns)
    try:
        probe.wait_ready()
        pid = _loop_pid(proc)
        probe.drive((0.3, 0.0, 0.0), 0.5)
        os.kill(pid, how)
        wait_until(lambda: _loop_error(probe, words), 10.0, f"an ERROR saying {words!r}")
        status = _driver_status(probe)
        assert _values(status)["controller_state"] == "fault"
        # the simulation stopped with the loop: nothing moves any more (no
        # new ground truth across a whole diagnostics period, counted from
        # the one after the error: what was in flight has arrived by then)
        wait_until(lambda: _gone(pid), 5.0, "the loop process to end")
        for _ in range(2):
            t0 = time.monotonic()
            seen = probe.diagnostics
            wait_until(lambda: probe.diagnostics is not seen, 5.0, "the next diagnostics")
        assert probe.truth_since(t0) == []
        # its services say why they cannot act
        answer = probe.enable(True)
        assert not answer.success and "not running" in answer.message
        if how == signal.SIGSTOP:
            assert "killed" in status.message
    finally:
        probe.close()
    assert proc.stop(signal.SIGINT) == 0
    log = proc.log()
    assert STOPPED in log and "Traceback" not in log, log


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_stops_the_loop_process_with_the_node(ros, start_bringup, sig):
    ns = f"loopsig{int(sig)}"
    proc = start_bringup("hamr", "--driver", "mock", "--enable", "--namespace", ns)
    probe = Probe(ros, ns)
    try:
        probe.wait_ready(ground_truth=False)
        pid = _loop_pid(proc)
    finally:
        probe.close()
    assert proc.stop(sig) == 0
    assert _gone(pid)
    assert STOPPED in proc.log() and "Traceback" not in proc.log()


def test_the_loop_process_scheduling_is_reported_and_can_be_turned_off(ros, start_bringup):
    def scheduling(probe):
        loop = next(s for s in probe.diagnostics.status if s.name.endswith("control loop"))
        return _values(loop)["scheduling"]

    for realtime_on in (True, False):
        ns = f"looprt{int(realtime_on)}"
        proc = start_bringup("hamr", "--driver", "mock", "--namespace", ns,
                             "-p", f"loop.realtime:={str(realtime_on).lower()}")
        probe = Probe(ros, ns)
        try:
            probe.wait_ready(ground_truth=False)
            wait_until(lambda: probe.diagnostics is not None, 10.0, "diagnostics")
            policy = scheduling(probe)
        finally:
            probe.close()
        assert proc.stop() == 0
        refused = "real-time scheduling unavailable" in proc.log()
        # on the normal scheduler the loop.slice default, 0.1 ms, where the
        # kernel takes it (6.12+), else one warning line saying it did not
        sliced = "loop.slice 0.1 ms not applied" not in proc.log()
        normal = "SCHED_OTHER 0, slice 0.10 ms" if sliced else "SCHED_OTHER 0"
        if realtime_on:
            # granted (SCHED_FIFO at the default priority), or one warning
            # line and the normal policy
            assert policy == (normal if refused else "SCHED_FIFO 50"), proc.log()
            assert proc.log().count("real-time scheduling unavailable") <= 1
        else:
            assert policy == normal and not refused
        assert proc.log().count("loop.slice 0.1 ms not applied") <= 1


def _get_parameter(ros, node: str, name: str):
    from rcl_interfaces.srv import GetParameters

    client = ros.create_client(GetParameters, f"{node}/get_parameters")
    try:
        assert client.wait_for_service(timeout_sec=10.0)
        future = client.call_async(GetParameters.Request(names=[name]))
        wait_until(future.done, 10.0, f"{node}'s parameters")
        return future.result().values[0].double_value
    finally:
        ros.destroy_client(client)


def test_a_fleet_runs_in_one_loop_process_with_its_overrides_parsed_by_rclpy(ros, start_bringup):
    # -p goes through rclpy for every robot, as for one robot
    fleet = start_bringup("hamr", "--fleet", "2", "-p", "cmd_timeout:=1.5")
    probes = [Probe(ros, f"robot{k}") for k in (1, 2)]
    try:
        for probe in probes:
            probe.wait_ready()
        pid = _loop_pid(fleet)
        children = [int(p) for task in Path(f"/proc/{fleet.proc.pid}/task").iterdir()
                    for p in (task / "children").read_text().split()]
        assert children == [pid]          # one world, one loop, one process
        for k in (1, 2):
            assert _get_parameter(ros, f"/robot{k}/base_controller", "cmd_timeout") == 1.5
        # the first robot alone publishes the simulated clock
        assert ros.count_publishers("/clock") == 1
    finally:
        for probe in probes:
            probe.close()
    assert fleet.stop() == 0
    assert _gone(pid)
