"""The static analysis of a swerve base (holonomic_analysis.rolling) against
hand-derived values.

swerve4: modules fl (0.25, 0.25), rl (-0.25, 0.25), rr (-0.25, -0.25),
fr (0.25, -0.25) [m], wheel radius r = 0.075 m, wheel limit 22 rad/s (so
R = r * 22 = 1.65 m/s per module), steering limit 8 rad/s, no
limits.linear.max_speed. |p_i| = 0.25 sqrt(2) = 0.35355 m.

Module i admits the twist x = (vx, vy, wz) only if its contact point has no
velocity across its wheel: (-sin phi_i, cos phi_i, x_i cos phi_i + y_i sin
phi_i) . x = 0.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from holonomic_analysis import holonomicity, mobility, rolling
from holonomic_analysis.cli import main as analyze_main
from holonomic_core.model import load_model
from swerve_base.swerve import Module, SwerveKinematics

R_WHEEL, WHEEL, STEER = 0.075, 22.0, 8.0
TOP = R_WHEEL * WHEEL                     # 1.65 m/s: one module's top speed
ARM = 0.25 * math.sqrt(2.0)               # |p_i| [m]
#: every module tangent to its circle about the centre (CCW rolling direction
#: (-y, x)): fl 135 deg, rl -135 deg, rr -45 deg, fr 45 deg
TANGENT = [3 * math.pi / 4, -3 * math.pi / 4, -math.pi / 4, math.pi / 4]


def swerve4(**overrides):
    return load_model("swerve4", overrides)


def at(model, steer):
    return mobility.analyze(model, mobility.configuration(model, steer))


def constraints(model, steer):
    return rolling.RollingConstraints(model.kinematics, mobility.configuration(model, steer),
                                      model.max_joint_velocity)


# -- at the configuration ----------------------------------------------------------------------
def test_aligned_modules_allow_only_the_translation_along_their_wheels():
    # phi = 0: rows (0, 1, x_i), x_i = +-0.25 -> rank 2, K = span{(1, 0, 0)}.
    # Along it every wheel turns at v / r: the top speed is r * 22 = 1.65 m/s;
    # normalised rates (1/r)/22 per m/s on 4 wheels give |W J| = 2 / 1.65,
    # the ellipsoid's one semi-axis 1.65 / 2 = 0.825 m/s.
    inst = at(swerve4(), [0.0] * 4)["instantaneous"]
    assert inst["mobility_dimension"] == 1
    assert inst["mobility_basis"] == [pytest.approx([1.0, 0.0, 0.0], abs=1e-12)]
    assert inst["translation"]["direction"] == pytest.approx(0.0, abs=1e-12)
    assert inst["translation"]["speed"] == pytest.approx(TOP)
    assert inst["ellipsoid_semi_axes"] == pytest.approx([TOP / 2, 0.0, 0.0])
    assert inst["H_hat"] == 0.0


def test_modules_steered_sideways_allow_only_the_sideways_translation():
    # phi = pi/2: rows (-1, 0, y_i) -> K = span{(0, 1, 0)}: a strafe at 1.65 m/s
    inst = at(swerve4(), [math.pi / 2] * 4)["instantaneous"]
    assert inst["mobility_basis"] == [pytest.approx([0.0, 1.0, 0.0], abs=1e-12)]
    assert inst["translation"]["direction"] == pytest.approx(math.pi / 2)
    assert inst["translation"]["speed"] == pytest.approx(TOP)


def test_tangent_modules_allow_only_the_spin_about_the_centre():
    # every axle line through the origin: the ICR is the centre, K = span{(0, 0, 1)}.
    # A spin at wz moves each wheel at |p| wz: the joint limits allow
    # 1.65 / 0.35355 = 4.667 rad/s, the ellipsoid's semi-axis half of it.
    rc = constraints(swerve4(), TANGENT)
    inst = rc.instantaneous()
    assert inst["mobility_basis"] == [pytest.approx([0.0, 0.0, 1.0], abs=1e-12)]
    assert inst["translation"] is None
    assert inst["ellipsoid_semi_axes"] == pytest.approx([TOP / ARM / 2, 0.0, 0.0])
    assert rc.joint_rates([0.0, 0.0, 1.0])[1::2] == pytest.approx([ARM / R_WHEEL] * 4)


def test_one_module_off_the_common_field_locks_the_base():
    # fl at 0.3 rad: its axle line meets fr's line x = 0.25 only at fl itself,
    # which rl and rr's line x = -0.25 misses: no common ICR, K = {0}
    out = at(swerve4(), [0.3, 0.0, 0.0, 0.0])
    assert out["instantaneous"]["mobility_dimension"] == 0
    assert out["instantaneous"]["ellipsoid_semi_axes"] == [0.0, 0.0, 0.0]
    assert out["sigma_ratio"] == 0.0


def test_two_modules_on_one_axle_line_are_a_differential_drive():
    # modules at (0, +-0.25), both rolling along x: both rows are (0, 1, 0), rank 1,
    # K = span{(1, 0, 0), (0, 0, 1)} -- forward and turning, never sideways
    kin = SwerveKinematics([Module("l", 0.0, 0.25, R_WHEEL), Module("r", 0.0, -0.25, R_WHEEL)])
    rc = rolling.RollingConstraints(kin, np.zeros(4), np.full(4, WHEEL))
    assert rc.dimension == 2
    assert np.allclose(rc.constraint @ [1.0, 0.0, 0.0], 0)
    assert np.allclose(rc.constraint @ [0.0, 0.0, 1.0], 0)
    assert not np.allclose(rc.constraint @ [0.0, 1.0, 0.0], 0)
    assert rc.instantaneous()["translation"]["speed"] == pytest.approx(TOP)


def test_sigma_ratio_is_zero_where_the_least_squares_estimator_has_full_rank():
    # At the tangent configuration the odometry's least-squares C_p^+ U maps
    # 4 wheel rates onto all 3 twist components (a slipping set of rates has a
    # lateral fit), so its sigma_min > 0 would call the base holonomic there;
    # the rates the rolling constraints admit move it along K only (1-D).
    model = swerve4()
    q = mobility.configuration(model, TANGENT)
    assert np.linalg.svd(model.jacobian(q), compute_uv=False)[-1] > 0.01
    assert at(model, TANGENT)["sigma_ratio"] == 0.0
    # aligned: x = B (U^+ C_p B)^+ q_dot; U^+ C_p B = 1/r on the 4 wheels, norm 2 / r,
    # so the one non-zero singular value is r / 2
    s = np.linalg.svd(constraints(model, [0.0] * 4).no_slip_jacobian(), compute_uv=False)
    assert s == pytest.approx([R_WHEEL / 2, 0.0, 0.0], abs=1e-12)


# -- with reorientation ------------------------------------------------------------------------
@pytest.mark.parametrize("steer", [[0.0] * 4, [0.3, 0.0, 0.0, 0.0], TANGENT])
def test_reoriented_every_direction_has_the_wheels_top_speed(steer):
    # a translation moves every module at the base's speed: the disc |v| <= 1.65,
    # H_hat 1 at any starting configuration; the spin: 1.65 / 0.35355 = 4.667 rad/s
    out = at(swerve4(), steer)
    assert out["H_hat"] == pytest.approx(1.0)
    assert out["constant_heading_speed"] == pytest.approx({"slowest": TOP, "fastest": TOP})
    for key in ("forward", "forward_constant_heading", "lateral", "lateral_constant_heading"):
        assert out["max_speed"][key] == pytest.approx(TOP, rel=1e-6)
    assert out["max_speed"]["rotation"] == pytest.approx(TOP / ARM)
    # the image of the unit ball of normalised module speeds, sum |C_i x|^2 / R^2 <= 1:
    # diag(4, 4, 4 |p|^2) / R^2 -> semi-axes R/(2|p|), R/2, R/2
    assert out["ellipsoid_semi_axes"] == pytest.approx([TOP / ARM / 2, TOP / 2, TOP / 2])


def test_turning_while_moving_beats_a_slow_module():
    # fl's wheel limited to 11 rad/s (R_fl = 0.825 m/s, rl the same by the mirror
    # below). At constant heading the disc shrinks to 0.825 m/s (H_hat stays 1).
    # Forward with the heading free, u = 0.25 wz: fl and rl move at
    # sqrt((t - u)^2 + u^2), fr and rr at sqrt((t + u)^2 + u^2) (x_i enters squared).
    # Neither ellipse's own optimum fits the other, so both bind:
    # (t-u)^2+u^2 = 0.825^2, (t+u)^2+u^2 = 1.65^2 -> 4tu = 2.041875,
    # 2t^2 + 4u^2 = 3.403125 -> 2t^4 - 3.403125 t^2 + 1.042313 = 0 -> t = 1.1406 m/s.
    model = swerve4(**{"joints.fl_wheel_joint.max_velocity": 11.0,
                       "joints.rl_wheel_joint.max_velocity": 11.0})
    out = at(model, [0.0] * 4)
    assert out["H_hat"] == pytest.approx(1.0)
    assert out["max_speed"]["forward_constant_heading"] == pytest.approx(0.825)
    assert out["max_speed"]["forward"] == pytest.approx(1.1406, abs=2e-4)


def test_a_speed_norm_caps_the_reoriented_translations_not_the_spin():
    out = mobility.analyze(swerve4(), mobility.configuration(swerve4()), max_speed=1.2)
    assert out["max_speed"]["forward"] == 1.2 and out["max_speed"]["lateral"] == 1.2
    assert out["max_speed"]["rotation"] == pytest.approx(TOP / ARM)
    assert out["H_hat"] == 1.0
    assert out["instantaneous"]["translation"]["speed"] == 1.2


def test_measured_h_falls_to_zero_as_the_move_shrinks_unlike_the_speed_ratio():
    # d_T = 0.01 m, kinematic limit: straight ahead takes about 0.01 / 1.65 s plus
    # a cycle, a sideways move first turns the modules pi/2 at <= 8 rad/s
    # (>= 0.196 s): H <= 0.011 / 0.196 < 0.06, while H_hat (speeds) is 1
    m = holonomicity.measure("swerve4", 0.01, 4, [0.0], "mock",
                             holonomicity.kinematic_overrides("swerve4"))
    sideways = [mv.seconds for mv in m.moves if abs(abs(mv.alpha) - math.pi / 2) < 1e-6]
    assert min(sideways) >= (math.pi / 2) / STEER
    assert m.H < 0.06


# -- the command line --------------------------------------------------------------------------
def test_cli_prints_the_swerves_numbers(capsys):
    assert analyze_main(["swerve4", "--json", "--steer", "1.5708,1.5708,1.5708,1.5708"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["robot"] == "swerve4"
    assert out["H_hat"] == pytest.approx(1.0) and out["sigma_ratio"] == 0.0
    assert out["max_speed"]["lateral_constant_heading"] == pytest.approx(TOP, rel=1e-6)
    assert out["max_speed"]["rotation"] == pytest.approx(TOP / ARM)
    assert out["instantaneous"]["translation"]["direction"] == pytest.approx(math.pi / 2,
                                                                            abs=1e-4)
    assert analyze_main(["swerve4"]) == 0
    text = capsys.readouterr().out
    assert "H_hat 1.000 (constant-heading speed 1.650 .. 1.650 m/s) with the wheels " \
           "reoriented" in text
    assert "1-D mobility" in text and "translation only along +0.0 deg, up to 1.650 m/s" in text


def test_cli_plot_of_a_swerve_writes_no_meaningless_ellipsoid(tmp_path, capsys):
    assert analyze_main(["swerve4", "--plot", str(tmp_path)]) == 0
    assert "no ellipsoid figures" in capsys.readouterr().out
    assert not list(tmp_path.glob("*.png"))
