"""The calibration's pieces that need no simulation: the band loss, the
random-walk reference for the spread between runs, the recordings cache, the
fit on synthetic samples whose right answer is known."""

import numpy as np
import pytest

from holonomic_core.odometry_calibration import Recording, _band_loss, random_walk_spread
from holonomic_sim.odometry_experiment import (CONDITION_KEYS, load_recording,
                                               recording_path, save_recording)


def test_band_loss_counts_over_coverage_above_the_band():
    # by hand, d = fraction - 0.95; loss = (4 if d < 0 else 1) d^2
    # + 100 (0.90 - f)^2 below the band + 100 (f - 0.995)^2 above it
    assert _band_loss(np.array([0.95])) == pytest.approx(0.0)
    assert _band_loss(np.array([0.99])) == pytest.approx(0.04 ** 2)
    # 100 %: 0.05^2 + 100 * 0.005^2 = 0.0025 + 0.0025
    assert _band_loss(np.array([1.0])) == pytest.approx(0.005)
    # 85 %: 4 * 0.1^2 + 100 * 0.05^2 = 0.04 + 0.25
    assert _band_loss(np.array([0.85])) == pytest.approx(0.29)
    # floors add up
    assert _band_loss(np.array([1.0, 0.85])) == pytest.approx(0.295)


def test_an_exact_random_walk_covers_95_percent_on_average_but_not_run_by_run():
    spread = random_walk_spread(samples_per_run=200, runs=2000)
    # every sample's error is N(0, t) (1-D) or N(0, t I) (2-D) exactly and the
    # regions are the 95 % quantiles: 95 % on average by construction; the
    # mean over 2000 runs of sd ~0.13 has a standard error of ~0.003
    assert spread["heading_mean"] == pytest.approx(0.95, abs=0.012)
    assert spread["position_mean"] == pytest.approx(0.95, abs=0.012)
    # the point: one run's fraction is far from 95 % (measured 0.12-0.13):
    # a spread of +-12 % between runs is no sign of a wrong covariance
    assert 0.08 < spread["heading"] < 0.2
    assert 0.08 < spread["position"] < 0.2


def test_a_recording_round_trips_through_its_cache_file(tmp_path):
    rng = np.random.default_rng(1)
    condition = CONDITION_KEYS["drives-worn"]
    rec = Recording("xr4000", condition, 3, None, np.arange(5) * 0.005,
                    rng.standard_normal((5, 8)), rng.standard_normal((5, 3)),
                    rng.standard_normal((5, 3)), seconds=1.5,
                    internal_force=rng.random(5), fault=None,
                    hidden_truth={"pcv.fl.wheel_radius": 0.0811})
    path = recording_path(str(tmp_path), "xr4000", condition, 3, 40.0, 1.25, 2.0)
    save_recording(rec, path)
    back = load_recording(path, "xr4000", condition, 3, "the config")
    for key in ("stamps", "positions", "truth", "truth_twist", "internal_force"):
        assert np.array_equal(getattr(back, key), getattr(rec, key)), key
    assert (back.seconds, back.fault, back.hidden_truth, back.config) == (
        1.5, None, {"pcv.fl.wheel_radius": 0.0811}, "the config")
    # a run with other arguments is another file: never reused for this one
    others = {recording_path(str(tmp_path), "xr4000", condition, 4, 40.0, 1.25, 2.0),
              recording_path(str(tmp_path), "xr4000", condition, 3, 60.0, 1.25, 2.0),
              recording_path(str(tmp_path), "xr4000", condition, 3, 40.0, 1.25, 2.0,
                             {"sim.drive.bandwidth": 120.0})}
    assert path not in others and len(others) == 3


def test_a_basis_at_rounding_level_gets_no_coefficient():
    # a DDROT's slip residual is ~1e-12 m/s: its basis (rho^2 dt summed) is
    # ~1e-24; "the coefficient that alone explains the error" would be
    # ~1e+20 and, multiplied by a basis that is rounding, meaningless
    from holonomic_core.odometry_calibration import _natural, _present
    bases = np.array([[1.0, 1e-24], [2.0, 3e-24]])
    err2 = np.array([0.5, 1.0])
    assert _present(bases).tolist() == [1.0, 0.0]
    # column 0: mean(err2) / mean(basis) = 0.75 / 1.5
    assert _natural(bases, err2).tolist() == [0.5, 0.0]


