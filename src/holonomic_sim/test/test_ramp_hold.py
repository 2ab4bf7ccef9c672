"""Holding still on a ramp (safety.disarm_mode, sim.floor_tilt): the base
controller on the simulator, lock-step, ground truth."""

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.driver import DriverState


def stopped_on_ramp(mode: str, brakes: bool, tilt: float = 5.0):
    """hamr on a ``tilt`` degree ramp (rising along +x): uphill at 0.3 m/s
    for 1 s, disarmed in ``mode``; returns (controller, driver, truth at
    rest 1 s after the disarm)."""
    cfg = load_config("hamr", {"driver": "sim", "sim.floor_tilt": tilt,
                               "sim.holding_brakes": brakes, "safety.disarm_mode": mode})
    driver = cfg.driver_class(cfg.model, cfg.values, cfg.controller.control_rate)
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=driver.sim_time)
    ctrl.request_enable(True)
    ctrl.step()
    for _ in range(200):
        ctrl.set_command((0.3, 0.0, 0.0))
        ctrl.step()
    ctrl.request_enable(False)
    for _ in range(200):
        ctrl.step()
    return ctrl, driver, driver.ground_truth().pose.copy()


def run_for(ctrl, seconds):
    for _ in range(round(seconds / ctrl.dt)):
        ctrl.step()


def test_hold_keeps_the_base_still_on_a_5_degree_ramp():
    ctrl, driver, rest = stopped_on_ramp("hold", brakes=False)
    assert driver.state is DriverState.ACTIVE and ctrl.status().holding
    run_for(ctrl, 10.0)
    moved = np.hypot(*(driver.ground_truth().pose[:2] - rest[:2]))
    print(f"hold, 5 deg, no brakes: moved {moved * 1e3:.3f} mm in 10 s")
    assert moved < 1e-3
    driver.close()


def test_coast_rolls_down_a_5_degree_ramp_without_brakes():
    ctrl, driver, rest = stopped_on_ramp("coast", brakes=False)
    assert driver.state is DriverState.INACTIVE
    run_for(ctrl, 10.0)
    truth = driver.ground_truth().pose
    moved = np.hypot(*(truth[:2] - rest[:2]))
    print(f"coast, 5 deg, no brakes: moved {moved:.3f} m in 10 s")
    # downhill is -x; friction of the drive trains slows it, but it rolls
    assert truth[0] - rest[0] < -0.1
    driver.close()
