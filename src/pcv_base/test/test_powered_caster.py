"""Powered-caster vehicle kinematics, estimators and torque distribution (ROS-free).

Expected values come from the derivation in pcv_base/powered_caster.py:
contact point p = s - b e, ideal rolling v(p) = r rho_dot e + b phi_dot n.
"""

import math

import numpy as np
import pytest

from holonomic_core.config import load_config
from holonomic_core.limits import joint_rate_saturation
from holonomic_core.model import load_model
from holonomic_core.schema import ConfigError
from pcv_base.powered_caster import Caster, PoweredCasterKinematics
from pcv_base.torque_distribution import torque_distribution

#: every test here runs on both implementations of the cycle's closed forms
#: ([pure], [compiled]: the hot_path_mode fixture of holonomic_testing)
pytestmark = pytest.mark.usefixtures("hot_path_mode")

ESTIMATORS = ("slip_min", "pinv", "robust")


def random_pcv(rng, n):
    """n casters on a ring (distinct, well-separated axes), random r, b, beta."""
    casters = []
    for i in range(n):
        beta = 2 * math.pi * i / n + rng.uniform(-0.3, 0.3)
        casters.append(Caster(f"c{i}", rng.uniform(0.25, 0.4), beta,
                              rng.uniform(0.03, 0.1), rng.uniform(0.01, 0.06)))
    return PoweredCasterKinematics(casters)


def rot(a):
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


@pytest.mark.parametrize("n", [2, 3, 4])
def test_forward_inverts_inverse_for_every_estimator_without_slip(n):
    rng = np.random.default_rng(n)
    for _ in range(100):
        kin = random_pcv(rng, n)
        q = rng.uniform(-2 * math.pi, 2 * math.pi, 2 * n)
        twist = rng.normal(0.0, 1.0, 3)
        rates = kin.inverse(q, twist)
        for est in ESTIMATORS:
            np.testing.assert_allclose(kin.forward(q, rates, est), twist, atol=1e-9)
        np.testing.assert_allclose(kin.fit_residual(q, rates), 0.0, atol=1e-9)


def test_constraint_matrix_is_eq7_and_the_product_cq_cp():
    rng = np.random.default_rng(1)
    kin = random_pcv(rng, 4)
    for _ in range(50):
        q = rng.uniform(-4, 4, 8)
        C = kin.constraint_matrix(q)
        # eq. 7 typed in again, independently, from the paper
        for i, c in enumerate(kin.casters):
            phi, b, r, h, be = q[2 * i], c.caster_offset, c.wheel_radius, c.h, c.beta
            s, co = math.sin(phi), math.cos(phi)
            row_phi = [-s / b, co / b, h * (math.cos(be) * co + math.sin(be) * s) / b - 1]
            row_rho = [co / r, s / r, h * (math.cos(be) * s - math.sin(be) * co) / r]
            np.testing.assert_allclose(C[2 * i], row_phi, atol=1e-12)
            np.testing.assert_allclose(C[2 * i + 1], row_rho, atol=1e-12)
        np.testing.assert_allclose(kin.contact_to_joint(q) @ kin.contact_jacobian(q), C, atol=1e-12)
        np.testing.assert_allclose(kin.contact_to_joint(q) @ kin.joint_to_contact(q), np.eye(8),
                                   atol=1e-12)
        twist = rng.normal(size=3)
        np.testing.assert_allclose(kin.inverse(q, twist), C @ twist, atol=1e-12)
        np.testing.assert_allclose(kin.jacobian(q) @ C, np.eye(3), atol=1e-9)


