"""Self-calibration (holonomic_core.calibration, the drift watch, the overlay):
the math against synthetic joint data generated with a *different* geometry
than the configured one, so the expected estimate is that geometry exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holonomic_core.calibration import (CalibrationError, calibrate, calibrate_measured,
                                        family_for, find_reference_segments,
                                        samples_from_readings)
from holonomic_core.config import load_model, read_params_file
from holonomic_core.drift_watch import DriftWatch


def _pcv_truth():
    """xr4000 with each caster changed: radii +-1.5 % around the same mean
    (the scale is held without a reference), offsets +-10 %, zeros +-3 deg."""
    nominal = load_model("xr4000")
    names = nominal.kinematics.caster_names
    dr = np.array([0.015, -0.01, 0.005, -0.01])          # sums to 0: mean radius kept
    db = np.array([0.1, -0.05, 0.08, -0.1])
    zeros = np.radians([3.0, -2.0, 1.0, -2.5])
    truth = {}
    for i, n in enumerate(names):
        truth[f"pcv.{n}.wheel_radius"] = 0.055 * (1 + dr[i])
        truth[f"pcv.{n}.caster_offset"] = 0.02 * (1 + db[i])
        # the encoder reads angle + zeros[i]: the correction is -zeros[i]
        truth[f"joints.{n}_steer_joint.zero_correction"] = -float(zeros[i])
    return nominal, truth


def _drive(model, twists, dt=0.005, zeros=None):
    """Joint readings of a rigid, slip-free base moving with ``twists`` (one
    per step [m/s, m/s, rad/s]) under ``model``'s true geometry: the joint
    rates are its exact inverse kinematics; the encoders add ``zeros``.
    Returns (stamps, raw readings, true poses in odom)."""
    q = np.zeros(len(model.joint_names))
    pose = np.zeros(3)
    stamps, readings, poses = [], [], []
    for k, twist in enumerate(twists):
        stamps.append(k * dt)
        readings.append(q + (0.0 if zeros is None else zeros))
        poses.append(pose.copy())
        # midpoint steps: joint rates at the half-step configuration
        half = q + 0.5 * dt * model.inverse(q, twist)
        q = q + dt * model.inverse(half, twist)
        c, s = math.cos(pose[2] + 0.5 * dt * twist[2]), math.sin(pose[2] + 0.5 * dt * twist[2])
        pose += dt * np.array([c * twist[0] - s * twist[1], s * twist[0] + c * twist[1],
                               twist[2]])
    return np.array(stamps), np.array(readings), np.array(poses)


def _teleop(seconds, dt=0.005, seed=0, rotation=True, sideways=True):
    """Smooth random twists: a new target every second, first-order approach."""
    rng = np.random.default_rng(seed)
    out, twist, target = [], np.zeros(3), np.zeros(3)
    for k in range(int(seconds / dt)):
        if k % int(1.0 / dt) == 0:
            target = rng.uniform(-1, 1, 3) * (0.6, 0.6 if sideways else 0.0,
                                              1.2 if rotation else 0.0)
        twist = twist + (target - twist) * dt / 0.3
        out.append(twist.copy())
    return out


def test_pcv_joint_data_of_another_geometry_gives_that_geometry_back():
    nominal, truth = _pcv_truth()
    true_model = load_model("xr4000", {k: v for k, v in truth.items() if k.startswith("pcv.")})
    zeros = np.zeros(len(nominal.joint_names))
    zeros[0::2] = [-truth[f"joints.{n}_steer_joint.zero_correction"]
                   for n in nominal.kinematics.caster_names]
    stamps, raw, _ = _drive(true_model, _teleop(40.0), zeros=zeros)
    # the configured model has no zeros: the controller hands the raw readings
    # on; every 5 ms reading is a sample, so that the steering transients
    # (unlimited here) are resolved
    result = calibrate(nominal, samples_from_readings(stamps, raw, period=0.005), "none")
    est = result.overlay()
    for key, value in truth.items():
        # slip-free data: only the 5 ms chords' discretisation separates the
        # fit from the truth (measured: radii 1e-6, offsets 1.1e-3 relative,
        # zeros 0.0012 deg; with 20 ms samples the offsets' error is 0.5 %)
        tol = (math.radians(0.005) if "zero_correction" in key else
               3e-3 * value if "caster_offset" in key else 1e-5 * value)
        assert est[key] == pytest.approx(value, abs=tol), key
    assert result.rms_residual < 1e-6          # [m] per sample: nothing left to explain


def test_pcv_reference_fixes_the_scale_the_joints_cannot_see():
    nominal = load_model("xr4000")
    # every radius 1.5 % larger: the joints alone stay consistent
    true_model = load_model("xr4000", {"pcv.wheel_radius": 0.055 * 1.015})
    stamps, raw, poses = _drive(true_model, _teleop(30.0, seed=1))
    no_ref = calibrate(nominal, samples_from_readings(stamps, raw), "none").overlay()
    assert no_ref["pcv.front_left.wheel_radius"] == pytest.approx(0.055, rel=2e-4)
    with_ref = calibrate(nominal, samples_from_readings(stamps, raw, poses),
                         "ground_truth").overlay()
    for name in nominal.kinematics.caster_names:
        assert with_ref[f"pcv.{name}.wheel_radius"] == pytest.approx(0.055 * 1.015, rel=2e-4)


def test_measured_distance_scales_the_radii():
    nominal = load_model("comr3")
    true_model = load_model("comr3", {"pcv.wheel_radius": 0.04 * 0.98})
    # the run ends at rest, where the user measures
    stamps, raw, poses = _drive(true_model, _teleop(30.0, seed=2) + [np.zeros(3)] * 40)
    span = float(np.hypot(*(poses[-1, :2] - poses[0, :2])))
    result = calibrate(nominal, samples_from_readings(stamps, raw), "distance", distance=span)
    # the joints fix everything but the common scale of radii and offsets;
    # the span fixes that: r = 0.98 * 0.04 and b = 0.03 exactly
    est = result.overlay()
    for name in ("c1", "c2", "c3"):
        assert est[f"pcv.{name}.wheel_radius"] == pytest.approx(0.04 * 0.98, rel=5e-4)
        assert est[f"pcv.{name}.caster_offset"] == pytest.approx(0.03, rel=5e-3)


def test_ddrot_is_calibrated_against_the_reference():
    nominal = load_model("hamr")
    truth = {"ddrot.left_wheel_radius": 0.0615 * 0.985, "ddrot.right_wheel_radius": 0.0615 * 1.01,
             "ddrot.half_wheel_separation": 0.1641 * 1.02}
    true_model = load_model("hamr", truth)
    zeros = np.array([0.0, 0.0, math.radians(2.0)])
    stamps, raw, poses = _drive(true_model, _teleop(30.0, seed=3), zeros=zeros)
    samples = samples_from_readings(stamps, raw, poses)
    est = calibrate(nominal, samples, "ground_truth").overlay()
    for key, value in truth.items():
        assert est[key] == pytest.approx(value, rel=2e-4), key
    assert est["joints.turret_joint.zero_correction"] == pytest.approx(-math.radians(2.0),
                                                                       abs=math.radians(0.01))
    with pytest.raises(CalibrationError, match="no redundant joint.*ground_truth"):
        calibrate(nominal, samples_from_readings(stamps, raw), "none")


def _reference_twists(b, dt=0.005, spin=1.0, turns=3.0, line=(0.5, 10.0), turret_only=False):
    """1 s still, ``line`` = (speed [m/s], time [s]) forward, 1 s still,
    ``turns`` revolutions at ``spin`` [rad/s] about the axle with the turret
    at 0 (twist (0, b w, w): the axle midpoint, b behind base_link, stays
    put), 1 s still; ``turret_only``: the base turns about base_link instead
    (only the turret moves)."""
    still = [np.zeros(3)] * int(1.0 / dt)
    rotate = (0.0, 0.0, spin) if turret_only else (0.0, b * spin, spin)
    return (still + [np.array((line[0], 0.0, 0.0))] * int(line[1] / dt) + still
            + [np.array(rotate)] * int(2 * math.pi * turns / spin / dt) + still)


def _measured_drive(truth, zero=0.0, **kwargs):
    """(model, readings' stamps, raw readings, segment ends, true poses) of
    a reference drive of hamr with the geometry ``truth`` and a turret
    encoder reading ``zero`` [rad] too much."""
    true_model = load_model("hamr", truth)
    twists = _reference_twists(true_model.kinematics.b, **kwargs)
    stamps, raw, poses = _drive(true_model, twists, zeros=np.array([0.0, 0.0, zero]))
    return stamps, raw, poses


def test_ddrot_is_calibrated_from_a_measured_line_and_rotation():
    # slip-free readings of a hamr whose wheels and separation differ from
    # the config; a user measures the straight run's end point and heading
    # change in its start frame and counts the rotation's turns: the fit
    # must give back the geometry that made the readings
    nominal = load_model("hamr")
    truth = {"ddrot.left_wheel_radius": 0.0615 * 0.985, "ddrot.right_wheel_radius": 0.0615 * 1.01,
             "ddrot.half_wheel_separation": 0.1641 * 1.02}
    stamps, raw, poses = _measured_drive(truth, zero=math.radians(2.0))
    line_end = int(12.0 / 0.005)                  # 1 s still + 10 s run + 1 s still
    forward, lateral = poses[line_end, :2]       # the run starts at the origin, heading 0
    # the true body follows the twists exactly: 5 m straight, 3 turns
    assert (forward, lateral) == pytest.approx((5.0, 0.0), abs=1e-9)
    yaw = np.unwrap(poses[:, 2])
    assert yaw[-1] - yaw[line_end] == pytest.approx(6 * math.pi, abs=0.01)
    segments = find_reference_segments(family_for(nominal), stamps, raw)
    result = calibrate_measured(nominal, segments, forward, lateral,
                                (yaw[-1] - yaw[line_end]) / (2 * math.pi), heading=0.0)
    est = result.overlay()
    # exact up to rounding: a straight line and a spin at constant rates are
    # integrated exactly by the midpoint readings and the chords (measured:
    # 4e-14 relative, 7e-12 deg)
    for key, value in truth.items():
        assert est[key] == pytest.approx(value, rel=1e-10), key
    assert est["joints.turret_joint.zero_correction"] == pytest.approx(-math.radians(2.0),
                                                                       abs=1e-10)
    # without the heading the turret zero is not fitted: kept, and said so
    plain = calibrate_measured(nominal, segments, forward, lateral, 3.0)
    assert plain.overlay()["joints.turret_joint.zero_correction"] == 0.0
    assert math.isnan(plain.stderr[3]) and "not observable" in " ".join(plain.notes)


@pytest.mark.parametrize("kwargs, cut, message", [
    ({}, int(12.0 / 0.005), "no rotation found"),                  # the line alone
    ({"line": (0.5, 0.0)}, None, "no straight run found"),         # the rotation alone
    ({"turret_only": True}, None, "turned the turret, not the wheels"),
])
def test_a_measured_drive_without_its_segments_is_refused(kwargs, cut, message):
    truth = {"ddrot.half_wheel_separation": 0.1641}
    stamps, raw, _ = _measured_drive(truth, **kwargs)
    with pytest.raises(CalibrationError, match=message):
        find_reference_segments(family_for(load_model("hamr")), stamps[:cut], raw[:cut])


def test_measured_references_must_be_positive_and_plausible():
    nominal = load_model("hamr")
    stamps, raw, _ = _measured_drive({"ddrot.half_wheel_separation": 0.1641})
    segments = find_reference_segments(family_for(nominal), stamps, raw)
    with pytest.raises(CalibrationError, match="--distance must be a measured distance > 0"):
        calibrate_measured(nominal, segments, -5.0, 0.0, 3.0)
    with pytest.raises(CalibrationError, match="--turns must be"):
        calibrate_measured(nominal, segments, 5.0, 0.0, 0.0)
    # the run was 5.000 m: 50 (a slipped decimal point) needs 10x the radii
    with pytest.raises(CalibrationError, match="more than 10 % from the configured"):
        calibrate_measured(nominal, segments, 50.0, 0.0, 3.0)


def test_straight_lines_only_are_rejected_with_what_motion_is_missing():
    model = load_model("xr4000")
    stamps, raw, _ = _drive(model, _teleop(60.0, seed=4, rotation=False, sideways=False))
    with pytest.raises(CalibrationError, match="only straight lines: drive with rotation and "
                                               "sideways"):
        calibrate(model, samples_from_readings(stamps, raw), "none")


def test_a_short_recording_is_rejected():
    model = load_model("xr4000")
    stamps, raw, _ = _drive(model, _teleop(5.0, seed=5))
    with pytest.raises(CalibrationError, match="too short"):
        calibrate(model, samples_from_readings(stamps, raw), "none")


def test_drift_watch_names_the_caster_and_the_parameter():
    nominal = load_model("xr4000")
    # front_left 2 % larger, rear_left 2 % smaller: the mean stays
    true_model = load_model("xr4000", {"pcv.front_left.wheel_radius": 0.055 * 1.02,
                                       "pcv.rear_left.wheel_radius": 0.055 * 0.98})
    stamps, raw, _ = _drive(true_model, _teleop(60.0, seed=6))
    for model, expect in ((nominal, True), (true_model, False)):
        watch = DriftWatch(model, window=20.0)
        for stamp, q in zip(stamps, raw):
            watch.update(stamp, q)
        findings = watch.findings()
        if expect:
            assert findings[0].startswith("caster ") and "run holonomic-calibrate" in findings[0]
            assert any(f.startswith("caster front_left: wheel radius looks 2.0 % larger")
                       for f in findings), findings
            assert any(f.startswith("caster rear_left: wheel radius looks 2.0 % smaller")
                       for f in findings), findings
        else:
            assert findings == [], findings


def test_drift_watch_works_a_batch_off_one_stage_per_cycle(monkeypatch):
    """The watch runs in the 1 kHz control cycle, and a batch costs more than a
    cycle (1.1-1.6 ms measured). So the residual, its Jacobian and the solve
    each run in a later update call of their own. The estimate is the same as
    when each batch is finished at once."""
    from holonomic_core import drift_watch
    model = load_model("xr4000")
    stamps, raw, _ = _drive(model, _teleop(12.0, dt=0.001, seed=7), dt=0.001)
    calls = {"n": 0, "residual": [], "jacobian": [], "solve": []}

    def spy(name, fn):
        def wrapped(*args, **kwargs):
            calls[name].append(calls["n"])
            return fn(*args, **kwargs)
        return wrapped
    monkeypatch.setattr(drift_watch, "residual_function",
                        spy("residual", drift_watch.residual_function))
    monkeypatch.setattr(drift_watch, "jacobian", spy("jacobian", drift_watch.jacobian))
    monkeypatch.setattr(DriftWatch, "_solve", spy("solve", DriftWatch._solve))
    staged, at_once = DriftWatch(model, window=5.0), DriftWatch(model, window=5.0)
    for n, (stamp, q) in enumerate(zip(stamps, raw)):
        calls["n"] = n
        staged.update(stamp, q)
    staged.flush()
    stages = list(zip(calls["residual"], calls["jacobian"], calls["solve"]))
    # 12 s of readings at 1 kHz: a batch of 41 samples 50 ms apart every 2 s
    assert len(stages) == 5
    for residual, jac, solve in stages:
        # one stage per call, on the calls after the batch filled (the 1 kHz
        # readings' cycles): residual, Jacobian, normal equations, solve
        assert (jac - residual, solve - jac) == (1, 2)
    for stamp, q in zip(stamps, raw):
        at_once.update(stamp, q)
        at_once.flush()
    assert staged.error is not None
    np.testing.assert_array_equal(staged.error, at_once.error)
    np.testing.assert_array_equal(staged._info, at_once._info)


def test_overlay_is_a_params_file_that_changes_the_model(tmp_path):
    import yaml
    from holonomic_bringup.calibrate import overlay_document
    from holonomic_core.config import load_config
    overlay = {"pcv.front_left.wheel_radius": 0.0561,
               "pcv.rear_right.caster_offset": 0.021,
               "joints.front_right_steer_joint.zero_correction": 0.05}
    path = tmp_path / "overlay.yaml"
    path.write_text(yaml.safe_dump(overlay_document(overlay)))
    flat = read_params_file(path)
    assert flat == pytest.approx(overlay)
    cfg = load_config("xr4000", flat)
    kin = cfg.model.kinematics
    assert kin.r[0] == 0.0561 and kin.b[2] == 0.021
    assert cfg.model.zero_corrections[6] == 0.05


def test_family_parameters_are_the_config_keys():
    fam = family_for(load_model("comr3"))
    assert fam.keys[:3] == ("pcv.c1.wheel_radius", "pcv.c2.wheel_radius", "pcv.c3.wheel_radius")
    assert fam.keys[-1] == "joints.c3_steer_joint.zero_correction"
    assert list(fam.nominal[:6]) == [0.04] * 3 + [0.03] * 3


#: steering zeros a robot's config already carries (a calibration done
#: before): joints.<caster>_steer_joint.zero_correction [rad]
CONFIGURED_ZEROS = np.radians([2.0, -1.5, 0.7, -3.0])


@pytest.mark.parametrize("drifted", [False, True], ids=["unchanged", "drifted"])
def test_pcv_calibration_from_configured_zeros_keeps_or_finds_them(drifted):
    """A robot calibrated before has zero corrections in its config; the
    controller adds them to the raw readings, and the recording holds
    those corrected angles. Recalibrated, a robot whose encoders did not
    move gets its configured zeros back (not 0, not twice the correction);
    one whose encoders slipped by +0.5, -0.3, 0, +1 deg since gets the
    configured zeros minus that slip. Geometry as configured: radii and
    offsets come back unchanged (slip-free data; the tolerances of
    test_pcv_joint_data_of_another_geometry_gives_that_geometry_back)."""
    names = load_model("xr4000").kinematics.caster_names
    overrides = {f"joints.{n}_steer_joint.zero_correction": float(z)
                 for n, z in zip(names, CONFIGURED_ZEROS)}
    configured = load_model("xr4000", overrides)
    slip = np.radians([0.5, -0.3, 0.0, 1.0]) if drifted else np.zeros(4)
    # the true angles, plus what the encoders slipped by since the config's
    # calibration: the readings as the controller saw them (raw + correction)
    seen = np.zeros(len(configured.joint_names))
    seen[0::2] = slip
    stamps, positions, _ = _drive(load_model("xr4000"), _teleop(30.0, seed=8), zeros=seen)
    result = calibrate(configured, samples_from_readings(stamps, positions, period=0.005),
                       "none")
    est = result.overlay()
    for i, name in enumerate(names):
        assert est[f"joints.{name}_steer_joint.zero_correction"] == pytest.approx(
            CONFIGURED_ZEROS[i] - slip[i], abs=math.radians(0.005)), name
        assert est[f"pcv.{name}.wheel_radius"] == pytest.approx(0.055, rel=1e-5), name
        assert est[f"pcv.{name}.caster_offset"] == pytest.approx(0.02, rel=3e-3), name


@pytest.mark.parametrize("drifted", [False, True], ids=["unchanged", "drifted"])
def test_ddrot_calibration_from_a_configured_turret_zero_keeps_or_finds_it(drifted):
    """The HAMR's turret zero configured at 1.5 deg: against ground truth,
    a turret encoder that did not move gives 1.5 deg back; one that slipped
    by 0.8 deg gives 1.5 - 0.8 = 0.7 deg. Radii and separation as configured
    (the tolerance of test_ddrot_is_calibrated_against_the_reference)."""
    zero = math.radians(1.5)
    configured = load_model("hamr", {"joints.turret_joint.zero_correction": zero})
    slip = math.radians(0.8) if drifted else 0.0
    stamps, positions, poses = _drive(load_model("hamr"), _teleop(30.0, seed=9),
                                      zeros=np.array([0.0, 0.0, slip]))
    est = calibrate(configured, samples_from_readings(stamps, positions, poses),
                    "ground_truth").overlay()
    assert est["joints.turret_joint.zero_correction"] == pytest.approx(
        zero - slip, abs=math.radians(0.01))
    for key, value in (("ddrot.left_wheel_radius", 0.0615), ("ddrot.right_wheel_radius", 0.0615),
                       ("ddrot.half_wheel_separation", 0.1641)):
        assert est[key] == pytest.approx(value, rel=2e-4), key