def _one_floor(k_per_run, samples_per_run=10):
    """Synthetic samples of one floor: run r's heading error is k_r sqrt(t)
    and its position error (k_r sqrt(t), 0), against the bases t (heading,
    angular_variance_per_radian) and t I (position, linear_variance_per_meter),
    t = 1..samples_per_run; every other basis 0 (absent)."""
    from holonomic_core.odometry_calibration import HEADING_KEYS, POSITION_KEYS, Samples
    t = np.arange(1.0, samples_per_run + 1.0)
    parts = []
    for r, k in enumerate(k_per_run):
        bases = {key: np.zeros((len(t), 3, 3)) for key in HEADING_KEYS + POSITION_KEYS}
        bases["angular_variance_per_radian"][:, 2, 2] = t
        bases["linear_variance_per_meter"][:, 0, 0] = t
        bases["linear_variance_per_meter"][:, 1, 1] = t
        error = np.column_stack([k * np.sqrt(t), np.zeros_like(t), k * np.sqrt(t)])
        parts.append({"condition": np.array(["floor"] * len(t)),
                      "motion": np.array(["random"] * len(t)),
                      "group": np.array(["floor"] * len(t)),
                      "run": np.array([f"floor seed {r}"] * len(t)), "error": error,
                      "twist_error": np.full((len(t), 3), 0.01), "bases": bases,
                      "slip_basis": np.zeros((len(t), 3)), "lag_basis": np.zeros((len(t), 3))})
    samples = Samples.__new__(Samples)
    samples._pool(parts)
    return samples


def test_a_floor_profile_is_scaled_for_the_next_run_not_the_runs_it_saw(monkeypatch):
    # four runs, error sizes k = 1, 1, 1, 2 (one seed's wheels slip more).
    # The likelihood fit of a variance c t to errors k sqrt(t) is c = mean(k^2):
    # 7/4 over all runs; the position's c t I to (k sqrt(t), 0): mean(k^2) / 2.
    # Every sample of a run has the same |e| / sigma, so 95 % of 4 equal runs
    # needs all 4 inside: heading k^2 <= 1.96^2 c, position k^2 <= 5.991 c.
    from holonomic_core import odometry_calibration
    from holonomic_core.odometry_calibration import fit
    from holonomic_core.odometry import OdometryNoise
    # the scale alone: no random-walk floor under the fitted terms (the
    # floor has its own test below)
    monkeypatch.setattr(odometry_calibration, "FLOOR_SHARE", 0.0)
    samples = _one_floor([1.0, 1.0, 1.0, 2.0])
    start = OdometryNoise()
    seen = fit(samples, start, predictive=False)
    # scaled on the runs it saw: the k = 2 run decides, c = 4 / 1.96^2, 4 / 5.991
    assert seen.angular_variance_per_radian == pytest.approx(4.0 / 1.96 ** 2, rel=1e-6)
    assert seen.linear_variance_per_meter == pytest.approx(4.0 / 5.991, rel=1e-6)
    nxt = fit(samples, start)
    # for the next run: fitted on the other three, the k = 2 run sees c = 1
    # (heading) and 1/2 (position), so the scale is 4 / 1.96^2 and 8 / 5.991,
    # applied to the fit over all four runs (7/4, 7/8): 7 / 1.96^2, 7 / 5.991
    assert nxt.angular_variance_per_radian == pytest.approx(7.0 / 1.96 ** 2, rel=1e-6)
    assert nxt.linear_variance_per_meter == pytest.approx(7.0 / 5.991, rel=1e-6)
    # two runs are too few to hold one out of the fit: scaled on what it saw
    two = _one_floor([1.0, 2.0])
    assert fit(two, start).angular_variance_per_radian == pytest.approx(
        fit(two, start, predictive=False).angular_variance_per_radian)


