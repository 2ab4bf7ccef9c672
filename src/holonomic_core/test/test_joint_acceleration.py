"""The joint acceleration stage on hand-made kinematics (q_dot = J xi with a
J that depends on q) and on the controller's route (the config key)."""

import math

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.joint_acceleration import JointAccelerationLimit

DT = 0.01


def identity_inverse(positions, twist):
    # two joints: q_dot = (vx, vy) scaled by (1 + q0): the configuration
    # changes the rates at an unchanged twist (the "drift")
    return np.array([twist[0] * (1.0 + positions[0]), twist[1]])


STAGE = JointAccelerationLimit(identity_inverse, [10.0, math.inf], [100.0, 100.0])
Q0 = np.zeros(2)


def test_a_change_within_the_limits_passes_unchanged():
    twist = np.array([0.05, 3.0, 0.0])          # joint 0 changes by 0.05 <= 10 x 0.01
    out = STAGE.limit(Q0, twist, np.zeros(3), np.zeros(2), DT)
    assert out is twist and STAGE.last == "target"


def test_a_large_change_is_scaled_along_its_line_to_the_limit():
    # joint 0 would change by 1.0 rad/s in one cycle, 0.1 allowed: t = 0.1, so
    # the twist goes a tenth of the way, both axes (the direction is kept)
    out = STAGE.limit(Q0, np.array([1.0, 2.0, 0.0]), np.zeros(3), np.zeros(2), DT)
    assert out == pytest.approx([0.1, 0.2, 0.0])


def test_a_drift_beyond_the_limit_slows_the_base_along_its_motion():
    # at q0 = 0.5 the unchanged twist (1, 0, 0) asks joint 0 for 1.5 rad/s,
    # commanded 1.0 last cycle: +0.5 in one cycle, 0.1 allowed. Slowing to
    # (1 - u) (1, 0, 0): 1.5 (1 - u) - 1.0 <= 0.1 -> u = 0.4 / 1.5
    prev = np.array([1.0, 0.0, 0.0])
    out = STAGE.limit(np.array([0.5, 0.0]), np.array([1.2, 0.0, 0.0]), prev,
                      np.array([1.0, 0.0]), DT)
    assert STAGE.last == "slowed"
    assert out == pytest.approx([1.0 - 0.4 / 1.5, 0.0, 0.0])
    rates = identity_inverse([0.5, 0.0], out)
    assert abs(rates[0] - 1.0) <= 10.0 * DT + 1e-12


def test_the_joint_speed_limits_hold_too_and_their_scale_is_reported():
    stage = JointAccelerationLimit(identity_inverse, [1e6, math.inf], [2.0, 2.0])
    out = stage.limit(Q0, np.array([4.0, 0.0, 0.0]), np.zeros(3), np.zeros(2), DT)
    assert out == pytest.approx([2.0, 0.0, 0.0]) and stage.speed_scale == 0.5


def test_the_config_builds_the_stage_and_no_limit_means_none():
    cfg = load_config("hamr", {"driver": "mock"})
    stage = JointAccelerationLimit.from_config(cfg.model, cfg.values)
    turret = cfg.model.joint_names.index("turret_joint")
    assert stage.max_acceleration[turret] == 20.0          # config/hamr.yaml
    off = {f"joints.{j}.max_acceleration": 0.0 for j in cfg.model.joint_names}
    cfg = load_config("hamr", {"driver": "mock", **off})
    assert JointAccelerationLimit.from_config(cfg.model, cfg.values) is None
