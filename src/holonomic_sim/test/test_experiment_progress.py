"""A long experiment shows its progress: in a log (stderr not a terminal),
plain lines with the runs done and the time left, never a redrawn bar."""

from __future__ import annotations

import re
import subprocess
import sys


def test_odometry_experiment_logs_plain_progress_lines_with_the_time_left():
    # two one-second runs of the HAMR on the nominal floor: a few seconds
    proc = subprocess.run(
        [sys.executable, "-m", "holonomic_sim.odometry_experiment", "--robot", "hamr",
         "--seeds", "2", "--duration", "1", "--condition", "nominal"],
        capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "\r" not in proc.stderr          # a bar redrawn in place would leave these
    progress = [line for line in proc.stderr.splitlines()
                if line.startswith("holonomic-odometry-experiment: ")]
    assert len(progress) == 2, proc.stderr
    assert re.fullmatch(r"holonomic-odometry-experiment: 1/2 runs \(50 %\), \d+ s elapsed, "
                        r"about \d+ s left", progress[0]), progress[0]
    assert re.fullmatch(r"holonomic-odometry-experiment: 2/2 runs \(100 %\), \d+ s elapsed, "
                        r"done", progress[1]), progress[1]
    # each run's own line comes before the progress line that counts it
    lines = proc.stderr.splitlines()
    assert "seed   0:" in lines[lines.index(progress[0]) - 1]
    # the results stay on stdout, without progress
    assert proc.stdout.lstrip().startswith("condition")
    assert "holonomic-odometry-experiment:" not in proc.stdout


def test_calibration_experiment_logs_plain_progress_lines_with_the_time_left():
    # one 20 s drive of the xr4000 calibrated with and without a reference, no
    # odometry paths: two steps, a few seconds
    proc = subprocess.run(
        [sys.executable, "-m", "holonomic_sim.calibration_experiment", "--robot", "xr4000",
         "--duration", "20", "--passes", "1", "--seeds", "0"],
        capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "\r" not in proc.stderr
    progress = [line for line in proc.stderr.splitlines()
                if line.startswith("holonomic-calibration-experiment: ")]
    assert len(progress) == 2, proc.stderr
    assert re.fullmatch(r"holonomic-calibration-experiment: 1/2 steps \(50 %\), \d+ s elapsed, "
                        r"about \d+ s left", progress[0]), progress[0]
    assert re.fullmatch(r"holonomic-calibration-experiment: 2/2 steps \(100 %\), \d+ s "
                        r"elapsed, done", progress[1]), progress[1]
    # the tables stay on stdout, without progress
    assert "reference ground_truth" in proc.stdout and "reference none" in proc.stdout
    assert "holonomic-calibration-experiment:" not in proc.stdout


def test_the_odometry_paths_of_a_calibration_are_counted_with_their_lines_above(
        capsys, monkeypatch):
    from holonomic_core.progress import progress
    from holonomic_sim import calibration_experiment as experiment

    ran = []

    def run(robot, condition, seed, overrides, calibration):    # no simulation: a stub
        ran.append(seed)
        return seed

    class Trial:
        position_error = {"slip_min": 0.01}
        distance = 2.0

    monkeypatch.setattr(experiment, "record_run", run)
    monkeypatch.setattr(experiment, "final_errors", lambda rec: Trial())
    with progress(2, "holonomic-calibration-experiment", "steps") as bar:
        errors = experiment.odometry_errors("hamr", 1, {}, 2, {}, bar=bar)
    assert ran == [0, 0, 0, 1, 1, 1] and errors["no faults"] == [0.01, 0.01]
    lines = capsys.readouterr().err.splitlines()
    assert lines[3].startswith("holonomic-calibration-experiment: 1/2 steps (50 %)")
    assert "about" in lines[3] and lines[2].strip().startswith("faults, calibrated   path 0")
    assert lines[7].endswith(", done") and "path 1" in lines[6]


def test_odometry_experiment_logs_the_replays_of_its_calibration():
    # --calibrate replays the odometry over every run: two 2 s runs, a second or two
    proc = subprocess.run(
        [sys.executable, "-m", "holonomic_sim.odometry_experiment", "--robot", "hamr",
         "--seeds", "2", "--duration", "2", "--condition", "nominal", "--calibrate"],
        capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "\r" not in proc.stderr
    replay = [line for line in proc.stderr.splitlines()
              if line.startswith("holonomic-odometry-experiment replay: ")]
    assert len(replay) == 2, proc.stderr
    assert re.fullmatch(r"holonomic-odometry-experiment replay: 1/2 recordings \(50 %\), \d+ s "
                        r"elapsed, about \d+ s left", replay[0]), replay[0]
    assert replay[1].endswith(", done")
    assert "calibrated parameters" in proc.stdout and "replay:" not in proc.stdout
