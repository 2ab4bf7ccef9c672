"""Joint acceleration limits in the simulator: the cases that need them.

A DDROT's turret reversal (HAMR strafing one way, then the other: the turret
swings the drive base around) and a powered caster swinging through its
unstable, leading alignment (the XR4000 reversing: each caster trailed its
steering axis and must turn half a turn). Each run with and without
``joints.NAME.max_acceleration``; peaks of the commanded joint accelerations
(the joint commands' change per cycle) and of the simulated ones (the
simulator's joint velocities' change per cycle)."""

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController


def drive(robot, segments, overrides):
    """Run the controller on the simulator through ``segments`` ((twist,
    seconds), ...). Returns (joint names, peak |commanded accel| and peak
    |simulated accel| per joint [rad/s^2], ground-truth poses (k x 3))."""
    cfg = load_config(robot, {**overrides, "driver": "sim", "cmd_timeout": 0.0,
                              "enable_on_start": True})
    drv = cfg.driver_class(cfg.model, cfg.values, cfg.controller.control_rate)
    dt = 1.0 / cfg.controller.control_rate
    measured, commanded, poses = [], [], []
    with drv:
        ctrl = BaseController(cfg, drv)
        ctrl.request_enable(True)
        for twist, seconds in segments:
            for _ in range(round(seconds / dt)):
                ctrl.set_command(twist)
                ctrl.step()
                assert ctrl.fault is None, ctrl.fault
                measured.append(ctrl.reading.velocities.copy())
                commanded.append(ctrl.joint_command.copy())
                poses.append(drv.ground_truth().pose.copy())
    peak = lambda rates: np.abs(np.diff(np.array(rates), axis=0)).max(axis=0) / dt  # noqa: E731
    return cfg.model.joint_names, peak(commanded), peak(measured), np.array(poses)


def no_limits(robot):
    names = load_config(robot, {"driver": "mock"}).model.joint_names
    return {f"joints.{j}.max_acceleration": 0.0 for j in names}


def test_a_turret_reversal_stays_within_the_turret_acceleration_limit_on_its_path():
    # strafe left at 0.6 m/s, then right: the drive base, rolling along the
    # turret's y axis, turns round through 180 deg
    segments = [((0.0, 0.6, 0.0), 1.5), ((0.0, -0.6, 0.0), 2.0), ((0.0, 0.0, 0.0), 1.0)]
    free = no_limits("hamr")
    names, cmd_free, sim_free, path_free = drive("hamr", segments, free)
    turret = names.index("turret_joint")
    limit = 8.0
    names, cmd, sim, path = drive("hamr", segments,
                                  {**free, "joints.turret_joint.max_acceleration": limit})
    print(f"turret peak accel [rad/s^2]: unlimited cmd {cmd_free[turret]:.1f} sim "
          f"{sim_free[turret]:.1f}; limit {limit}: cmd {cmd[turret]:.1f} sim {sim[turret]:.1f}")
    # without the limit the reversal asks more of the turret (13.3 rad/s^2)
    assert cmd_free[turret] > 1.5 * limit
    assert cmd[turret] <= limit * (1 + 1e-9)
    # the simulated turret follows its command within its drive's tracking
    # (the drive model's velocity loop overshoots a ramp's start by a few %)
    assert sim[turret] <= 1.1 * limit < sim_free[turret]
    # the path kept: the base stays on its line (x = 0) and heading as well as
    # without the limit (2.7 cm, 4 deg: the drive base's own swing)
    assert np.abs(path[:, 0]).max() <= np.abs(path_free[:, 0]).max() + 0.005
    assert np.abs(path[:, 2]).max() <= np.abs(path_free[:, 2]).max() + np.radians(0.5)


def test_casters_swinging_through_their_leading_alignment_are_commanded_within_the_limit():
    # forward at 0.8 m/s, then backward: every caster, trailing its steering
    # axis, now leads it and swings half a turn, its steering rate v sin(alpha)
    # / b and acceleration about (v / b)^2 sin(2 alpha) / 2 with b = 2 cm
    segments = [((0.8, 0.0, 0.0), 1.5), ((-0.8, 0.0, 0.0), 2.0), ((0.0, 0.0, 0.0), 1.0)]
    free = no_limits("xr4000")
    names, cmd_free, sim_free, path_free = drive("xr4000", segments, free)
    steer = [i for i, n in enumerate(names) if n.endswith("_steer_joint")]
    limit = 250.0
    limited = {**free, **{f"joints.{names[i]}.max_acceleration": limit for i in steer}}
    names, cmd, sim, path = drive("xr4000", segments, limited)
    print("steering peak accel [rad/s^2]: unlimited cmd",
          np.round(cmd_free[steer], 1), "sim", np.round(sim_free[steer], 1),
          f"; limit {limit}: cmd", np.round(cmd[steer], 1), "sim", np.round(sim[steer], 1))
    assert cmd_free[steer].max() > 1.2 * limit       # 320 rad/s^2 without the limit
    assert cmd[steer].max() <= limit * (1 + 1e-9)
    # the path: the base's lateral drift and heading error (the casters' swing
    # pulls it aside) no worse than without the limit
    assert np.abs(path[:, 1]).max() <= np.abs(path_free[:, 1]).max() + 0.005
    assert np.abs(path[:, 2]).max() <= np.abs(path_free[:, 2]).max() + np.radians(0.5)
