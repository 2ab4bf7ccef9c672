"""The analysis tools against the papers' facts (Costa & Yim; Kim & Moon).

Each expected value is derived by hand in a comment; the geometry is HAMR's
(r = 0.0615, a = b = 0.1641, wheels 20 rad/s, turret 4.712 rad/s) unless
the test overrides it.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from holonomic_analysis import holonomicity, isotropy, mobility
from holonomic_analysis.cli import main as analyze_main
from holonomic_core.model import load_model
from holonomic_core.schema import ConfigError

PI = math.pi
R, A, B, WHEEL, TURRET = 0.0615, 0.1641, 0.1641, 20.0, 4.712


def hamr(**overrides):
    return load_model("hamr", overrides)


def analysis(model, **angles):
    return mobility.analyze(model, mobility.configuration(model, **angles))


# -- mobility ellipsoid and speed polytope (Costa & Yim) -------------------------------------
def test_hamr_numbers_follow_from_its_geometry_and_joint_limits():
    result = analysis(hamr())
    s = result["max_speed"]
    # forward: both wheels at 20 rad/s -> r * 20 = 1.23 m/s
    assert s["forward"] == pytest.approx(R * WHEEL)
    # lateral, heading free: the drive base turns at wd = v / b and the
    # turret turns with it (turret joint still); the wheels run at a wd / r =
    # a v / (b r) -> v = 20 r b / a = 1.23 m/s (a = b)
    assert s["lateral"] == pytest.approx(WHEEL * R * B / A)
    # lateral at constant heading: the turret must cancel wd = v / b, so
    # v <= 4.712 * b = 0.7732 m/s (below the wheels' 1.23)
    assert s["lateral_constant_heading"] == pytest.approx(TURRET * B)
    # rotation in place: only the turret turns, 4.712 rad/s
    assert s["rotation"] == pytest.approx(TURRET)
    # H_hat = slowest / fastest constant-heading speed = 0.7732 / 1.23
    assert result["H_hat"] == pytest.approx(TURRET * B / (WHEEL * R))
    # sigma_ratio is that of the exact Jacobian, SI units
    s_vals = np.linalg.svd(hamr().jacobian(np.zeros(3)), compute_uv=False)
    assert result["sigma_ratio"] == pytest.approx(s_vals[-1] / s_vals[0])


def test_a_equal_b_gives_a_circular_translation_shadow_and_other_ratios_do_not():
    # XY block of J W^-2 J^T at phi = 0: diag(2 k^2 a^2 q^2, 2 k^2 b^2 q^2),
    # k = r / (2a): circular iff a = b (Sec. V-A)
    for b, expect_round in ((B, True), (2 * B, False), (0.5 * B, False)):
        speeds = mobility.SpeedSet.of(hamr(**{"ddrot.turret_offset": b}), np.zeros(3))
        S = speeds.ellipsoid_shape[:2, :2]
        axes = np.sqrt(np.linalg.eigvalsh(S))
        assert (abs(axes[1] / axes[0] - 1.0) < 1e-9) == expect_round
        if not expect_round:    # semi-axes in the ratio b : a
            assert axes[1] / axes[0] == pytest.approx(max(b, A) / min(b, A))


def test_the_shadow_is_the_same_at_every_turret_angle_only_rotated():
    base = mobility.SpeedSet.of(hamr(), np.zeros(3))
    for phi in (0.4, 1.3, -2.0):
        turned = mobility.SpeedSet.of(hamr(), np.array([0.0, 0.0, phi]))
        assert np.sort(np.linalg.eigvalsh(turned.ellipsoid_shape[:2, :2])) == pytest.approx(
            np.sort(np.linalg.eigvalsh(base.ellipsoid_shape[:2, :2])))
        assert turned.holonomicity()[0] == pytest.approx(base.holonomicity()[0])


def test_h_hat_vanishes_with_the_turret_offset_and_zero_offset_is_refused():
    # lateral at constant heading ~ b (turret and wheels both bind
    # proportionally to b), forward stays r q: H_hat is linear in b -> 0
    small = [analysis(hamr(**{"ddrot.turret_offset": b}))["H_hat"] for b in (1e-3, 1e-4, 1e-5)]
    assert small[0] == pytest.approx(10 * small[1], rel=1e-6)
    assert small[1] == pytest.approx(10 * small[2], rel=1e-6)
    assert small[2] < 1e-4
    # b = 0 is the plain differential drive: not holonomic (H_hat = 0); the
    # model refuses it, saying why
    with pytest.raises(ConfigError, match="not holonomic"):
        hamr(**{"ddrot.turret_offset": 0.0})


def test_turret_speed_raises_the_constant_heading_lateral_speed_until_the_wheels_bind():
    # Sec. V-C, third solution: v_lat = min(q_turret b, 20 r b / a)
    rows = mobility.sweep(lambda o: load_model("hamr", o), "joints.turret_joint.max_velocity",
                          np.linspace(2.0, 12.0, 11), {}, lambda m: np.zeros(3))
    lat = np.array([r["max_speed"]["lateral_constant_heading"] for r in rows])
    expected = np.minimum(np.linspace(2.0, 12.0, 11) * B, WHEEL * R * B / A)
    assert lat == pytest.approx(expected)
    assert np.all(np.diff(lat) >= -1e-12) and lat[-1] > 1.5 * lat[0]
    # and H_hat rises with it, up to the wheels' diamond: 1/sqrt(2) for a = b
    # (at 45 deg each wheel adds |v cos| + |v sin| a/b)
    h = [r["H_hat"] for r in rows]
    assert np.all(np.diff(h) >= -1e-12)
    assert h[-1] == pytest.approx(1 / math.sqrt(2))


def test_orientation_bias_of_the_ddrot_is_one_over_b():
    # moving sideways at v swings the drive base at v / b: the lateral-rotation
    # projection is skewed by 1/b rad per metre (Sec. V-B)
    for b in (B, 0.3):
        assert analysis(hamr(**{"ddrot.turret_offset": b}))["orientation_bias"] == \
            pytest.approx(1.0 / b)


def test_polytope_speeds_match_a_brute_force_search_on_the_xr4000():
    model = load_model("xr4000")
    steer = [0.3, -1.0, 2.0, 0.7]
    q = mobility.configuration(model, steer=steer)
    speeds = mobility.SpeedSet.of(model, q)
    limits = model.max_joint_velocity

    def feasible(twists):
        rates = np.stack([model.inverse(q, t) for t in twists])
        return np.all(np.abs(rates) <= limits * (1 + 1e-9), axis=1)

    # lateral with the rotation free: the feasible vy form an interval (P is
    # convex and symmetric); bisect on vy, scanning wz densely at each
    wz = np.linspace(-15, 15, 1501)
    lo, hi = 0.0, 2.0
    for _ in range(16):
        vy = 0.5 * (lo + hi)
        if feasible(np.column_stack([np.zeros_like(wz), np.full_like(wz, vy), wz])).any():
            lo = vy
        else:
            hi = vy
    assert speeds.max_speeds()["lateral"] == pytest.approx(lo, abs=0.005)
    # H_hat: the constant-heading speed over 720 directions
    ang = np.linspace(0, 2 * PI, 720, endpoint=False)
    radial = [speeds.ray_speed((math.cos(t), math.sin(t), 0.0)) for t in ang]
    for t, s in zip(ang[::60], radial[::60]):
        assert feasible([(s * math.cos(t), s * math.sin(t), 0.0)])[0]
        assert not feasible([(1.01 * s * math.cos(t), 1.01 * s * math.sin(t), 0.0)])[0]
    assert speeds.holonomicity()[0] == pytest.approx(min(radial) / max(radial), rel=2e-3)


# -- caster isotropy (Kim & Moon) ----------------------------------------------------------
def paper_Z(steer_ours, d, r, L, side=1.0):
    """Z = B^-1 A built from the paper's eqs. 1, 6, 8-15 as printed (their
    angles, u, v and p), with eq. 4 corrected (module doc of isotropy)."""
    phi = isotropy.to_paper_angles(steer_ours)
    s = side / math.sqrt(3) * np.array([[-math.sqrt(3) / 2, -0.5], [math.sqrt(3) / 2, -0.5],
                                        [0.0, 1.0]])
    rows_t, rows_s = [], []
    for si, ph in zip(s, phi):
        u = -np.array([math.cos(ph), math.sin(ph)])
        v = np.array([-math.sin(ph), math.cos(ph)])
        p = si - d * u
        q = np.array([-p[1], p[0]])
        rows_t.append(np.r_[u, u @ q / L] / r)
        rows_s.append(np.r_[v, v @ q / L] / d)
    return np.array(rows_t + rows_s)


def test_our_isotropy_index_is_the_papers_z_matrix():
    rng = np.random.default_rng(3)
    for _ in range(20):
        d, r = rng.uniform(0.05, 0.5, 2)
        steer = rng.uniform(-PI, PI, 3)
        iso = isotropy.isotropy(isotropy.paper_robot(d, r), steer)
        sv = np.linalg.svd(paper_Z(steer, d, r, iso.length), compute_uv=False)
        assert iso.index == pytest.approx(sv[-1] / sv[0], abs=1e-9)
        # and no other characteristic length does better
        for scale in (0.7, 0.95, 1.05, 1.4):
            sv = np.linalg.svd(paper_Z(steer, d, r, iso.length * scale), compute_uv=False)
            assert sv[-1] / sv[0] <= iso.index + 1e-9


def km(phi1, hat2, hat3):
    """Our steering angles for the paper's (phi_1, phi_1 + hat2, phi_1 + hat3)."""
    return isotropy.from_paper_angles([phi1, phi1 + hat2, phi1 + hat3])


