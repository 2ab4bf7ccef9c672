"""Self-calibration of a swerve base: the wheel radii and steering zeros
recovered from ordinary driving (the least-squares odometry's residual),
on samples synthesised from a robot whose true parameters differ from the
configured ones."""


import numpy as np
import pytest

from holonomic_core.calibration import Samples, calibrate, chord, family_for
from holonomic_core.model import load_model

R = 0.075


def _samples(model, radii, zero_errors, seed=3, count=400, dt=0.05):
    """Modules aligned with random twists; the encoders read the true heading
    minus the zero error, the wheels turn |v| dt / r_true."""
    rng = np.random.default_rng(seed)
    kin = model.kinematics
    positions = np.zeros((count, 8))
    displacements = np.zeros((count, 8))
    reference = np.zeros((count, 3))
    for k in range(count):
        twist = rng.uniform([-0.8, -0.8, -1.5], [0.8, 0.8, 1.5])
        v = kin.module_velocities(twist)
        heading = np.arctan2(v[:, 1], v[:, 0])
        positions[k, 0::2] = heading - zero_errors
        displacements[k, 1::2] = np.hypot(v[:, 0], v[:, 1]) * dt / radii
        reference[k] = chord(twist * dt)
    return Samples(positions, displacements, np.full(count, dt), reference)


def test_the_true_parameters_leave_no_residual_and_the_configured_ones_do():
    model = load_model("swerve4")
    family = family_for(model)
    radii = np.array([1.01, 1.0, 1.0, 0.99]) * R
    zeros = np.array([0.0, 0.02, 0.0, 0.0])
    samples = _samples(model, radii, zeros)
    truth = np.concatenate((radii, zeros))
    assert np.abs(family.slip(truth, samples)).max() < 1e-12
    assert np.abs(family.slip(family.nominal, samples)).max() > 1e-4


def test_radii_and_steering_zeros_are_recovered_against_ground_truth():
    # fl 1 % large, fr 1 % small, rl's steering encoder 0.02 rad (1.15 deg) off
    model = load_model("swerve4")
    radii = np.array([1.01, 1.0, 1.0, 0.99]) * R
    zeros = np.array([0.0, 0.02, 0.0, 0.0])
    result = calibrate(model, _samples(model, radii, zeros), reference="ground_truth")
    assert result.theta[:4] == pytest.approx(radii, rel=1e-6)
    assert result.theta[4:] == pytest.approx(zeros, abs=1e-6)
    assert set(result.overlay()) == {"swerve.fl.wheel_radius", "swerve.rl.wheel_radius",
                                     "swerve.rr.wheel_radius", "swerve.fr.wheel_radius",
                                     "joints.fl_steer_joint.zero_correction",
                                     "joints.rl_steer_joint.zero_correction",
                                     "joints.rr_steer_joint.zero_correction",
                                     "joints.fr_steer_joint.zero_correction"}


def test_without_a_reference_the_radii_ratios_and_zeros_are_recovered():
    # the overall scale is unobservable: the mean radius stays as configured
    # (0.075 m), the ratios and the zeros are what the residual shows
    model = load_model("swerve4")
    radii = np.array([1.02, 1.0, 1.0, 1.0]) * R
    zeros = np.array([0.0, 0.0, -0.03, 0.0])
    result = calibrate(model, _samples(model, radii, zeros), reference="none")
    expected = radii * (R / radii.mean())
    assert result.theta[:4] == pytest.approx(expected, rel=1e-5)
    assert result.theta[4:] == pytest.approx(zeros, abs=1e-5)
