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
