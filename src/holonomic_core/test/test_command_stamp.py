"""The window of stamped commands (cmd_vel_stamped): which are taken, and
when they go stale (ROS-free; the ROS route: test_process_safety.py).

By hand, with cmd_timeout 0.5 s (the shipped configs') and the window
[-0.1 s, cmd_timeout] of ages (now - stamp):

* stamped 0.2 s ago (age +0.2): taken, dated back 0.2 s, so it goes stale
  at stamp + 0.5 s, 0.3 s after it arrived;
* stamped 0.05 s ahead (age -0.05, a clock offset between hosts): taken as
  sent now, stale 0.5 s after it arrived;
* stamped 0.3 s ahead (age -0.3): refused; 10 s old or 5 s ahead: refused.
"""

from __future__ import annotations

import pytest

from holonomic_core.command_stamp import FUTURE_TOLERANCE, stamped_command_age
from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.loop import ManualClock
from holonomic_core.mock_driver import MockDriver

NOW = 1000.0        # [s] the node's clock
TIMEOUT = 0.5       # [s] cmd_timeout of the shipped configs


@pytest.mark.parametrize("offset, age", [
    (-0.2, 0.2),            # 0.2 s old: dated back by it
    (0.05, 0.0),            # 50 ms ahead: a clock offset, counts as now
    (0.0, 0.0),
    (-0.499, 0.499),        # just inside cmd_timeout
    (0.099, 0.0),           # 99 ms ahead: just inside the tolerance
])
def test_a_stamp_inside_the_window_is_taken_dated_back_by_its_age(offset, age):
    got, problem = stamped_command_age(NOW, NOW + offset, TIMEOUT)
    assert problem is None
    assert got == pytest.approx(age, abs=1e-9)


@pytest.mark.parametrize("offset", [0.3, 0.101, 5.0, -0.501, -10.0])
def test_a_stamp_outside_the_window_is_refused_saying_the_window(offset):
    got, problem = stamped_command_age(NOW, NOW + offset, TIMEOUT)
    assert got is None
    assert problem == (f"cmd_vel stamped {-offset:+.3f} s from now rejected (allowed: "
                       "-0.1 s to cmd_timeout=0.5 s old)")


def test_without_a_timeout_only_the_future_bound_holds():
    # cmd_timeout 0 disables the timeout: a 10 s old command is taken (and
    # never goes stale), one 0.3 s ahead still is not
    assert stamped_command_age(NOW, NOW - 10.0, 0.0) == (pytest.approx(10.0), None)
    assert stamped_command_age(NOW, NOW + 0.3, 0.0)[0] is None
    assert FUTURE_TOLERANCE == 0.1


@pytest.mark.parametrize("offset, moving_for", [(-0.2, 0.3), (0.05, 0.5), (0.0, 0.5)])
def test_a_stamped_command_stops_the_base_at_its_stamp_plus_cmd_timeout(offset, moving_for):
    """The node's route: the command arrives at t = 1 s on the controller's
    clock, dated back by its age (received = arrival - age); the controller
    follows it until it is older than cmd_timeout, i.e. until stamp + 0.5 s:
    0.3 s after arrival for a command stamped 0.2 s ago, 0.5 s for a fresh
    one or one stamped 50 ms ahead. Cycles every 5 ms (200 Hz)."""
    cfg = load_config("hamr", {"driver": "mock"})
    clock = ManualClock()
    driver = MockDriver(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock)
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=clock)
    ctrl.request_enable(True)
    assert cfg.controller.cmd_timeout == TIMEOUT and ctrl.dt == 0.005
    clock.now = 1.0
    ctrl.step()
    arrival = clock.now
    age, problem = stamped_command_age(NOW, NOW + offset, ctrl.cmd_timeout)
    assert problem is None
    ctrl.set_command((0.2, 0.0, 0.0), received=arrival - age)
    fresh = []
    for k in range(1, 121):                         # 0.6 s of cycles
        clock.now = arrival + k * ctrl.dt
        ctrl.step()
        fresh.append(not ctrl.stale)
    # fresh while clock - received <= 0.5 s: the cycles up to arrival + moving_for
    # (cycle k at k x 5 ms; a margin of one cycle for the rounding of k x dt)
    cycles = round(moving_for / ctrl.dt)
    assert all(fresh[:cycles - 1]) and not any(fresh[cycles + 1:]), (offset, fresh)
    assert ctrl.counters["timeouts"] == 1