@pytest.mark.parametrize("phi1", [0.0, 0.7, -2.2])
def test_mu_one_both_families_are_isotropic(phi1):
    # Group 1 (d = r): (phi1, phi1 +- 2pi/3, phi1 -+ 2pi/3), eq. 34
    kin = isotropy.paper_robot(0.25, 0.25)
    for hats in ((2 * PI / 3, -2 * PI / 3), (-2 * PI / 3, 2 * PI / 3)):
        iso = isotropy.isotropy(kin, km(phi1, *hats))
        assert iso.isotropic
        # C3: the maximiser is the isotropic characteristic length sqrt(k/sigma)
        assert iso.length == pytest.approx(iso.isotropic_length, rel=1e-4)


@pytest.mark.parametrize("d,r", [(0.1, 0.3), (0.2, 0.4), (0.4, 0.2), (0.03, 0.04)])
def test_one_family_is_isotropic_for_every_offset_and_its_mirror_is_not(d, r):
    # Group 2, (2pi/3, -2pi/3): isotropic for every d and mu (Sec. IV.2); the
    # mirrored family needs mu = 1 (Group 3, eq. 53)
    kin = isotropy.paper_robot(d, r)
    for phi1 in (0.0, 1.1, -2.5):
        assert isotropy.isotropy(kin, km(phi1, 2 * PI / 3, -2 * PI / 3)).isotropic
        assert isotropy.isotropy(kin, km(phi1, -2 * PI / 3, 2 * PI / 3)).index < 0.99


