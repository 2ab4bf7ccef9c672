"""The simulated robot is a physical object of its own: built from the robot's
drawing (its config file) and the hidden sim.* errors, never from what the
controller believes (a calibration overlay, -p geometry)."""

from __future__ import annotations

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.nominal import driver_for, nominal_model

FAULTS = {"sim.wheel_radius_spread": 0.02, "sim.caster_offset_spread": 0.1,
          "sim.steer_zero_spread": 0.05, "sim.seed": 3}


def test_nominal_model_takes_the_geometry_from_the_config_file_only():
    overlay = {"pcv.front_left.wheel_radius": 0.0561, "pcv.rear_right.caster_offset": 0.021,
               "joints.rear_left_steer_joint.zero_correction": 0.04,
               "joints.front_left_wheel_joint.max_effort": 3.0}
    cfg = load_config("xr4000", overlay)
    drawn = nominal_model(cfg)
    # config/xr4000.yaml: r = 55 mm, b = 20 mm, every zero correction 0
    assert drawn.kinematics.r == pytest.approx([0.055] * 4)
    assert drawn.kinematics.b == pytest.approx([0.02] * 4)
    assert not drawn.zero_corrections.any()
    # not geometry: a torque limit is the same for the controller and the body
    assert drawn.params["joints.front_left_wheel_joint.max_effort"] == 3.0
    # the controller's model keeps the overlay
    assert cfg.model.kinematics.r[0] == 0.0561
    assert cfg.model.zero_corrections[2] == 0.04
    # a DDROT overlay writes per-wheel radii over the file's common one
    hamr = load_config("hamr", {"ddrot.left_wheel_radius": 0.0601,
                                "ddrot.half_wheel_separation": 0.17})
    kin = nominal_model(hamr).kinematics
    assert (kin.r_left, kin.r_right, kin.a) == pytest.approx((0.0615, 0.0615, 0.1641))


def test_nominal_model_of_a_config_without_a_file_is_the_config():
    from holonomic_core.config import config_from_flat, read_params_file, resolve_config
    flat = read_params_file(resolve_config("comr3"))
    flat["pcv.c1.wheel_radius"] = 0.041
    cfg = config_from_flat(flat, "<parameters>")
    assert nominal_model(cfg) is cfg.model


def test_a_calibration_overlay_changes_the_controller_not_the_simulated_robot():
    """Load the perfect calibration (the simulator's hidden truth) as an
    overlay: the body is the same (same hidden truth, same readings), and
    the controller, which adds the calibrated zero corrections, sees the
    steering joints at their true angle (at rest: 0, the wheels trailing as
    they were placed), not at angle + encoder error."""
    worn = load_config("xr4000", FAULTS)
    with driver_for(worn) as driver:
        truth = dict(driver.hidden_truth)
        radii = list(driver.wheel_radii)
        raw_worn = driver.read().positions
    assert len(truth) == 12         # 4 radii, 4 offsets, 4 zeros
    calibrated = load_config("xr4000", {**FAULTS, **truth})
    with driver_for(calibrated) as driver:
        assert driver.hidden_truth == truth
        assert driver.wheel_radii == radii
        raw_calibrated = driver.read().positions
    np.testing.assert_array_equal(raw_calibrated, raw_worn)
    steer = slice(0, None, 2)
    seen_worn = (raw_worn + worn.model.zero_corrections)[steer]
    seen_calibrated = (raw_calibrated + calibrated.model.zero_corrections)[steer]
    # errors up to 0.05 rad hidden; calibrated, what is left is the encoder's
    # quantisation (2 pi / (16384 x 20) = 1.9e-5 rad)
    assert np.max(np.abs(seen_worn)) > 0.02
    assert seen_calibrated == pytest.approx(np.zeros(4), abs=1e-4)


def test_a_ddrot_overlay_leaves_the_simulated_wheels_as_the_errors_made_them():
    faults = {"sim.wheel_radius_spread": 0.02, "sim.wheel_separation_spread": 0.02,
              "sim.steer_zero_spread": 0.05, "sim.seed": 2}
    with driver_for(load_config("hamr", faults)) as driver:
        truth = dict(driver.hidden_truth)
    overlay = {"ddrot.left_wheel_radius": 0.07, "ddrot.right_wheel_radius": 0.05,
               "ddrot.half_wheel_separation": 0.2, "joints.turret_joint.zero_correction": 0.3}
    with driver_for(load_config("hamr", {**faults, **overlay})) as driver:
        assert driver.hidden_truth == truth
        assert driver.wheel_radii == [truth["ddrot.left_wheel_radius"],
                                      truth["ddrot.right_wheel_radius"]]


def test_the_physics_process_builds_the_same_body():
    """sim.physics_process: the body's description travels to the physics
    process, so an overlay does not reach it there either."""
    faults = {**FAULTS, "sim.physics_process": True}
    calibrated = load_config("xr4000", {**faults, "pcv.front_left.wheel_radius": 0.07,
                                        "joints.front_left_steer_joint.zero_correction": 0.3})
    with driver_for(load_config("xr4000", faults)) as a, driver_for(calibrated) as b:
        assert a.hidden_truth == b.hidden_truth and a.wheel_radii == b.wheel_radii
        assert a.physics_pid != b.physics_pid
