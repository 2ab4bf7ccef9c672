"""The family comparison: the time to reverse at speed and the measured
holonomicity of a swerve base, with the controller in the loop on ideal
joints (mock)."""

import math

import pytest

from holonomic_analysis.family_comparison import main, reversal_time
from holonomic_analysis.holonomicity import time_move


def test_a_swerve_reverses_by_flipping_its_wheels_in_the_limiters_time():
    # swerve4: 0.5 m/s down to 0 at 1.5 m/s^2 (0.333 s), then up to 90 % of
    # 0.5 at 1 m/s^2 (0.45 s): 0.783 s; the modules flip instead of turning,
    # so no steering time is added (the odometry's 30 ms twist window: +15 ms)
    assert reversal_time("swerve4", 0.5, 0.0) == pytest.approx(0.783, abs=0.03)
    assert reversal_time("swerve4", 0.5, math.pi / 2) == pytest.approx(0.783, abs=0.03)


def test_a_swerve_pays_for_turning_its_modules_before_a_sideways_move():
    # from rest with the modules at 0: along x at once, along y only after
    # the modules turned 90 deg (8 rad/s limit: about 0.2 s, partly hidden
    # by the acceleration ramp)
    forward = time_move("swerve4", 0.0, 0.0, 1.0, "mock").seconds
    sideways = time_move("swerve4", math.pi / 2, 0.0, 1.0, "mock").seconds
    assert sideways > forward + 0.03


def test_the_comparison_prints_one_row_per_robot(capsys):
    assert main(["swerve4", "xr4000"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[2].startswith("| swerve4 |") and out[3].startswith("| xr4000 |")


def test_a_bad_speed_is_refused_in_one_line(capsys):
    assert main(["swerve4", "--speed", "0"]) == 2
    assert capsys.readouterr().err.strip() == "--speed: must be in (0, 5] m/s, got 0"