def test_constraint_rows_are_rigid_body_rolling_without_slip():
    """Move the base by a twist and steer by phi_dot for a tiny dt: the wheel
    centre (above the contact point) must move along the wheel's heading by
    r rho_dot dt and not sideways -- numeric differentiation of the motion."""
    rng = np.random.default_rng(2)
    kin = random_pcv(rng, 3)
    dt = 1e-6
    for _ in range(30):
        q = rng.uniform(-4, 4, 6)
        twist = rng.normal(size=3)
        rates = kin.inverse(q, twist)

        def wheel_centres(t):
            th = twist[2] * t          # base heading (starts at 0)
            # base origin: integrate the body twist (constant in body frame)
            # to first order -- exact enough over dt
            origin = rot(th / 2) @ twist[:2] * t
            phi = q[0::2] + rates[0::2] * t
            local = kin.contact_points(np.column_stack((phi, np.zeros(3))).ravel())
            return np.array([origin + rot(th) @ p for p in local]), phi + th

        before, _ = wheel_centres(-dt)
        after, _ = wheel_centres(dt)
        _, heading = wheel_centres(0.0)
        velocity = (after - before) / (2 * dt)
        for i, c in enumerate(kin.casters):
            e = np.array([math.cos(heading[i]), math.sin(heading[i])])
            n = np.array([-e[1], e[0]])
            assert velocity[i] @ n == pytest.approx(0.0, abs=1e-5)      # no side slip
            assert velocity[i] @ e == pytest.approx(c.wheel_radius * rates[2 * i + 1], abs=1e-5)


def conflict_slip(kin, q, rng, size):
    """Contact velocities with no rigid-body component (orthogonal to range C_p)."""
    cp = kin.contact_jacobian(q)
    v = rng.normal(size=cp.shape[0])
    v -= cp @ np.linalg.lstsq(cp, v, rcond=None)[0]
    return v / np.linalg.norm(v) * size


def test_actuator_conflict_leaves_slip_min_unaffected_while_pinv_errs():
    rng = np.random.default_rng(3)
    model = load_model("xr4000")
    kin = model.kinematics
    err = {"pinv": [], "robust": []}
    for _ in range(50):
        q = rng.uniform(-math.pi, math.pi, 8)
        twist = rng.normal(0, 0.5, 3)
        slip = conflict_slip(kin, q, rng, 0.05)         # 5 cm/s of fighting casters
        rates = kin.inverse(q, twist) + kin.contact_to_joint(q) @ slip
        np.testing.assert_allclose(kin.forward(q, rates, "slip_min"), twist, atol=1e-9)
        for e in err:
            err[e].append(np.linalg.norm(kin.forward(q, rates, e) - twist))
        # the residual reports the slip the estimator could not explain
        assert np.linalg.norm(kin.fit_residual(q, rates)) == pytest.approx(0.05, rel=1e-6)
    assert min(err["pinv"]) > 1e-3 and np.mean(err["pinv"]) > 0.02
    # spread over the casters, 5 cm/s of conflict is no burst: robust is C#
    assert max(err["robust"]) < 1e-9


def test_small_actuator_conflict_leaves_robust_unaffected_too():
    rng = np.random.default_rng(7)
    kin = load_model("xr4000").kinematics
    for _ in range(50):
        q = rng.uniform(-math.pi, math.pi, 8)
        twist = rng.normal(0, 0.5, 3)
        slip = conflict_slip(kin, q, rng, 0.01)          # below ROBUST_SCALE (2 cm/s)
        rates = kin.inverse(q, twist) + kin.contact_to_joint(q) @ slip
        assert np.linalg.norm(kin.forward(q, rates, "robust") - twist) < 1e-3
        assert np.linalg.norm(kin.forward(q, rates, "pinv") - twist) > 2e-4


def test_one_wheel_burst_is_rejected_by_robust():
    rng = np.random.default_rng(4)
    kin = load_model("xr4000").kinematics
    for trial in range(40):
        q = rng.uniform(-math.pi, math.pi, 8)
        twist = rng.normal(0, 0.5, 3)
        rates = kin.inverse(q, twist)
        wheel = 2 * rng.integers(4) + 1
        rates[wheel] += rng.choice([-1, 1]) * rng.uniform(5.0, 20.0)   # spins 0.3-1.1 m/s
        err = {e: np.linalg.norm(kin.forward(q, rates, e) - twist) for e in ESTIMATORS}
        assert err["slip_min"] > 0.05
        assert err["robust"] < 1e-6, (trial, err)
        res = kin.fit_residual(q, rates, "robust")
        assert np.argmax(res) == wheel // 2 and np.sum(res > 1e-6) == 1


