"""The calibration's pieces that need no simulation: the band loss, the
random-walk reference for the spread between runs, the recordings cache."""

import numpy as np
import pytest

from holonomic_sim.odometry_calibration import _band_loss, random_walk_spread
from holonomic_sim.odometry_experiment import (CONDITION_KEYS, Recording, load_recording,
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
    from holonomic_sim.odometry_calibration import _natural, _present
    bases = np.array([[1.0, 1e-24], [2.0, 3e-24]])
    err2 = np.array([0.5, 1.0])
    assert _present(bases).tolist() == [1.0, 0.0]
    # column 0: mean(err2) / mean(basis) = 0.75 / 1.5
    assert _natural(bases, err2).tolist() == [0.5, 0.0]
