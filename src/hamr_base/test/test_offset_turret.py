"""DDROT (HAMR) kinematics: derivation checks, identities, the paper's facts."""

import math

import numpy as np
import pytest

from hamr_base.offset_turret import OffsetTurretKinematics
from holonomic_core.model import load_model
from holonomic_core.schema import ConfigError

HAMR = dict(wheel_radius=0.0615, half_wheel_separation=0.1641, turret_offset=0.1641)
# a != b, so that a formula that mixes up the half wheel separation a and the
# turret offset b cannot pass: the paper's b = 2a design (Fig. 9) and a
# turret closer to the axle than the wheels (b = a / 2)
B_IS_2A = dict(wheel_radius=0.0615, half_wheel_separation=0.1641, turret_offset=0.3282)
B_IS_HALF_A = dict(wheel_radius=0.05, half_wheel_separation=0.2, turret_offset=0.1)
# a sweep of turret angles like HSR's twin-caster test: -360..360 deg
TURRET_SWEEP = np.radians(np.arange(-360.0, 361.0, 15.0))
#: the inverse kinematics have a compiled twin: the tests of them run on both
#: ([pure], [compiled]: the hot_path_mode fixture of holonomic_testing)
BOTH_PATHS = pytest.mark.usefixtures("hot_path_mode")


def turret_pose(state, b):
    """Pose (x, y, heading) of the turret axis / base_link for a drive base at
    axle midpoint (mx, my) with heading psi and turret angle phi."""
    mx, my, psi, phi = state
    return np.array([mx + b * math.cos(psi), my + b * math.sin(psi), psi + phi])


def numeric_body_twist(kin, state, rates, h=1e-6):
    """Differentiate the rigid-body motion: move the drive base as a
    differential drive for h seconds, then express the turret's velocity
    in base_link. Independent of the implementation under test."""
    wl, wr, dphi = rates
    v = kin.r * (wl + wr) / 2.0
    wd = kin.r * (wr - wl) / (2.0 * kin.a)
    mx, my, psi, phi = state
    nxt = (mx + h * v * math.cos(psi), my + h * v * math.sin(psi), psi + h * wd, phi + h * dphi)
    prv = (mx - h * v * math.cos(psi), my - h * v * math.sin(psi), psi - h * wd, phi - h * dphi)
    dpose = (turret_pose(nxt, kin.b) - turret_pose(prv, kin.b)) / (2 * h)
    th = psi + phi
    c, s = math.cos(th), math.sin(th)
    return np.array([c * dpose[0] + s * dpose[1], -s * dpose[0] + c * dpose[1], dpose[2]])


@pytest.fixture(params=[HAMR, B_IS_2A, B_IS_HALF_A], ids=["a=b", "b=2a", "b=a/2"])
def kin(request):
    return OffsetTurretKinematics(**request.param)


@BOTH_PATHS
def test_inverse_then_forward_is_identity_over_turret_sweep(kin):
    rng = np.random.default_rng(1)
    for phi in TURRET_SWEEP:
        for _ in range(5):
            twist = rng.uniform(-1.5, 1.5, 3)
            q = np.array([rng.normal(), rng.normal(), phi])
            rates = kin.inverse(q, twist)
            for est in ("slip_min", "pinv", "robust"):
                np.testing.assert_allclose(kin.forward(q, rates, est), twist, atol=1e-12)


@BOTH_PATHS
def test_forward_then_inverse_is_identity(kin):
    rng = np.random.default_rng(2)
    for phi in TURRET_SWEEP:
        rates = rng.uniform(-20, 20, 3)
        q = np.array([0.0, 0.0, phi])
        np.testing.assert_allclose(kin.inverse(q, kin.forward(q, rates)), rates, atol=1e-10)


def test_forward_matches_numeric_differentiation_of_the_rigid_body():
    rng = np.random.default_rng(3)
    for _ in range(50):
        kin = OffsetTurretKinematics(*rng.uniform(0.03, 0.5, 3))
        state = (rng.normal(), rng.normal(), rng.uniform(-math.pi, math.pi),
                 rng.uniform(-2 * math.pi, 2 * math.pi))
        rates = rng.uniform(-10, 10, 3)
        q = np.array([0.0, 0.0, state[3]])
        np.testing.assert_allclose(kin.forward(q, rates), numeric_body_twist(kin, state, rates),
                                   atol=1e-7)


