"""A caster whose odometry residual stays high is named (ROS-free)."""

import math

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.loop import ManualClock
from holonomic_core.mock_driver import MockDriver
from holonomic_core.slip_monitor import SlipLimits, SlipMonitor

#: every test here runs on both implementations of the cycle's closed forms
#: ([pure], [compiled]: the hot_path_mode fixture of holonomic_testing)
pytestmark = pytest.mark.usefixtures("hot_path_mode")


def test_a_unit_is_named_only_after_staying_above_the_threshold_for_the_duration():
    mon = SlipMonitor(("a", "b", "c"), SlipLimits(threshold=0.05, duration=1.0))
    mon.update([0.0, 0.2, 0.0], 10.0)
    assert mon.slipping(10.0) == []
    mon.update([0.0, 0.2, 0.0], 10.99)
    assert mon.slipping(10.99) == []                 # 0.99 s < 1 s
    mon.update([0.0, 0.2, 0.06], 11.0)
    assert mon.slipping(11.0) == [("b", 1.0)]
    # one cycle back under the threshold restarts the clock
    mon.update([0.0, 0.04, 0.06], 11.5)
    mon.update([0.0, 0.2, 0.06], 11.6)
    assert mon.slipping(12.0) == [("c", 1.0)]
    mon.reset()
    assert mon.slipping(20.0) == []


def test_non_finite_or_mismatched_residuals_never_raise_or_warn():
    mon = SlipMonitor(("a", "b"), SlipLimits(0.05, 0.0))
    mon.update([math.nan, 0.0], 1.0)
    mon.update([0.1, 0.1, 0.1], 1.0)                 # wrong length: ignored
    assert mon.slipping(5.0) == []


class SpinningWheelMock(MockDriver):
    """Mock XR4000 whose rear_left wheel spins 0.3 m/s faster than commanded
    (a wheel on a wet patch): its encoder runs ahead by 0.3 / r rad/s."""

    extra = 0.0          # [rad/s]
    offset = 0.0         # [rad] accumulated extra turn
    last = None

    def _on_read(self):
        reading = super()._on_read()
        if self.last is not None:
            self.offset += self.extra * (reading.stamp - self.last)
        self.last = reading.stamp
        positions = reading.positions.copy()
        positions[self.model.joint_names.index("rear_left_wheel_joint")] += self.offset
        return type(reading)(reading.stamp, positions, reading.velocities, reading.efforts)


def test_controller_names_the_caster_that_keeps_slipping():
    cfg = load_config("xr4000", {"driver": "mock", "estimator": "robust", "cmd_timeout": 0.0,
                                 "diagnostics.slip_threshold": 0.05,
                                 "diagnostics.slip_duration": 0.5})
    clock = ManualClock()
    driver = SpinningWheelMock(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock)
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=clock)
    ctrl.request_enable(True)

    def run(seconds):
        for _ in range(int(round(seconds / ctrl.dt))):
            clock.now += ctrl.dt
            ctrl.step()

    # the casters start aligned with x: steering needs no transient
    run(0.01)
    ctrl.set_command((0.3, 0.0, 0.0))
    run(1.0)
    assert ctrl.slip_monitor.slipping(clock.now) == []
    driver.extra = 0.3 / cfg.model.kinematics.casters[1].wheel_radius
    run(0.4)
    assert ctrl.slip_monitor.slipping(clock.now) == []        # 0.4 s < 0.5 s
    run(0.2)
    names = [name for name, _ in ctrl.slip_monitor.slipping(clock.now)]
    # robust leaves the spinning caster out: it alone carries the residual
    # (0.3 m/s, its disagreement with the others), the others none
    assert names == ["rear_left"]
    # the status the diagnostics are built from says the same (at the reading's stamp)
    assert [name for name, _ in ctrl.status().slipping] == ["rear_left"]
    np.testing.assert_allclose(ctrl.odometry.residual, [0.0, 0.3, 0.0, 0.0], atol=1e-6)
    # and the odometry follows the three good casters: 0.3 m/s, not more
    assert abs(ctrl.odometry.twist[0] - 0.3) < 1e-3
