"""Encoder spikes with the simulator in the loop (ROS-free), under the default
safety.glitch_policy (drop, glitch_rate 10/min): spikes as rare as real
encoders make them are dropped and the odometry does not notice; spikes 20
times a second are a broken encoder and fault, naming the joint."""

import numpy as np
import pytest

from holonomic_core.controller import ControllerState

from test_sim_faults import Rig

TWIST = (0.5, 0.0, 0.3)          # [m/s, m/s, rad/s]: an arc, not a line


def drive(spike_every: float | None, seconds: float):
    """Drive TWIST for ``seconds`` s after 1 s of speeding up, with a +4000
    rad/s velocity spike on the left wheel every ``spike_every`` s (None:
    none); returns the rig and the sim time of the fault (None: none)."""
    rig = Rig(**{"safety.glitch_policy": "drop"})
    rig.run(TWIST, 1.0)
    cycles = int(round(seconds * 200))
    every = None if spike_every is None else int(round(spike_every * 200))
    start, fault_at = rig.now, None
    for k in range(cycles):
        if every is not None and k % every == 0:
            rig.driver.spike_joint = 0
        rig.run(TWIST, 0.005)
        if fault_at is None and rig.ctrl.state is ControllerState.FAULT:
            fault_at = rig.now - start
            break
    return rig, fault_at


@pytest.fixture(scope="module")
def clean_run():
    rig, fault_at = drive(None, 60.0)
    yield rig.ctrl.odometry.pose.copy(), rig.ctrl.status()
    rig.close()


def test_a_spike_every_ten_seconds_is_dropped_and_the_odometry_does_not_notice(clean_run):
    """Six spikes in a minute (under glitch_rate 10/min): no fault, six
    dropped readings in the status, and the odometry within 1 mm (and 1 mrad)
    of the same run without spikes. A spike that reached the odometry would be
    4000 rad/s x 5 ms x 0.0615 m / 2 = 0.6 m off at once."""
    rig, fault_at = drive(10.0, 60.0)
    try:
        assert fault_at is None and rig.ctrl.state is ControllerState.ARMED
        status = rig.ctrl.status()
        assert status.dropped_readings == 6 and status.implausible_readings == 0
        assert status.last_dropped.startswith("left_wheel_joint: velocity reading")
        clean_pose, clean_status = clean_run
        assert clean_status.dropped_readings == 0
        difference = np.linalg.norm(rig.ctrl.odometry.pose[:2] - clean_pose[:2])
        print(f"odometry difference with / without spikes after 60 s: {difference * 1e3:.4f} mm "
              f"(path {status.distance:.2f} m)")
        assert difference < 1e-3
        assert abs(rig.ctrl.odometry.pose[2] - clean_pose[2]) < 1e-3
    finally:
        rig.close()


def test_twenty_spikes_a_second_fault_naming_the_joint():
    """20 spikes/s: the 11th in a minute is over glitch_rate 10, 10 x 50 ms =
    0.5 s after the first; the base stops and the fault names the joint."""
    rig, fault_at = drive(0.05, 5.0)
    try:
        print(f"fault {fault_at:.3f} s after the first spike: {rig.ctrl.fault}")
        assert fault_at == pytest.approx(0.5 + 0.005, abs=0.006)
        assert rig.ctrl.fault.startswith("left_wheel_joint: velocity reading")
        assert "11 invalid readings in the last minute" in rig.ctrl.fault
        assert not rig.driver.armed
        rig.run(TWIST, 1.0)
        assert rig.speed() < 0.01
    finally:
        rig.close()
