"""The simulator stamps a reading with the time it describes.

The drive model's positions and speeds are ``sim.drive.feedback_delay`` (5 ms)
old when the driver reads them. A reading stamped at the time it is read puts
the joints 5 ms late against anything stamped at the true time (the ground
truth, another sensor), which biased the calibration against ground truth and
showed in the odometry covariance as a 5 ms latency. The CAN drivers stamp at
the sample (a SYNC, a frame's arrival); the simulator stamps at the world's
time less the delay, and gives the ground truth at that stamp.
"""

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.loop import ManualClock


def _forward_run(overrides):
    """HAMR (sim.seed 3): 0.5 m/s forward for 1.2 s, then a stop, through the
    controller (its acceleration limits make the ramps); per cycle the
    forward speed from the joint readings (the kinematics' forward map) and
    the true one, with their stamps and the driver's sim time."""
    cfg = load_config("hamr", {"sim.seed": 3, "cmd_timeout": 0.0, "enable_on_start": True,
                               **overrides})
    clock = ManualClock()
    rows = []
    with cfg.driver_class(cfg.model, cfg.values, cfg.controller.control_rate) as driver:
        ctrl = BaseController(cfg, driver, clock=clock)
        ctrl.request_enable(True)
        for k in range(int(2.5 * cfg.controller.control_rate)):
            ctrl.set_command((0.5, 0.0, 0.0) if k < 1.2 * cfg.controller.control_rate
                             else (0.0, 0.0, 0.0))
            ctrl.step()
            clock.now = ctrl.reading.stamp
            reading, truth = ctrl.reading, driver.ground_truth()
            rows.append((reading.stamp, truth.stamp, driver.sim_time(),
                         cfg.model.kinematics.forward(reading.positions, reading.velocities)[0],
                         truth.twist[0]))
    return np.array(rows)


@pytest.fixture(scope="module")
def drive_model_run():
    return _forward_run({})


def test_a_reading_is_stamped_when_it_was_sampled(drive_model_run):
    stamp, truth_stamp, sim_time = drive_model_run[:, 0], drive_model_run[:, 1], \
        drive_model_run[:, 2]
    # default feedback_delay 5 ms = 5 physics steps at 1 kHz: every reading
    # (the first one too: the world settled before the clock started) is
    # 5 ms older than the world's time, and the truth comes at its stamp
    assert sim_time - stamp == pytest.approx(np.full(len(stamp), 0.005), abs=1e-12)
    assert np.array_equal(truth_stamp, stamp)


def test_the_joints_and_the_truth_describe_the_same_instant(drive_model_run):
    # If the truth led the joints by tau, the true speed minus the speed from
    # the joints would be tau x the acceleration on the ramps: tau is the
    # least-squares slope of that difference on the acceleration. Measured:
    # 0.002 ms with the sample-time stamps; 5.0 ms with the truth taken at
    # the world's time (the reading 5 ms older), the bias this removes.
    stamp, v_joints, v_true = drive_model_run[:, 0], drive_model_run[:, 3], drive_model_run[:, 4]
    accel = np.gradient(v_true, stamp)
    assert np.abs(accel).max() > 1.0          # the run has ramps to measure on
    tau = float(np.sum((v_true - v_joints) * accel) / np.sum(accel * accel))
    assert abs(tau) < 0.0005, f"the truth leads the joints by {tau * 1e3:.2f} ms"


def test_ideal_motors_have_no_delay_to_stamp():
    # ideal motors report the state after the step: stamp = the world's time
    run = _forward_run({"sim.ideal_motors": True})
    assert np.array_equal(run[:, 0], run[:, 2])
    assert np.array_equal(run[:, 1], run[:, 0])
