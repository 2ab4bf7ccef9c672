"""The scalar-arithmetic operational-space terms (``PcvDynamics.terms``,
eq. 4 and the bias mu) and torque distribution (eq. 14) give the numbers of
the numpy implementation they replaced (main 7112ec2, copied verbatim into
holonomic_testing.pcv_numpy_reference), on random and singular-looking
configurations of every robot with a dynamic model (the PCVs: xr4000 with 4
casters, comr3 with 3).

Tolerance: the two sum the same products in a different order (numpy's
matmul against a running sum), so they agree to rounding. Measured over these
inputs, relative to the largest entry: Lambda <= 6.6e-16, mu <= 1.5e-14 (its
body terms partly cancel), the distribution bitwise equal; asserted 1e-12.

The terms have a compiled twin (``_hot_path.pcv_terms``): every test of the
terms runs on both paths (``HOLONOMIC_HOT_PATH`` pure and compiled), and
test_hot_path checks that the two are bitwise equal.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from holonomic_core import hot_path
from holonomic_core.model import load_model
from pcv_base.dynamics import PcvDynamics
from pcv_base.torque_distribution import torque_distribution
from holonomic_testing.pcv_numpy_reference import (RefLaw, ref_caster_jacobians, ref_terms,
                                                   ref_torque_distribution)

TOL = 1e-12


# -- inputs -------------------------------------------------------------------------------
def configurations(n_casters, rng, count=300):
    """Joint positions [rad]: random steering in [-pi, pi] and wheel angles,
    then every caster at each of the angles where sin or cos vanish, and far
    from zero (1e6 rad: large-argument sin/cos), all with the same wheel angles."""
    for _ in range(count):
        yield rng.uniform(-math.pi, math.pi, 2 * n_casters)
    for phi in (0.0, math.pi / 2, -math.pi / 2, math.pi, 1e6):
        q = rng.uniform(-math.pi, math.pi, 2 * n_casters)
        q[0::2] = phi
        yield q


def twists(rng):
    """Body twists [m/s, m/s, rad/s]: none (mu = 0), rest, pure spin, pure
    translation, random up to 2 m/s and 3 rad/s."""
    yield None
    yield np.zeros(3)
    yield np.array([0.0, 0.0, 2.5])
    yield np.array([1.2, -0.7, 0.0])
    yield rng.uniform(-2.0, 2.0, 3) * (1.0, 1.0, 1.5)


def assert_close(new, ref):
    scale = max(float(np.max(np.abs(ref))), 1e-300)
    assert np.max(np.abs(np.asarray(new) - ref)) <= TOL * scale, (new, ref)


@pytest.fixture(params=[("xr4000", 4, "pure"), ("comr3", 3, "pure"),
                        ("xr4000", 4, "compiled"), ("comr3", 3, "compiled")],
                ids=["xr4000-pure", "comr3-pure", "xr4000-compiled", "comr3-compiled"])
def dynamics(request, monkeypatch):
    """The loops run over the robot's n casters, not a fixed 4; built on the
    pure-Python or the compiled path (the env var is read when it is built)."""
    robot, n_casters, path = request.param
    monkeypatch.setenv(hot_path.ENV, path)
    dyn = PcvDynamics.from_model(load_model(robot))
    assert len(dyn.kin.casters) == n_casters
    # a twist of four values: the compiled twin checks the length itself
    # (its message shows the call went there), Python's unpacking refuses it
    message = "twist: exactly 3 values" if path == "compiled" else "too many values to unpack"
    with pytest.raises(ValueError, match=message):
        dyn.terms(np.zeros(2 * n_casters), (0.0, 0.0, 0.0, 0.0))
    return dyn


def test_terms_match_the_numpy_reference(dynamics):
    rng = np.random.default_rng(24)
    n = len(dynamics.kin.casters)
    for q in configurations(n, rng):
        for twist in twists(rng):
            lam, mu = dynamics.terms(q, twist)
            lam_ref, mu_ref = ref_terms(dynamics, q, twist)
            assert lam.shape == (3, 3) and mu.shape == (3,)
            assert_close(lam, lam_ref)
            assert_close(mu, mu_ref)
            assert np.array_equal(lam, lam.T)           # Lambda is symmetric by construction


def test_terms_accept_lists_and_tuples(dynamics):
    """The controller passes numpy arrays; the public API also takes sequences."""
    rng = np.random.default_rng(7)
    q = rng.uniform(-3, 3, 2 * len(dynamics.kin.casters))
    lam_ref, mu_ref = ref_terms(dynamics, q, (0.3, -0.2, 0.9))
    lam, mu = dynamics.terms(list(q), (0.3, -0.2, 0.9))
    assert_close(lam, lam_ref)
    assert_close(mu, mu_ref)


def test_body_jacobians_match_the_numpy_reference(dynamics):
    rng = np.random.default_rng(3)
    for i in range(len(dynamics.kin.casters)):
        for phi in rng.uniform(-4.0, 4.0, 50):
            for new, ref in zip(dynamics._caster_jacobians(i, phi),
                                ref_caster_jacobians(dynamics, i, phi)):
                assert new.shape == ref.shape
                assert_close(new, ref)


def test_torque_distribution_matches_the_numpy_reference(dynamics):
    rng = np.random.default_rng(14)
    kin = dynamics.kin
    for q in configurations(len(kin.casters), rng):
        for force in (rng.uniform(-200.0, 200.0, 3), np.array([50.0, 0.0, 0.0]),
                      np.array([0.0, 0.0, -30.0])):
            tau = torque_distribution(kin, q, force)
            assert tau.shape == (2 * len(kin.casters),)
            assert_close(tau, ref_torque_distribution(kin, q, force))


@pytest.mark.parametrize("path", ["pure", "compiled"])
@pytest.mark.parametrize("robot", ["xr4000", "comr3"])
def test_torque_law_matches_the_numpy_reference(robot, path, monkeypatch):
    """OperationalSpaceController.step as BaseController builds it, cycle by
    cycle against the reference law: a smooth drive, then the base held back
    (the reference pulled to MAX_ERROR) and a NaN twist (zero torques)."""
    from holonomic_core.config import load_config
    from holonomic_core.torque import OperationalSpaceController

    monkeypatch.setenv(hot_path.ENV, path)
    cfg = load_config(robot, {"control_mode": "torque"})
    c, model = cfg.controller, cfg.model
    efforts = [j.max_effort for j in model.joint_limits]
    law = OperationalSpaceController(model, c.torque_kp, c.torque_kv, efforts)
    ref = RefLaw(law.dynamics, c.torque_kp, c.torque_kv, efforts, (0.5, -0.2, 0.3))
    law.reset((0.5, -0.2, 0.3))
    rng = np.random.default_rng(5)
    n, dt = len(model.joint_names), 1.0 / c.control_rate
    q = rng.uniform(-math.pi, math.pi, n)
    pose = np.array([0.5, -0.2, 0.3])
    for k in range(400):
        q += rng.uniform(-0.02, 0.02, n)
        twist = rng.uniform(-0.5, 0.5, 3)
        if k == 300:
            twist[1] = np.nan
        if k < 200:                     # following: the pose moves with the twist
            pose = pose + twist * dt
        command = (1.5, 0.3, 3.0)       # held from k = 200: the reference runs ahead
        tau = law.step(q, pose, twist, command, dt)
        tau_ref = ref.step(q, pose, twist, command, dt)
        if k == 300:
            assert not tau.any() and not tau_ref.any()
        assert_close(tau, tau_ref)
        assert_close(law.ref_pose, ref.ref_pose)
    # the held base's reference was pulled back: x error at MAX_ERROR (0.15 m)
    # (a 200-cycle hold at 1.5 m/s is 0.3 m at 1 kHz, 1.5 m at 200 Hz)
    e_pose, _ = law.errors(pose, twist)
    assert abs(e_pose[0]) == pytest.approx(0.15, abs=1e-3)


def test_torque_distribution_refuses_a_reading_of_the_wrong_length(dynamics):
    """As the numpy form did (a broadcasting error): no torques computed for
    casters the reading does not describe."""
    n = len(dynamics.kin.casters)
    with pytest.raises(ValueError):
        torque_distribution(dynamics.kin, np.zeros(2 * n - 2), (10.0, 0.0, 0.0))
    with pytest.raises(ValueError):
        torque_distribution(dynamics.kin, np.zeros(2 * n + 2), (10.0, 0.0, 0.0))