GROUP3 = [  # (hat2, hat3, phi1 for mu < 1, phi1 for mu > 1): eqs. 48-50
    (PI / 3, -PI / 3, PI / 6, -5 * PI / 6),
    (-2 * PI / 3, -PI / 3, -PI / 6, 5 * PI / 6),
    (PI / 3, 2 * PI / 3, PI / 2, -PI / 2),
]


@pytest.mark.parametrize("mu", [0.25, 0.6, 1.5, 2.0])
def test_third_group_is_isotropic_only_at_its_special_offset(mu):
    # d = sqrt(3)/4 |1 - mu| (side l = 1), r = d / sqrt(mu). (For mu > 2.15,
    # d > l/2 and the casters' contact circles overlap: no such robot.)
    d = math.sqrt(3) / 4 * abs(1 - mu)
    kin = isotropy.paper_robot(d, d / math.sqrt(mu))
    other = isotropy.paper_robot(0.8 * d, 0.8 * d / math.sqrt(mu))
    for hat2, hat3, below, above in GROUP3:
        phi1 = below if mu < 1 else above
        assert isotropy.isotropy(kin, km(phi1, hat2, hat3)).isotropic
        assert isotropy.isotropy(other, km(phi1, hat2, hat3)).index < 0.99
        # the other sign's phi1 is not isotropic
        assert isotropy.isotropy(kin, km(above if mu < 1 else below, hat2, hat3)).index < 0.99


def test_group_two_other_cases_are_never_isotropic():
    # (-pi/3, pi/3), (-pi/3, -2pi/3), (2pi/3, pi/3): eq. 37 cannot hold
    for d, r in ((0.2, 0.4), (0.4, 0.2), math.sqrt(3) / 4 * np.array([0.75, 1.5])):
        kin = isotropy.paper_robot(d, r)
        for hats in ((-PI / 3, PI / 3), (-PI / 3, -2 * PI / 3), (2 * PI / 3, PI / 3)):
            best = max(isotropy.isotropy(kin, km(p, *hats)).index
                       for p in np.linspace(-PI, PI, 37))
            assert best < 0.99


def test_random_configurations_are_not_isotropic():
    rng = np.random.default_rng(11)
    kin = isotropy.paper_robot(0.2, 0.3)
    for _ in range(50):
        assert isotropy.isotropy(kin, rng.uniform(-PI, PI, 3)).index < 0.999