def test_jacobian_matches_forward_and_numeric_derivative(kin):
    rng = np.random.default_rng(4)
    for phi in TURRET_SWEEP:
        q = np.array([0.0, 0.0, phi])
        J = kin.jacobian(q)
        rates = rng.uniform(-5, 5, 3)
        np.testing.assert_allclose(J @ rates, kin.forward(q, rates), atol=1e-12)
        # numeric Jacobian column by column from the rigid-body motion
        Jn = np.column_stack([numeric_body_twist(kin, (0, 0, 0.3, phi), e) for e in np.eye(3)])
        np.testing.assert_allclose(J, Jn, atol=1e-7)


def test_paper_equation_1_with_sin_cos_fixed_is_our_model_in_the_papers_frame(kin):
    """Eq. 1 prints 's = cos, c = sin'. With s = sin, c = cos it is our
    model once expressed in the paper's frame: X = -vy (right), Y = vx,
    Phi = wz; wheel 1 = right, wheel 2 = left; theta_s = -turret_joint."""
    rng = np.random.default_rng(5)
    for phi in TURRET_SWEEP:
        wl, wr, dphi = rng.uniform(-10, 10, 3)
        vx, vy, wz = kin.forward(np.array([0, 0, phi]), np.array([wl, wr, dphi]))
        X, Y, Phi = kin.paper_jacobian(-phi) @ np.array([wr, wl, -dphi])
        np.testing.assert_allclose([X, Y, Phi], [-vy, vx, wz], atol=1e-12)


def test_printed_equation_1_with_s_equal_cos_is_not_a_rigid_body(kin):
    """The typo as printed (s = cos, c = sin, i.e. the sin/cos form evaluated
    at pi/2 - theta_s) disagrees with the rigid-body motion."""
    phi = 0.4
    wl, wr, dphi = 3.0, -2.0, 1.0
    vx, vy, wz = kin.forward(np.array([0, 0, phi]), np.array([wl, wr, dphi]))
    typo = kin.paper_jacobian(math.pi / 2 - (-phi)) @ np.array([wr, wl, -dphi])
    assert not np.allclose(typo, [-vy, vx, wz], atol=1e-3)


def test_xy_shadow_of_the_mobility_ellipsoid_is_circular_when_a_equals_b():
    """Image of the unit ball of joint rates, projected on (vx, vy): the
    ellipse with shape P J J^T P^T. Its (vx, vy) block is
    2k^2 [[a^2 c^2 + b^2 s^2, cs(b^2 - a^2)], [cs(b^2 - a^2), a^2 s^2 + b^2 c^2]]
    with k = r / 2a: a multiple of the identity iff a = b (for every phi)."""
    equal = OffsetTurretKinematics(0.0615, 0.1641, 0.1641)
    unequal = OffsetTurretKinematics(0.0615, 0.1641, 0.25)
    for phi in TURRET_SWEEP:
        q = np.array([0, 0, phi])
        M = equal.jacobian(q)[:2] @ equal.jacobian(q)[:2].T
        expected = 2 * (0.0615 / (2 * 0.1641)) ** 2 * 0.1641 ** 2
        np.testing.assert_allclose(M, expected * np.eye(2), atol=1e-12)
        eig = np.linalg.eigvalsh(unequal.jacobian(q)[:2] @ unequal.jacobian(q)[:2].T)
        assert eig[1] / eig[0] > 1.5


def test_determinant_vanishes_with_turret_offset():
    """det J = r^2 b / (2a): the DDROT is singular (not holonomic) at b = 0."""
    for b in (0.3, 0.1, 1e-3, 1e-6):
        kin = OffsetTurretKinematics(0.0615, 0.1641, b)
        for phi in (0.0, 1.0, -2.5):
            det = np.linalg.det(kin.jacobian(np.array([0, 0, phi])))
            assert det == pytest.approx(0.0615 ** 2 * b / (2 * 0.1641), rel=1e-9)


@pytest.mark.parametrize("key,kwargs", [
    ("ddrot.turret_offset", dict(HAMR, turret_offset=0.0)),
    ("ddrot.wheel_radius", dict(HAMR, wheel_radius=-0.05)),
    ("ddrot.half_wheel_separation", dict(HAMR, half_wheel_separation=0.0)),
    ("ddrot.wheel_radius", dict(HAMR, wheel_radius=float("nan"))),
])
def test_invalid_geometry_is_rejected_naming_the_parameter(key, kwargs):
    with pytest.raises(ConfigError) as err:
        OffsetTurretKinematics(**kwargs)
    assert err.value.key == key
    assert key in str(err.value)
    # only a zero turret offset is explained as the loss of holonomy
    assert ("not holonomic" in str(err.value)) == (key == "ddrot.turret_offset")