def _two_floors(with_rho4_basis):
    """Synthetic samples of two floors whose error variance grows with rho^4:
    floor "grip" has an RMS residual rho = 0.05 m/s, floor "slide" 0.2 m/s;
    at sample t (t = 1..400, one run per floor) the true heading variance is
    g rho^4 t and the true position covariance g rho^4 t I. The errors are
    the exact quantiles of those Gaussians (heading: the normal's, position:
    the Rayleigh radius's, in a turning direction), so a variance that
    matches covers 95 % to within a sample. Bases: rho^2 t for the slip
    gains, rho^4 t for the slip4 gains (zero without them: the model before
    the rho^4 terms)."""
    from statistics import NormalDist
    from holonomic_core.odometry_calibration import HEADING_KEYS, POSITION_KEYS, Samples
    n, g = 400, 50.0
    t = np.arange(1.0, n + 1.0)
    u = (np.arange(n) + 0.5) / n
    order = np.random.default_rng(0).permutation(n)      # quantiles in no time order
    parts = []
    for floor, rho in (("grip", 0.05), ("slide", 0.2)):
        sigma = np.sqrt(g * rho ** 4 * t)
        radius = sigma * np.sqrt(-2.0 * np.log(1.0 - u[order]))
        angle = 2.4 * np.arange(n)
        error = np.column_stack([radius * np.cos(angle), radius * np.sin(angle),
                                 sigma * np.array([NormalDist().inv_cdf(p) for p in u[order]])])
        bases = {key: np.zeros((n, 3, 3)) for key in HEADING_KEYS + POSITION_KEYS}
        bases["slip_heading_gain"][:, 2, 2] = rho ** 2 * t
        bases["slip_position_gain"][:, 0, 0] = bases["slip_position_gain"][:, 1, 1] = rho ** 2 * t
        if with_rho4_basis:
            bases["slip4_heading_gain"][:, 2, 2] = rho ** 4 * t
            bases["slip4_position_gain"][:, 0, 0] = rho ** 4 * t
            bases["slip4_position_gain"][:, 1, 1] = rho ** 4 * t
        parts.append({"condition": np.array([floor] * n), "motion": np.array(["random"] * n),
                      "group": np.array([floor] * n), "run": np.array([f"{floor} seed 0"] * n),
                      "error": error, "twist_error": np.full((n, 3), 0.01), "bases": bases,
                      "slip_basis": np.zeros((n, 3)), "lag_basis": np.zeros((n, 3))})
    samples = Samples.__new__(Samples)
    samples._pool(parts)
    return samples


def test_the_rho4_terms_let_one_profile_cover_floors_whose_slip_differs():
    # Errors that grow with rho^4 on two floors 4x apart in rho: a variance
    # ~ rho^2 is 16x too large on one floor or 16x too small on the other,
    # whatever its gain; with the rho^4 basis the multi-floor search finds
    # the gain and both floors are in the band
    from holonomic_core.odometry import OdometryNoise
    from holonomic_core.odometry_calibration import BAND, fit
    for with_rho4 in (True, False):
        samples = _two_floors(with_rho4)
        noise = fit(samples, OdometryNoise())
        cover = {floor: samples.coverage(noise, samples.condition == floor)
                 for floor in ("grip", "slide")}
        inside = all(BAND[0] <= c[key] <= BAND[1] for c in cover.values()
                     for key in ("position", "heading"))
        assert inside == with_rho4, (with_rho4, cover, noise)
        if with_rho4:
            # measured: both floors 95.0 % (position and heading), slip4 gains
            # 48.9 (heading) and 49.6 (position) against the true 50, the rho^2
            # gains ~0.001. Without the basis: 100 % on "grip", 95 % on "slide"
            assert 40.0 < noise.slip4_heading_gain < 60.0, noise
            assert 40.0 < noise.slip4_position_gain < 60.0, noise
            assert noise.slip_heading_gain < 0.01 and noise.slip_position_gain < 0.01, noise


def test_the_random_walk_floors_never_go_to_zero_when_slip_explains_the_errors():
    # errors that grow with rho^4 only (_two_floors), with distance and
    # rotation bases present too (t, as if the base moved 1 m and turned
    # 1 rad per sample): a free fit would put everything on the rho^4 terms
    # and publish no variance on motion without residual. The floor is
    # FLOOR_SHARE of the value at which the term alone explains the mean
    # squared error: mean(e^2) / mean(t), per column
    from holonomic_core.odometry import OdometryNoise
    from holonomic_core.odometry_calibration import FLOOR_SHARE, fit
    samples = _two_floors(True)
    t = np.tile(np.arange(1.0, 401.0), 2)
    samples.bases["angular_variance_per_radian"][:, 2, 2] = t
    samples.bases["angular_variance_per_meter"][:, 2, 2] = t
    samples.bases["linear_variance_per_meter"][:, 0, 0] = t
    samples.bases["linear_variance_per_meter"][:, 1, 1] = t
    noise = fit(samples, OdometryNoise())
    e = samples.error
    heading_natural = np.mean(e[:, 2] ** 2) / np.mean(t)
    position_natural = np.mean(np.sum(e[:, :2] ** 2, axis=1)) / np.mean(2.0 * t)
    assert FLOOR_SHARE > 0.0
    for value in (noise.angular_variance_per_radian, noise.angular_variance_per_meter):
        assert value >= FLOOR_SHARE * heading_natural * (1.0 - 1e-9) > 0.0, noise
    assert noise.linear_variance_per_meter >= (
        FLOOR_SHARE * position_natural * (1.0 - 1e-9)) > 0.0, noise