def test_robust_leave_one_out_is_the_least_squares_fit_of_the_other_casters():
    """The closed-form deletion formulas against a plain least-squares fit of
    C_p without the rejected caster's rows, on noisy data with one burst."""
    rng = np.random.default_rng(9)
    kin = load_model("xr4000").kinematics
    for _ in range(30):
        q = rng.uniform(-math.pi, math.pi, 8)
        twist = rng.normal(0, 0.5, 3)
        contact = kin.contact_jacobian(q) @ twist + rng.normal(0, 0.002, 8)
        bad = rng.integers(4)
        contact[2 * bad:2 * bad + 2] += rng.uniform(0.3, 1.0) * rng.choice([-1, 1], 2)
        rates = kin.contact_to_joint(q) @ contact
        keep = [k for k in range(8) if k // 2 != bad]
        expected = np.linalg.lstsq(kin.contact_jacobian(q)[keep], contact[keep], rcond=None)[0]
        np.testing.assert_allclose(kin.forward(q, rates, "robust"), expected, atol=1e-9)


def test_robust_matches_slip_min_under_small_noise():
    rng = np.random.default_rng(5)
    kin = load_model("comr3").kinematics
    for _ in range(50):
        q = rng.uniform(-math.pi, math.pi, 6)
        twist = rng.normal(0, 0.5, 3)
        rates = kin.inverse(q, twist) + rng.normal(0, 0.01, 6)
        a, b = kin.forward(q, rates, "slip_min"), kin.forward(q, rates, "robust")
        assert np.linalg.norm(a - b) < 1e-3


def test_unexplained_slip_inflates_the_odometry_covariance():
    from holonomic_core.odometry import Odometry, OdometryNoise
    model = load_model("xr4000")
    kin = model.kinematics
    # a strafe with the wheels aligned to it: constant joint rates, so the
    # clean run has no residual at all (Euler steps are exact)
    twist = np.array([0.4, 0.2, 0.0])
    q0 = np.zeros(8)
    q0[0::2] = math.atan2(0.2, 0.4)
    # slip terms only: position variance per metre of unexplained slip, and
    # twist variance per squared RMS residual
    noise = OdometryNoise(0.0, 0.0, 0.0, slip_position_gain=0.1,
                          slip_heading_gain=0.0, twist_variance=(0.0, 0.0, 0.0),
                          twist_slip_gain=(2.0, 0.0, 0.0), latency_variance=0.0,
                          slip4_position_gain=0.0, slip4_heading_gain=0.0)

    def covariance(conflict):
        odo = Odometry(model, "slip_min", noise)
        q = q0.copy()
        odo.update(q, 0.0)
        for k in range(1, 101):            # 0.5 s at 200 Hz
            rates = kin.inverse(q, twist)
            rates += kin.contact_to_joint(q) @ conflict_slip(kin, q, np.random.default_rng(k),
                                                             conflict)
            q = q + rates * 0.005
            odo.update(q, k * 0.005)
        return odo.pose_covariance[0, 0], odo.twist_covariance[0, 0], odo.residual

    p_clean, t_clean, r_clean = covariance(1e-9)
    p_slip, t_slip, r_slip = covariance(0.02)          # 2 cm/s fighting casters
    assert np.max(r_clean) < 1e-4 and np.linalg.norm(r_slip) == pytest.approx(0.02, rel=0.05)
    # 2 cm/s over 4 casters: RMS residual 1 cm/s; over 0.5 s:
    # 0.1 s x (0.01 m/s)^2 x 0.5 s = 5e-6 m^2; twist 2 x (1 cm/s)^2
    assert p_clean < 1e-9 and t_clean < 1e-9
    assert p_slip == pytest.approx(5e-6, rel=0.1)       # measured 5.26e-6
    assert t_slip == pytest.approx(2e-4, rel=0.1)


def test_torque_distribution_produces_the_wrench_with_least_contact_force():
    rng = np.random.default_rng(6)
    kin = load_model("xr4000").kinematics
    for _ in range(30):
        q = rng.uniform(-math.pi, math.pi, 8)
        force = rng.normal(0, 20, 3)
        tau = torque_distribution(kin, q, force)
        C = kin.constraint_matrix(q)
        np.testing.assert_allclose(C.T @ tau, force, atol=1e-9)   # eq. 9
        # contact forces f with tau = C_q^-T f ... each wheel's tractive force
        # is C_q^T tau; C#^T minimises its norm among all tau with C^T tau = F
        contact = lambda t: kin.contact_to_joint(q).T @ t  # noqa: E731
        other = np.linalg.pinv(C).T @ force            # the Moore-Penrose split
        assert np.linalg.norm(contact(tau)) <= np.linalg.norm(contact(other)) + 1e-9
        # the closed form is eq. 14 itself: C#^T F with C# = C_p^+ C_q^-1
        np.testing.assert_allclose(tau, kin.jacobian(q).T @ force, atol=1e-9)


def test_joint_saturation_keeps_the_direction_of_a_strafe():
    """From casters facing forward, a fast strafe needs steering far over its
    limit: the whole twist is scaled down, in its direction."""
    model = load_model("xr4000")
    q = np.zeros(8)
    twist = np.array([0.0, 1.0, 0.0])
    raw = model.inverse(q, twist)
    assert np.max(np.abs(raw[0::2])) > 40.0               # 1 m/s / 0.02 m = 50 rad/s
    rates, scale = joint_rate_saturation()(raw, model.max_joint_velocity)
    assert np.all(np.abs(rates) <= model.max_joint_velocity + 1e-9)
    assert scale == pytest.approx(12.0 / 50.0)
    # the scaled rates are exactly those of the scaled twist: same direction
    np.testing.assert_allclose(rates, model.inverse(q, twist * scale), atol=1e-12)
    np.testing.assert_allclose(model.forward(q, rates), twist * scale, atol=1e-12)


@pytest.mark.parametrize("robot, n", [("xr4000", 4), ("comr3", 3)])
def test_shipped_configs_load(robot, n):
    model = load_model(robot)
    assert model.kind == "pcv" and len(model.joint_names) == 2 * n
    assert model.joint_names[:2] == (f"{model.kinematics.caster_names[0]}_steer_joint",
                                     f"{model.kinematics.caster_names[0]}_wheel_joint")
    load_config(robot)       # controller and driver keys validate too


def test_per_caster_values_override_the_shared_ones():
    model = load_model("xr4000", {"pcv.rear_left.wheel_radius": 0.06,
                                  "pcv.front_left.caster_offset": 0.03})
    by_name = {c.name: c for c in model.kinematics.casters}
    assert by_name["rear_left"].wheel_radius == 0.06
    assert by_name["front_right"].wheel_radius == 0.055
    assert by_name["front_left"].caster_offset == 0.03


@pytest.mark.parametrize("overrides, key", [
    ({"pcv.caster_offset": 0.0}, "pcv.caster_offset"),
    ({"pcv.front_right.caster_offset": -0.01}, "pcv.front_right.caster_offset"),
    ({"pcv.wheel_radius": 0.0}, "pcv.wheel_radius"),
    ({"pcv.rear_left.h": 0.240416, "pcv.rear_left.beta": 0.785398}, "pcv.rear_left.h"),
    ({"pcv.casters": ["front_left"]}, "pcv.casters"),
    ({"pcv.casters": ["front_left", "front_left"]}, "pcv.casters"),
    ({"pcv.casters": ["front left", "rear_left"]}, "pcv.casters"),
    ({"pcv.casters": [1, 2]}, "pcv.casters"),          # not names: refused, no TypeError
    ({"pcv.front_left.h": 0.05, "pcv.front_left.beta": 0.0,
      "pcv.rear_left.h": 0.05, "pcv.rear_left.beta": 3.14159}, "pcv.rear_left.h"),
])
def test_invalid_geometry_is_rejected_naming_the_key(overrides, key):
    with pytest.raises(ConfigError) as info:
        load_model("xr4000", overrides)
    assert info.value.key == key, str(info.value)


def test_constructor_rejects_fewer_than_two_casters_and_zero_offset():
    with pytest.raises(ConfigError, match="at least 2 casters"):
        PoweredCasterKinematics([Caster("a", 0.2, 0.0, 0.05, 0.02)])
    with pytest.raises(ConfigError, match="not be holonomic|not\\s+be holonomic"):
        PoweredCasterKinematics([Caster("a", 0.2, 0.0, 0.05, 0.0),
                                 Caster("b", 0.2, math.pi, 0.05, 0.02)])


def test_steering_axes_no_further_apart_than_the_two_offsets_are_refused():
    """By hand: casters b and c have their steering axes at (0, 0.1) and
    (0, -0.1), 0.2 m apart; with offsets b = 0.1 m each the circles their
    contact points move on touch (0.2 <= 0.1 + 0.1), so the wheels can meet:
    refused, naming the later caster's h, the bound and the distance. They
    are the 2nd and 3rd of three casters: every pair is checked. Offsets of
    0.099 m leave 2 mm between the circles: accepted."""
    def three(b):
        return [Caster("a", 0.3, 0.0, 0.05, b), Caster("b", 0.1, math.pi / 2, 0.05, b),
                Caster("c", 0.1, -math.pi / 2, 0.05, b)]

    with pytest.raises(ConfigError) as info:
        PoweredCasterKinematics(three(0.1))
    assert info.value.key == "pcv.c.h"
    assert "more than b_b + b_c = 0.2 m from caster b's (it is 0.2 m" in str(info.value)
    assert len(PoweredCasterKinematics(three(0.099)).casters) == 3


def test_steering_axis_at_the_origin_is_valid_and_an_infinite_one_is_not():
    """h = 0 (a caster under the base_link origin) is a valid geometry (the
    check is h >= 0); h = inf or beta = nan is refused, naming the key."""
    kin = PoweredCasterKinematics([Caster("a", 0.0, 0.0, 0.05, 0.02),
                                   Caster("b", 0.3, math.pi, 0.05, 0.02)])
    assert kin.caster_names == ("a", "b")
    for h, beta in ((math.inf, 0.0), (0.3, math.nan)):
        with pytest.raises(ConfigError) as info:
            PoweredCasterKinematics([Caster("a", 0.0, 0.0, 0.05, 0.02),
                                     Caster("b", h, beta, 0.05, 0.02)])
        assert info.value.key == "pcv.b.h"


def test_joint_slices_and_frozen_caster_geometry():
    """Joint order (steer, wheel) per caster: the steering joints are the even
    entries, the wheels the odd ones. A Caster cannot be changed after the
    kinematics copied its numbers (it is frozen)."""
    import dataclasses

    kin = PoweredCasterKinematics([Caster("a", 0.3, 0.0, 0.05, 0.02),
                                   Caster("b", 0.3, math.pi, 0.05, 0.02)])
    q = np.array([0.1, 5.0, 0.2, 6.0])
    np.testing.assert_array_equal(q[kin.steer_indices], [0.1, 0.2])
    np.testing.assert_array_equal(q[kin.wheel_indices], [5.0, 6.0])
    with pytest.raises(dataclasses.FrozenInstanceError):
        kin.casters[0].h = 0.5


@pytest.mark.parametrize("key, value, allowed", [
    ("pcv.wheel_radius", 10.5, "(0, 10]"),
    ("pcv.caster_offset", 10.5, "[0, 10]"),
    ("pcv.front_left.h", 100.5, "[0, 100]"),
    ("pcv.front_left.h", -0.1, "[0, 100]"),
    ("pcv.front_left.beta", 10.5, "[-10, 10]"),
    ("pcv.front_left.beta", -10.5, "[-10, 10]"),
    ("pcv.front_left.wheel_radius", 0.0, "(0, 10]"),
    ("pcv.front_left.wheel_radius", 10.5, "(0, 10]"),
    ("pcv.front_left.caster_offset", 10.5, "[0, 10]"),
])
def test_geometry_out_of_range_is_refused_by_the_schema_with_its_range(key, value, allowed):
    """The README's parameter ranges: lengths up to 10 m (h: 100 m), angles
    within +-10 rad, radii open at 0; offsets closed at 0 so that b = 0
    reaches the constructor's explanation."""
    with pytest.raises(ConfigError) as info:
        load_config("xr4000", {key: value})
    assert info.value.key == key
    assert f"expected a number in {allowed}" in str(info.value)


def test_two_casters_are_enough():
    """Two casters (4 constraints on 3 DOF) make a holonomic base: the
    schema's minimum list length is 2."""
    model = load_model("xr4000", {"pcv.casters": ["front_left", "rear_right"]})
    assert model.joint_names == ("front_left_steer_joint", "front_left_wheel_joint",
                                 "rear_right_steer_joint", "rear_right_wheel_joint")


def test_two_wheels_skidding_at_once_are_not_blamed_on_one():
    """Two casters' wheels spin at once (0.5 and 0.3 m/s of rolling slip):
    leaving either out leaves the other's burst, far more than
    ROBUST_CONCENTRATION (5 %) of the residual energy, so no single caster
    explains the disagreement and robust keeps the slip_min twist exactly
    (rejecting the larger one would move the twist by tenths of m/s)."""
    kin = load_model("xr4000").kinematics
    q = np.array([0.3, 0.0, -0.4, 0.0, 1.0, 0.0, 2.0, 0.0])
    rates = kin.inverse(q, np.array([0.4, -0.2, 0.3]))
    rates[1] += 0.5 / kin.r[0]
    rates[5] += 0.3 / kin.r[2]
    np.testing.assert_array_equal(kin.forward(q, rates, "robust"),
                                  kin.forward(q, rates, "slip_min"))


def test_each_estimators_residual_is_the_contact_slip_its_twist_leaves():
    """By definition (eq. 10 inverted, eq. 11): the sensed contact velocities
    u = C_q^-1 q_dot minus the rigid field C_p x of the estimator's twist x,
    per caster the norm of its 2 rows [m/s]. Computed here with the
    matrices, for joint rates with slip on every caster (so pinv's twist,
    which weighs the rows differently, leaves a different residual)."""
    rng = np.random.default_rng(7)
    kin = load_model("xr4000").kinematics
    q = rng.uniform(-math.pi, math.pi, 8)
    rates = kin.inverse(q, np.array([0.3, 0.1, -0.4])) + rng.normal(0.0, 0.5, 8)
    u = kin.joint_to_contact(q) @ rates
    for estimator in ESTIMATORS:
        twist, residual = kin.estimate(q, rates, estimator)
        rows = u - kin.contact_jacobian(q) @ twist
        expected = np.hypot(rows[0::2], rows[1::2])
        np.testing.assert_allclose(residual, expected, rtol=1e-9, atol=1e-12)
        assert np.all(residual > 1e-3)


def test_a_burst_two_casters_explain_equally_is_not_blamed_on_either():
    """3 casters: the fit's residual space is 3-dimensional and a burst on
    caster i leaves a residual in its plane (I - H) E_i (H = C_p C_p^+,
    E_i: caster i's two rows). Two planes meet along a line; a burst of
    0.5 m/s on caster 0 whose residual lies on the line it shares with
    caster 1 is explained as well by caster 1's burst. Robust cannot tell
    which caster slipped and keeps the slip_min twist exactly."""
    kin = load_model("comr3").kinematics
    q = np.array([0.4, 0.0, -1.1, 0.0, 2.2, 0.0])
    cp = kin.contact_jacobian(q)
    residual_space = np.eye(6) - cp @ np.linalg.pinv(cp)
    planes = [residual_space[:, 2 * i:2 * i + 2] for i in range(3)]
    # a0, b1 with planes[0] a0 = planes[1] b1: the null space of [P0, -P1]
    null = np.linalg.svd(np.hstack((planes[0], -planes[1])))[2][-1]
    burst = np.zeros(6)
    burst[0:2] = null[:2] / np.linalg.norm(null[:2]) * 0.5
    np.testing.assert_allclose(planes[0] @ null[:2], planes[1] @ null[2:], atol=1e-12)
    twist = np.array([0.3, -0.1, 0.2])
    rates = kin.contact_to_joint(q) @ (cp @ twist + burst)
    slip_min = kin.forward(q, rates, "slip_min")
    assert np.linalg.norm(slip_min - twist) > 0.05            # the burst moves slip_min
    np.testing.assert_array_equal(kin.forward(q, rates, "robust"), slip_min)


def test_only_the_slip_min_fit_has_a_compiled_form():
    """The compiled hot path covers the slip_min fit (per caster sx, sy, b,
    r); robust and pinv stay in Python, so they get no compiled geometry."""
    from holonomic_core import hot_path

    kin = load_model("xr4000").kinematics
    kind, geometry = kin.hot_path_geometry("slip_min")
    assert kind == hot_path.KIND_PCV
    np.testing.assert_array_equal(geometry, np.ravel(kin.contact_geometry))
    assert kin.hot_path_geometry("robust") is None and kin.hot_path_geometry("pinv") is None