@pytest.mark.parametrize("key, value, allowed", [
    ("ddrot.wheel_radius", 100.5, "(0, 100]"),                 # over 100 m
    ("body.drive_base.mass", 0.0, None),                       # not > 0
    # a wheel of radius 0 is refused by the schema, whose message gives the
    # open lower bound, not later by the constructor
    ("ddrot.wheel_radius", 0.0, "(0, 100]"),
    ("ddrot.left_wheel_radius", 0.0, "(0, 100]"),
    ("ddrot.half_wheel_separation", 0.0, "(0, 100]"),
    # b = 0 passes the schema (closed lower bound) for the constructor to
    # explain; over 100 m it is refused like the other lengths
    ("ddrot.turret_offset", 100.5, "[0, 100]"),
])
def test_geometry_out_of_range_is_refused_by_the_schema(key, value, allowed):
    from holonomic_core.config import load_config
    with pytest.raises(ConfigError) as err:
        load_config("hamr", {key: value})
    assert err.value.key == key
    if allowed is not None:
        assert f"expected a number in {allowed}" in str(err.value)


def test_estimate_is_exact_with_an_empty_read_only_residual(kin):
    q, rates = np.array([0.0, 0.0, 0.4]), np.array([3.0, -2.0, 1.0])
    twist, residual = kin.estimate(q, rates)
    np.testing.assert_allclose(twist, kin.forward(q, rates), atol=0)
    # a square Jacobian leaves nothing to fit: no residual; the one empty
    # array is shared by every call, so nobody may write into it
    assert residual.shape == (0,) and not residual.flags.writeable
    with pytest.raises(ValueError, match=r"^estimator must be one of \('slip_min'"):
        kin.forward(q, rates, "kalman")


def test_zero_turret_offset_in_a_config_file_is_rejected(tmp_path):
    text = (load_model_path_text()).replace("turret_offset: 0.1641", "turret_offset: 0.0")
    path = tmp_path / "flat_turret.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match="ddrot.turret_offset"):
        load_model(path)


def load_model_path_text():
    from holonomic_core.config import resolve_config
    return resolve_config("hamr").read_text()


@BOTH_PATHS
def test_load_model_hamr_follows_the_contract():
    model = load_model("hamr")
    assert model.kind == "ddrot" and OffsetTurretKinematics.kind == "ddrot"
    assert model.joint_names == ("left_wheel_joint", "right_wheel_joint", "turret_joint")
    kin = model.kinematics
    assert (kin.r, kin.a, kin.b) == (0.0615, 0.1641, 0.1641)
    np.testing.assert_allclose(model.max_joint_velocity, [20.0, 20.0, math.radians(270)],
                               rtol=1e-3)
    # pure forward at 1 m/s with the drive base aligned: both wheels at 1/r
    rates = model.inverse([0, 0, 0], [1.0, 0, 0])
    np.testing.assert_allclose(rates, [1 / 0.0615, 1 / 0.0615, 0.0], atol=1e-12)
    # spin in place: base_link's origin (the turret axis) must stay put, so
    # the drive base does not move and only the turret turns
    np.testing.assert_allclose(model.inverse([0, 0, 0], [0, 0, 1.0]), [0, 0, 1.0], atol=1e-12)
    # strafe left at 0.1 m/s, aligned: the drive base turns at vy/b (the turret
    # axis swings on the lever b), wheels differential by a*wd/r, turret counter-rotates
    wd = 0.1 / 0.1641
    np.testing.assert_allclose(model.inverse([0, 0, 0], [0, 0.1, 0]),
                               [-0.1641 * wd / 0.0615, 0.1641 * wd / 0.0615, -wd], atol=1e-12)


