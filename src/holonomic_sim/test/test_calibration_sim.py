"""Self-calibration against the simulator's hidden truth (offline: controller
core + sim driver, no ROS), shortened versions of holonomic-calibration-experiment
(which runs 2 x 60 s; docs/calibration.md has its table)."""

from __future__ import annotations

import math

import numpy as np

from holonomic_core.model import load_model
from holonomic_sim.calibration_experiment import calibration_run


def _worst(result, errors, kind):
    return float(np.max(np.abs(errors[[k == kind for k in result.family.kinds]])))


def test_pcv_geometry_is_recovered_from_two_short_drives():
    # hidden: radii +-2 %, offsets +-10 %, steering zeros +-3 deg (sim.seed 2);
    # two 30 s drives in torque mode, the second with the first estimate
    result, truth, errors = calibration_run("xr4000", 2, 30.0, "ground_truth", passes=2)
    configured = load_model("xr4000").params
    assert len(truth) == 12 and all(truth[k] != configured[k] for k in truth)  # all hidden
    # measured: radii 0.062 %, offsets 0.20 %, zeros 0.0055 deg
    assert _worst(result, errors, "radius") < 0.002
    assert _worst(result, errors, "offset") < 0.006
    assert _worst(result, errors, "zero") < math.radians(0.02)


def test_ddrot_geometry_is_recovered_against_ground_truth():
    # hidden: radii +-2 %, separation +-2 %, turret zero +-3 deg; one 30 s drive
    result, truth, errors = calibration_run("hamr", 2, 30.0, "ground_truth", passes=1)
    assert set(truth) == {"ddrot.left_wheel_radius", "ddrot.right_wheel_radius",
                          "ddrot.half_wheel_separation", "joints.turret_joint.zero_correction"}
    assert truth["ddrot.half_wheel_separation"] != 0.1641      # perturbed
    # measured: radii 0.015 %, half separation 0.076 %, turret zero 0.0036 deg
    assert _worst(result, errors, "radius") < 0.001
    assert _worst(result, errors, "length") < 0.003
    assert _worst(result, errors, "zero") < math.radians(0.02)