def test_search_finds_exactly_the_papers_isotropic_configurations():
    def found(d, r):
        return isotropy.isotropic_configurations(isotropy.paper_robot(d, r))

    def hats(s):
        return tuple(np.round(np.array(s.offsets) / PI * 3).astype(int))   # units of pi/3

    # generic d/r: the one family (2pi/3, -2pi/3)
    sets = found(0.2, 0.4)
    assert [(s.kind, hats(s)) for s in sets] == [("family", (2, -2))]
    # d = r: both families
    assert sorted((s.kind, hats(s)) for s in found(0.3, 0.3)) == [
        ("family", (-2, 2)), ("family", (2, -2))]
    # mu = 1/4 at d = sqrt(3)/4 * 3/4: the family plus the third group's three points
    d = math.sqrt(3) / 4 * 0.75
    sets = found(d, 2 * d)
    points = sorted((hats(s), round(float(isotropy.to_paper_angles(s.angles)[0]) / PI * 6))
                    for s in sets if s.kind == "point")
    assert [s.kind for s in sets].count("family") == 1
    # phi1 in units of pi/6: pi/6 -> 1, -pi/6 -> -1, pi/2 -> 3
    assert points == [((-2, -1), -1), ((1, -1), 1), ((1, 2), 3)]


def test_isotropy_along_the_demo_script_follows_the_casters():
    kin = load_model("comr3").kinematics
    times, samples, starts = holonomicity.rollout("comr3", _script())
    assert [name for _, name in starts][:2] == ["forward", "strafe left (constant heading)"]
    # end of "forward": every wheel rolls along +x (steer 0); end of the
    # constant-heading strafe: every wheel has swung to roll along +y
    for t_end, steer in ((starts[1][0], 0.0), (starts[2][0], PI / 2)):
        q = samples[np.searchsorted(times, t_end - 0.1)][0::2]
        assert q == pytest.approx(np.full(3, steer), abs=1e-3)
        index = isotropy.isotropy(kin, q).index
        assert index == pytest.approx(isotropy.isotropy(kin, np.full(3, steer)).index, abs=1e-4)
    index = np.array([isotropy.isotropy(kin, q[0::2]).index for q in samples])
    assert len(index) > 300 and 0.5 < index.min() < index.max() < 1.0


def _script():
    from holonomic_core.teleop_script import demo_script
    return demo_script()


# -- measured holonomicity ------------------------------------------------------------------
def test_measured_h_tends_to_h_hat_as_the_distance_shrinks():
    h_hat = analysis(hamr())["H_hat"]
    kin = holonomicity.kinematic_overrides("hamr")
    measured = [holonomicity.measure("hamr", d, 8, (0.0,), "mock", kin).H
                for d in (1.0, 0.2, 0.03)]
    # the drive base swings toward the direction of travel during long moves,
    # so long moves are more uniform; tiny ones see only the instantaneous
    # speeds: 0.81 -> 0.67 -> 0.63 = H_hat
    assert measured[0] > measured[1] > measured[2]
    assert measured[2] == pytest.approx(h_hat, abs=0.015)
    assert measured[0] > h_hat + 0.1


def test_a_simulated_move_takes_the_time_the_limits_allow_and_stops_on_target():
    # HAMR forward 1 m: accelerate at 1.0 m/s^2, brake at 0.9 * 2.0: the peak
    # v_p solves 1 = v_p^2 / 2 (1/1 + 1/1.8) -> 1.134 m/s (< 1.2 limit), t =
    # v_p / 1 + v_p / 1.8 = 1.764 s
    # Ideal motors: the time the limits allow is the ideal plant's.
    ideal = {"sim.ideal_motors": True}
    move = holonomicity.time_move("hamr", 0.0, 0.0, 1.0, "sim", overrides=ideal)
    assert move.seconds == pytest.approx(1.764, rel=0.05)
    assert move.position_error < 0.01 and move.heading_error < math.radians(1)
    lateral = holonomicity.time_move("hamr", PI / 2, 0.0, 1.0, "sim", overrides=ideal)
    assert math.isfinite(lateral.seconds) and lateral.position_error < 0.01