@BOTH_PATHS
def test_unequal_wheels_turn_the_drive_base_by_their_rim_speed_difference():
    # both wheels at 10 rad/s, left r = 0.06, right r = 0.063: rim speeds 0.6
    # and 0.63 m/s, so v = 0.615 m/s and wd = (0.63 - 0.6) / (2 a) with
    # a = 0.15: 0.1 rad/s; at phi = 0 the turret axis (b = 0.2 ahead) also
    # moves sideways at b wd = 0.02 m/s
    kin = OffsetTurretKinematics(0.0615, 0.15, 0.2, left_wheel_radius=0.06,
                                 right_wheel_radius=0.063)
    q = np.zeros(3)
    np.testing.assert_allclose(kin.forward(q, [10.0, 10.0, 0.0]), [0.615, 0.02, 0.1],
                               atol=1e-12)
    # and back: that twist needs both wheels at 10 rad/s, the turret still
    # (an inverse that divides the left rim speed by the right radius gives
    # 0.6 / 0.063 = 9.52 and 0.63 / 0.06 = 10.5 rad/s)
    np.testing.assert_allclose(kin.inverse(q, [0.615, 0.02, 0.1]), [10.0, 10.0, 0.0],
                               atol=1e-12)
    rng = np.random.default_rng(7)
    for phi in TURRET_SWEEP:
        twist = rng.uniform(-1, 1, 3)
        q = np.array([0.0, 0.0, phi])
        np.testing.assert_allclose(kin.forward(q, kin.inverse(q, twist)), twist, atol=1e-12)
        np.testing.assert_allclose(kin.jacobian(q) @ kin.inverse(q, twist), twist, atol=1e-12)


def test_per_wheel_radii_default_to_the_shared_radius():
    model = load_model("hamr", {"ddrot.right_wheel_radius": 0.062})
    assert (model.kinematics.r_left, model.kinematics.r_right) == (0.0615, 0.062)


# Hand-derived inverse with a != b, from eq. 1 (s = sin, c = cos) in the
# paper's frame (X lateral right = -vy, Y forward = vx, Phi = wz; theta_1 =
# right wheel, theta_2 = left wheel, theta_s = -turret_joint), for
# r = 0.05, a = 0.2, b = 0.1 (B_IS_HALF_A), so r/(2a) = 0.125, r b/(2a) = 0.0125:
#
# * strafe left vy = 0.1 at theta_s = 0 (s = 0, c = 1): X = -0.1, Y = Phi = 0.
#   Row 2: Y = r/2 (wR + wL) = 0 -> wL = -wR. Row 1: X = -r b/(2a) (wR - wL)
#   = -0.025 wR = -0.1 -> wR = 4, wL = -4. Row 3: Phi = r/(2a) (wR - wL) -
#   theta_s_dot = 1 - theta_s_dot = 0 -> theta_s_dot = 1, turret rate -1 rad/s.
#   (Dividing by a instead of b would give wheels -+2 rad/s, turret -0.5.)
# * forward vx = 0.2 with the drive base turned 90 deg left of the turret
#   (turret_joint = -pi/2, theta_s = pi/2, s = 1, c = 0): X = 0, Y = 0.2.
#   Row 1: X = -r a/(2a) wR - r a/(2a) wL = -0.025 (wR + wL) = 0 -> wL = -wR.
#   Row 2: Y = -r b/(2a) wR + r b/(2a) wL = -0.0125 * 2 wR = 0.2 -> wR = -8,
#   wL = 8. Row 3: Phi = 0.125 (-16) - theta_s_dot = 0 -> theta_s_dot = -2,
#   turret rate +2 rad/s: the drive base turns clockwise at 2 rad/s = vx / b.
# * spin in place wz = 1: the turret axis must not move, so the wheels stand
#   still and the turret turns at 1 rad/s, for any a and b.
@BOTH_PATHS
@pytest.mark.parametrize("phi, twist, expected", [
    (0.0, (0.0, 0.1, 0.0), (-4.0, 4.0, -1.0)),
    (-math.pi / 2, (0.2, 0.0, 0.0), (8.0, -8.0, 2.0)),
    (0.7, (0.0, 0.0, 1.0), (0.0, 0.0, 1.0)),
])
def test_inverse_with_unequal_separation_and_offset_matches_hand_derivation(phi, twist, expected):
    kin = OffsetTurretKinematics(**B_IS_HALF_A)
    np.testing.assert_allclose(kin.inverse(np.array([0.0, 0.0, phi]), np.array(twist)),
                               expected, atol=1e-12)
    # and the forward map takes the rates back to the twist
    np.testing.assert_allclose(kin.forward(np.array([0.0, 0.0, phi]), np.array(expected)),
                               twist, atol=1e-12)
