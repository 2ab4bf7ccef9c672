"""holonomic-odometry-calibrate shows its progress over reading and replaying
the recordings: in a log (stderr not a terminal), plain lines with the steps
done and the time left; the results on stdout unchanged."""

from __future__ import annotations

import re


def test_odometry_calibrate_logs_reading_and_replaying_each_recording(capsys, monkeypatch):
    from holonomic_bringup import odometry_calibrate
    from holonomic_sim.odometry_experiment import record_run

    # two 3 s simulated runs stand in for the MCAP files
    runs = {f"run{k}.mcap": record_run("hamr", "nominal (mu 1.0)", k, 3.0) for k in (1, 2)}
    monkeypatch.setattr(odometry_calibrate, "recording_from_mcap",
                        lambda path, namespace, topic: runs[path.name])
    assert odometry_calibrate.main(["run1.mcap", "run2.mcap"]) == 0
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines()
             if line.startswith("holonomic-odometry-calibrate: ")]
    assert "\r" not in captured.err
    assert [line.split(" (")[0] for line in lines] == [
        f"holonomic-odometry-calibrate: {k}/4 steps" for k in (1, 2, 3, 4)], captured.err
    assert all(re.search(r"\d+ s elapsed, about \d+ s left$", line) for line in lines[:3])
    assert lines[3].endswith(", done")
    # the results stay on stdout, as the calibration without progress prints them
    from holonomic_core.odometry_calibration import calibrate_main
    calibrate_main(list(runs.values()), fit_noise=True, plot_path=None)
    assert "calibrated coverage" in captured.out
    assert capsys.readouterr().out == captured.out