@pytest.mark.parametrize("heading", [0.0, PI / 2])
def test_a_simulated_move_on_the_drive_model_stops_on_target(heading):
    # Drives tuned on the floor (sim.drive.tuned_on): both moves stop within
    # 1 cm / 1 deg, measured 2.015 / 2.030 s (0.8 / 0.3 mm, 0.51 / 0.33 deg),
    # 14-15 % over the ideal plant's 1.764 s: the drives' lag (7 ms of delays,
    # a 40 Hz loop) at the approach, and the move is steered on the ground
    # truth at the readings' sample time, 5 ms old (like a motion-capture
    # system's latency; 1.90 s each when the truth was the current one). With
    # the default drives (tuned lifted, ~2 Hz on the floor) the lateral move
    # limit-cycles (heading ~9 deg off after 20 s).
    move = holonomicity.time_move("hamr", heading, 0.0, 1.0, "sim",
                                  overrides={"sim.drive.tuned_on": "floor"})
    assert move.seconds < 1.764 * 1.25
    assert move.position_error < 0.01 and move.heading_error < math.radians(1)


# -- the command line ------------------------------------------------------------------------
def test_json_has_the_contract_keys(capsys):
    assert analyze_main(["xr4000", "--json", "--isotropy", "--steer", "0,0.5,1,1.5"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["robot"] == "xr4000"
    for key in ("H_hat", "sigma_ratio", "isotropy_index", "L"):
        assert isinstance(out[key], float)
    assert set(out["max_speed"]) >= {"forward", "lateral", "lateral_constant_heading",
                                     "rotation"}
    assert 0 < out["isotropy_index"] < 1 and out["L"] > 0


def test_a_speed_norm_caps_the_translation_speeds_and_h_hat(capsys):
    # HAMR: forward 1.23 m/s, constant-heading lateral 0.7732 m/s (joint limits)
    assert analyze_main(["hamr", "--json", "-p", "limits.linear.max_speed:=1.0"]) == 0
    out = json.loads(capsys.readouterr().out)
    s = out["max_speed"]
    assert s["forward"] == pytest.approx(1.0) and s["lateral"] == pytest.approx(1.0)
    assert s["lateral_constant_heading"] == pytest.approx(TURRET * B)     # below the cap
    assert s["rotation"] == pytest.approx(TURRET)                          # not capped
    assert out["H_hat"] == pytest.approx(TURRET * B / 1.0)
    # a cap below every direction's speed: equally fast in every direction
    assert analyze_main(["hamr", "--json", "-p", "limits.linear.max_speed:=0.5"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["H_hat"] == pytest.approx(1.0) and out["speed_limit"] == 0.5
    # 0: no norm limit, the joint limits alone
    assert analyze_main(["hamr", "--json", "-p", "limits.linear.max_speed:=0"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["H_hat"] == pytest.approx(TURRET * B / (WHEEL * R))
    assert out["speed_limit"] is None


def test_plot_writes_the_figures_and_sweep_prints_a_row_per_value(tmp_path, capsys):
    assert analyze_main(["hamr", "--plot", str(tmp_path),
                         "--sweep", "ddrot.turret_offset=0.05:0.4:8"]) == 0
    out = capsys.readouterr().out
    # H_hat of HAMR = constant-heading lateral / forward speed = turret rate * b
    # / (wheel rate * r) = 4.712 * 0.1641 / (20 * 0.0615) = 0.7732 / 1.23 = 0.629
    # within the joint limits; config/hamr.yaml caps the speed norm at 1.2 m/s:
    # 0.7732 / 1.2 = 0.644
    assert f"H_hat {TURRET * B / 1.2:.3f}" in out
    assert "limits.linear.max_speed 1.2 m/s caps them" in out
    assert sum(1 for line in out.splitlines() if line.strip().startswith(("0.", "0,"))) >= 8
    for name in ("hamr_ellipsoid_3d.png", "hamr_projections.png",
                 "hamr_sweep_ddrot.turret_offset.png"):
        assert (tmp_path / name).stat().st_size > 10_000


@pytest.mark.parametrize("argv,message", [
    (["hamr", "--isotropy"], "for a powered-caster vehicle"),
    (["xr4000", "--steer", "0,1"], "4 casters"),
    (["hamr", "--sweep", "ddrot.turret_offset=0.1:0.2"], "KEY=START:STOP:N"),
    (["hamr", "-p", "ddrot.wheel_radius:=-1"], "ddrot.wheel_radius"),
    (["nosuchrobot"], "config name"),
    (["swerve4", "--steer", "0,1"], "4 steered wheels: give 4 steering angles"),
    (["swerve4", "--turret", "1"], "--turret is for a DDROT"),
    (["swerve4", "--steer", "0,nan,0,0"], "finite comma-separated radians"),
])
def test_bad_arguments_exit_2_with_one_line(argv, message):
    proc = subprocess.run([sys.executable, "-c",
                           "import sys; from holonomic_analysis.cli import main; "
                           "sys.exit(main(sys.argv[1:]))", *argv],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert message in proc.stderr and "Traceback" not in proc.stderr
