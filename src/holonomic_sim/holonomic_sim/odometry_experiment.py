"""``holonomic-odometry-experiment``: Holmberg & Khatib's odometry test, in simulation.

The paper drove the XR4000 randomly for a minute inside a 1.5 m x 2.5 m
area and back to its start, and compared the final dead-reckoning error of
the slip-minimising estimator C# = Cp+ Cq^-1 with the pseudo-inverse of C.
This reproduces it with the real control stack (``BaseController`` and the
``sim`` driver, stepped as fast as the CPU allows, no ROS):

* the base follows random target poses inside the area centred on its start
  (steered by ground truth, like the paper's externally measured runs), at up
  to ``--speed`` and under the controller's acceleration limits, for
  ``--duration`` seconds, then returns to the start and stops;
* every joint reading is recorded once, and each estimator integrates the
  same recording -- the estimators are compared on identical motion;
* the final error is ``|odometry - ground truth|`` at the end (position, m;
  heading, rad), over ``--seeds`` seeds x the conditions;
* the internal force -- the part of the wheels' contact forces that produces
  no net force or moment on the base (:mod:`holonomic_sim.contact_forces`),
  the wheels fighting each other -- is sampled every control cycle (RMS).

Conditions: the slip conditions on ideal motors (pybullet's velocity motors,
the reference) and on the drive model (velocity loops with a per-joint spread
of gains and friction, torque limits, rotor inertia, delays: the simulator's
default). ``-p NAME:=VALUE`` changes the drive model (e.g. its bandwidth or
spread) for a sweep.

Prints a table (mean and median per estimator and condition, and the ratios
to ``pinv``) and, with ``--json``, writes every trial. With ``--calibrate``
it also fits the odometry covariance to ground truth over the same runs
(:mod:`holonomic_core.odometry_calibration`); ``--check`` reports the coverage
of the config's own covariance. :func:`simulate` is also the offline driver
of the self-calibration experiment (a calibration overlay for the
controller only, the simulated robot built from the drawing and its hidden
errors, as holonomic-bringup builds it: :mod:`holonomic_core.nominal`).

The runs, and with ``--calibrate`` or ``--check`` the replays of the
odometry over them, report their progress on stderr
(:mod:`holonomic_core.progress`): a bar with the time left on a terminal,
plain lines with the time left in a log. The tables stay on stdout.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field, replace

import numpy as np

from holonomic_core.calibration import CalibrationError, calibrate, samples_from_readings
from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.kinematics import ESTIMATORS
from holonomic_core.loop import ManualClock
from holonomic_core.nominal import driver_for
from holonomic_core.odometry import Odometry
from holonomic_core.odometry_calibration import Recording
from holonomic_core.progress import progress
from holonomic_core.se2 import wrap_angle
from holonomic_core.command_line import (ArgumentParser, ShowDefaults, number, output_file,
                                         robot_config)
from holonomic_core.schema import ConfigError, parse_overrides
from holonomic_sim.contact_forces import internal_force
from holonomic_sim.motion_kinds import MOTION_KINDS, MotionPlan, motion_list

_IDEAL = {"sim.ideal_motors": True}
_DRIVES = {"sim.ideal_motors": False}
#: conditions: name -> simulator overrides (per-wheel friction spread and the
#: drives' per-joint spread are re-drawn from each trial's seed)
CONDITIONS = {
    "nominal (mu 1.0)": {"sim.wheel_friction": 1.0, "sim.friction_spread": 0.0, **_IDEAL},
    "uneven (mu 0.8 +-40 %)": {"sim.wheel_friction": 0.8, "sim.friction_spread": 0.4,
                               **_IDEAL},
    "slippery (mu 0.3 +-30 %)": {"sim.wheel_friction": 0.3, "sim.friction_spread": 0.3,
                                 **_IDEAL},
    "worn tyres (r +-2 %)": {"sim.wheel_friction": 1.0, "sim.friction_spread": 0.0,
                             "sim.wheel_radius_spread": 0.02, **_IDEAL},
    "drives, nominal (mu 1.0)": {"sim.wheel_friction": 1.0, "sim.friction_spread": 0.0,
                                 **_DRIVES},
    "drives, uneven (mu 0.8 +-40 %)": {"sim.wheel_friction": 0.8, "sim.friction_spread": 0.4,
                                       **_DRIVES},
    "drives, slippery (mu 0.3 +-30 %)": {"sim.wheel_friction": 0.3, "sim.friction_spread": 0.3,
                                         **_DRIVES},
    "drives, worn tyres (r +-2 %)": {"sim.wheel_friction": 1.0, "sim.friction_spread": 0.0,
                                     "sim.wheel_radius_spread": 0.02, **_DRIVES},
}
#: short name on the command line -> the condition's full name
CONDITION_KEYS = {"nominal": "nominal (mu 1.0)", "uneven": "uneven (mu 0.8 +-40 %)",
                  "slippery": "slippery (mu 0.3 +-30 %)", "worn": "worn tyres (r +-2 %)",
                  "drives-nominal": "drives, nominal (mu 1.0)",
                  "drives-uneven": "drives, uneven (mu 0.8 +-40 %)",
                  "drives-slippery": "drives, slippery (mu 0.3 +-30 %)",
                  "drives-worn": "drives, worn tyres (r +-2 %)"}

#: condition -> the floor's name in a profile file (ROBOT_FLOOR.yaml): the
#: drive model is the simulator's default, so its floors get the plain names
PROFILE_NAMES = {full: key.removeprefix("drives-") if key.startswith("drives-")
                 else f"ideal-{key}" for key, full in CONDITION_KEYS.items()}


def condition_name(text: str) -> str:
    """An argparse type: a condition's short name (``worn``) or full name."""
    if text in CONDITIONS:
        return text
    if text in CONDITION_KEYS:
        return CONDITION_KEYS[text]
    raise argparse.ArgumentTypeError(
        f"expected one of {', '.join(CONDITION_KEYS)}, got {text!r}")


@dataclass
class Trial:
    robot: str
    condition: str
    seed: int
    distance: float                      # [m] true path length
    position_error: dict = field(default_factory=dict)   # estimator -> [m]
    heading_error: dict = field(default_factory=dict)    # estimator -> [rad]
    seconds: float = 0.0                 # [s] wall time of the simulation
    internal_force_rms: float = 0.0      # [N] RMS of |f_int| over the run
    fault: str | None = None             # the controller's fault, if it stopped the run
    motion: str = "random"               # the kind of motion (holonomic_sim.motion_kinds)


def _body_command(pose, target, speed: float, wz_max: float) -> tuple[float, float, float]:
    """Proportional move to ``target`` (odom frame), as a body twist."""
    ex, ey = target[0] - pose[0], target[1] - pose[1]
    dist = math.hypot(ex, ey)
    v = min(speed, 2.0 * dist)
    vx_w, vy_w = (ex / dist * v, ey / dist * v) if dist > 1e-9 else (0.0, 0.0)
    wz = max(-wz_max, min(wz_max, 2.5 * wrap_angle(target[2] - pose[2])))
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return (c * vx_w + s * vy_w, -s * vx_w + c * vy_w, wz)


def run_overrides(seed: int, speed: float, acceleration: float,
                  overrides: dict | None = None) -> dict:
    """The config keys a run is made with: its seed, the limits (``speed``
    [m/s], ``acceleration`` [m/s^2]), then ``overrides``."""
    merged = {"sim.seed": seed, "cmd_timeout": 0.0, "enable_on_start": True}
    for axis in ("x", "y"):
        merged[f"limits.linear.{axis}.max_velocity"] = speed
        merged[f"limits.linear.{axis}.max_acceleration"] = acceleration
        merged[f"limits.linear.{axis}.max_deceleration"] = acceleration
    merged.update(overrides or {})
    return merged


def simulate(robot: str, seed: int, duration: float = 60.0, area=(1.5, 2.5),
             speed: float = 1.25, acceleration: float = 2.0, overrides: dict | None = None,
             calibration: dict | None = None, condition: str = "",
             finish=(0.0, 0.0, 0.0), motion: str = "random",
             straight: float = 0.0) -> Recording:
    """Random moves inside ``area`` [m] for ``duration`` [s] (targets drawn
    from ``seed``), then to ``finish`` (x, y, yaw in odom [m, m, rad];
    default back to the start), recorded (see the module docstring); another
    kind of ``motion`` (:mod:`holonomic_sim.motion_kinds`) drives its
    open-loop schedule for ``duration`` instead, then stops where it is.
    ``overrides``: config keys (a slip condition, simulator faults, the drive
    model); ``calibration``: a calibration overlay for the controller.
    ``straight`` [m] > 0: after the rest at ``finish``, one more pause and a
    straight run of about that length at constant heading (forward at
    STRAIGHT_SPEED, the heading held on the true pose as a user steers by
    eye: a worn robot commanded straight open loop curves), then a rest (a
    PCV's ``--distance --straight-run`` route). The simulated robot is built
    as holonomic-bringup builds it
    (:func:`holonomic_core.nominal.driver_for`): from the robot's config
    file's geometry and the ``sim.*`` errors, so neither the overlay nor a
    geometry key among ``overrides`` changes it (they are the controller's
    belief)."""
    merged = run_overrides(seed, speed, acceleration, overrides)
    cfg = load_config(robot, {**merged, **(calibration or {})})
    clock = ManualClock()
    driver = driver_for(cfg)
    rng = np.random.default_rng(seed)
    wz_max = min(1.5, cfg.controller.max_velocity[2])
    stamps, readings, truths, twists, internal = [], [], [], [], []
    t_wall = time.perf_counter()
    with driver:
        ctrl = BaseController(cfg, driver, clock=clock)
        ctrl.request_enable(True)

        def step():
            ctrl.step()
            clock.now = ctrl.reading.stamp
            stamps.append(ctrl.reading.stamp)
            readings.append(ctrl.reading.positions.copy())
            truth = driver.ground_truth()
            truths.append(truth.pose.copy())
            twists.append(truth.twist.copy())
            positions, forces = driver.wheel_contacts()
            internal.append(float(np.linalg.norm(internal_force(positions, forces))))

        step()
        if motion != "random":
            _drive_open_loop(ctrl, step, clock,
                             MotionPlan(motion, seed, duration, speed, wz_max), duration)
        half = np.array(area) / 2.0
        target, target_since = None, 0.0
        while motion == "random" and clock.now < duration:
            pose = truths[-1]
            reached = target is not None and math.hypot(*(target[:2] - pose[:2])) < 0.05
            if target is None or reached or clock.now - target_since > 4.0:
                target = np.array([rng.uniform(-half[0], half[0]), rng.uniform(-half[1], half[1]),
                                   rng.uniform(-math.pi, math.pi)])
                target_since = clock.now
            ctrl.set_command(_body_command(pose, target, speed, wz_max))
            step()
        home = np.array(finish, float)
        deadline = clock.now + 15.0
        while motion == "random" and clock.now < deadline:
            pose = truths[-1]
            if (math.hypot(*(pose[:2] - home[:2])) < 0.01
                    and abs(wrap_angle(pose[2] - home[2])) < 0.02):
                break
            ctrl.set_command(_body_command(pose, home, speed, wz_max))
            step()
        ctrl.set_command((0.0, 0.0, 0.0))
        for _ in range(int(0.5 * cfg.controller.control_rate)):
            step()
        if straight > 0:
            _straight_run(ctrl, step, clock, straight, lambda: truths[-1])
        fault = ctrl.fault
        hidden = dict(driver.hidden_truth)
    return Recording(robot, condition, seed, cfg, np.array(stamps), np.array(readings),
                     np.array(truths), np.array(twists), seconds=time.perf_counter() - t_wall,
                     internal_force=np.array(internal),
                     fault=None if fault is None else str(fault), hidden_truth=hidden,
                     motion=motion)


#: [m/s] the straight run's speed; [s] the rests around it (longer than the
#: calibration's SEGMENT_PAUSE, so the run is a stretch of motion of its
#: own); [1/s] the gain of the user's heading hold
STRAIGHT_SPEED, STRAIGHT_REST, HEADING_HOLD_GAIN = 0.5, 1.0, 1.0


def _straight_run(ctrl, step, clock, length: float, pose) -> None:
    """Rest, drive forward at STRAIGHT_SPEED for ``length`` [m] worth of
    time holding the start heading (``pose()``: the true pose, what the
    user sees), rest (``step``: one recorded control cycle)."""
    heading = pose()[2]
    for speed, seconds in ((0.0, STRAIGHT_REST), (STRAIGHT_SPEED, length / STRAIGHT_SPEED),
                           (0.0, STRAIGHT_REST)):
        end = clock.now + seconds
        while clock.now < end:
            turn = HEADING_HOLD_GAIN * wrap_angle(heading - pose()[2]) if speed else 0.0
            ctrl.set_command((speed, 0.0, turn))
            step()


def _drive_open_loop(ctrl, step, clock, plan: MotionPlan, duration: float) -> None:
    """Command ``plan``'s twist every cycle for ``duration`` [s] (``step``:
    one recorded control cycle)."""
    start = clock.now
    while clock.now - start < duration:
        ctrl.set_command(plan.twist_at(clock.now - start))
        step()


def record_run(robot: str, condition: str, seed: int, duration: float = 60.0,
               area=(1.5, 2.5), speed: float = 1.25, acceleration: float = 2.0,
               overrides: dict | None = None, calibration: dict | None = None,
               motion: str = "random") -> Recording:
    """One run of ``motion`` (default: random moves and the return) under a
    slip ``condition`` (a key of CONDITIONS), recorded; ``overrides`` /
    ``calibration`` as in :func:`simulate`, applied over the condition's
    settings."""
    return simulate(robot, seed, duration, area, speed, acceleration,
                    {**CONDITIONS[condition], **(overrides or {})}, calibration, condition,
                    motion=motion)


def recording_path(folder: str, robot: str, condition: str, seed: int, duration: float,
                   speed: float, acceleration: float, overrides: dict | None = None,
                   motion: str = "random") -> str:
    """Where ``--recordings FOLDER`` keeps one run: the file name holds every
    argument that changes the simulation (robot, condition, seed, duration,
    limits, the ``-p`` overrides, the kind of motion but random's), so a
    cached run is only reused for the same run."""
    extra = "".join(f"_{k}={v}" for k, v in sorted((overrides or {}).items()))
    kind = "" if motion == "random" else f"_{motion}"
    name = (f"{os.path.splitext(os.path.basename(robot))[0]}_{PROFILE_NAMES[condition]}{kind}"
            f"_seed{seed}"
            f"_{duration:g}s_{speed:g}mps_{acceleration:g}mps2{extra}.npz")
    return os.path.join(folder, name.replace(os.sep, "_"))


def save_recording(rec: Recording, path: str) -> None:
    """Write a recording's arrays to ``path`` (.npz, no pickled objects)."""
    tmp = path + ".part.npz"
    np.savez_compressed(tmp, stamps=rec.stamps, positions=rec.positions, truth=rec.truth,
                        truth_twist=rec.truth_twist, internal_force=rec.internal_force,
                        seconds=rec.seconds, fault=rec.fault or "",
                        hidden_truth=json.dumps(rec.hidden_truth))
    os.replace(tmp, path)


def load_recording(path: str, robot: str, condition: str, seed: int, config,
                   motion: str = "random") -> Recording:
    """A recording written by :func:`save_recording`; ``config``: the robot
    config the run was made with (not stored: it is re-loaded); ``motion``:
    its kind of motion (in its file name)."""
    with np.load(path, allow_pickle=False) as data:
        return Recording(robot, condition, seed, config, data["stamps"], data["positions"],
                         data["truth"], data["truth_twist"], seconds=float(data["seconds"]),
                         internal_force=data["internal_force"],
                         fault=str(data["fault"]) or None,
                         hidden_truth=json.loads(str(data["hidden_truth"])), motion=motion)


#: shortest --duration [s] with --self-calibrate: the first half of a run
#: (random driving, then the return) must hold the 20 s of motion the
#: geometry calibration asks for
SELF_CALIBRATION_DURATION = 40.0


def self_calibrated(rec: Recording, overrides: dict) -> tuple[Recording, float]:
    """``rec`` as the odometry sees it after a self-calibration of the
    robot's geometry (wheel radii, caster offsets, steering zeros; DDROT:
    radii, separation, turret zero) on the first half of the run, against
    its ground truth (:func:`holonomic_core.calibration.calibrate`, what
    ``holonomic-calibrate --reference ground_truth`` does with a recording;
    the second half is a drive the calibration has not seen). ``overrides``:
    the config keys the run was made with. Returns the recording with the
    calibrated config and the largest radius error left [%] against the
    simulator's hidden truth (nan when the run hid none). Raises
    CalibrationError when the half run cannot determine the geometry."""
    half = len(rec.stamps) // 2
    samples = samples_from_readings(rec.stamps[:half], rec.positions[:half], rec.truth[:half])
    overlay = calibrate(rec.config.model, samples, reference="ground_truth").overlay()
    errors = [abs(overlay[k] / v - 1.0) for k, v in rec.hidden_truth.items()
              if k in overlay and "radius" in k]
    return (replace(rec, config=load_config(rec.robot, {**overrides, **overlay})),
            100.0 * max(errors) if errors else float("nan"))


def final_errors(rec: Recording) -> Trial:
    """The final error of every estimator integrating the same recording."""
    path = rec.truth
    cfg = rec.config
    trial = Trial(rec.robot, rec.condition, rec.seed,
                  float(np.sum(np.linalg.norm(np.diff(path[:, :2], axis=0), axis=1))),
                  seconds=rec.seconds,
                  internal_force_rms=float(np.sqrt(np.mean(np.square(rec.internal_force))))
                  if rec.internal_force.size else 0.0,
                  fault=rec.fault, motion=rec.motion)
    for estimator in ESTIMATORS:
        odo = Odometry(cfg.model, estimator, cfg.controller.noise, cfg.controller.twist_window)
        for stamp, positions in zip(rec.stamps.tolist(), rec.positions):
            odo.update(positions, stamp)
        trial.position_error[estimator] = float(np.linalg.norm(odo.pose[:2] - path[-1, :2]))
        trial.heading_error[estimator] = abs(wrap_angle(odo.pose[2] - path[-1, 2]))
    return trial


def summarize(trials: list[Trial]) -> str:
    """The table: per condition and estimator, mean/median errors, ratios to
    pinv and in how many runs the estimator ended closer than pinv."""
    lines = []
    head = (f"{'condition':30s} {'estimator':9s} {'mean err':>9s} {'median':>8s} "
            f"{'mean hdg':>9s} {'mean/pinv':>9s} {'median/pinv':>11s} {'< pinv':>7s}")
    lines += [head, "-" * len(head)]

    def label(t):
        return t.condition if t.motion == "random" else f"{t.condition} / {t.motion}"

    for condition in dict.fromkeys(label(t) for t in trials):
        group = [t for t in trials if label(t) == condition]
        pos = {e: np.array([t.position_error[e] for t in group]) for e in ESTIMATORS}
        hdg = {e: np.array([t.heading_error[e] for t in group]) for e in ESTIMATORS}
        for e in ESTIMATORS:
            mean, median = pos[e].mean(), np.median(pos[e])
            lines.append(
                f"{condition:30s} {e:9s} {mean * 1000:7.1f}mm {median * 1000:6.1f}mm "
                f"{math.degrees(hdg[e].mean()):7.2f}deg {mean / pos['pinv'].mean():9.2f} "
                f"{median / np.median(pos['pinv']):11.2f} "
                f"{'' if e == 'pinv' else str(int(np.sum(pos[e] < pos['pinv']))):>7s}")
        dist = np.mean([t.distance for t in group])
        force = np.mean([t.internal_force_rms for t in group])
        faults = sum(t.fault is not None for t in group)
        lines.append(f"{'':30s} ({len(group)} runs, mean true path {dist:.1f} m, "
                     f"internal force RMS {force:.1f} N"
                     + (f"; the controller faulted in {faults}: see --json" if faults else "")
                     + ")")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="holonomic-odometry-experiment", formatter_class=ShowDefaults,
                            description=__doc__.split("\n\n")[0])
    parser.add_argument("--robot", type=robot_config, default="xr4000",
                        help="config name or YAML")
    parser.add_argument("--seeds", type=number(1, 10000, integer=True), default=20,
                        help="random runs per condition")
    parser.add_argument("--first-seed", type=number(0, 1000000, integer=True), default=0,
                        help="seed of the first run (the runs use --first-seed, +1, ...): a "
                             "drive none of the calibration's seeds made")
    parser.add_argument("--duration", type=number(0.0, 3600.0, strict_low=True, unit="s"),
                        default=60.0, help="random motion [s]")
    parser.add_argument("--speed", type=number(0.0, 10.0, strict_low=True, unit="m/s"),
                        default=1.25, help="top speed [m/s]")
    parser.add_argument("--acceleration", type=number(0.0, 100.0, strict_low=True,
                                                      unit="m/s^2"),
                        default=2.0, help="[m/s^2]")
    parser.add_argument("--condition", action="append", type=condition_name,
                        metavar="|".join(CONDITION_KEYS),
                        help="slip condition(s), repeatable (default: all): "
                             # argparse %-formats help strings: the names' "%" doubled
                             + "; ".join(f"{k} = {v}" for k, v in CONDITION_KEYS.items())
                             .replace("%", "%%"))
    parser.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="override a parameter in the drive-model conditions, "
                             "e.g. -p sim.drive.spread:=0.3")
    parser.add_argument("--json", type=output_file, metavar="FILE",
                        help="write every trial to FILE")
    parser.add_argument("--calibrate", action="store_true",
                        help="also fit the odometry covariance to ground truth over the runs, "
                             "print the coverage per condition and the odometry.* parameters")
    parser.add_argument("--default-floor", action="append", type=condition_name,
                        metavar="CONDITION",
                        help="with --calibrate: fit the one profile for several floors (a "
                             "config's default) on these recorded conditions only, "
                             "repeatable (default: every recorded one); its held-out coverage "
                             "is still shown on every floor")
    parser.add_argument("--self-calibrate", action="store_true",
                        help="before the odometry replays a run, calibrate the robot's "
                             "geometry (radii, caster offsets, steering zeros) on the first "
                             "half of that run against ground truth, as holonomic-calibrate "
                             "does: the covariance of a robot whose geometry is calibrated "
                             "(worn tyres after calibration)")
    parser.add_argument("--fit-motion", type=motion_list, default=None,
                        metavar="KIND[,KIND...]",
                        help="with --calibrate: the kinds of motion the covariance is fitted "
                             f"on, comma-separated among {', '.join(MOTION_KINDS)} (or all; "
                             "default: random); each is recorded on every --condition")
    parser.add_argument("--validate-motion", type=motion_list, default=[],
                        metavar="KIND[,KIND...]",
                        help="kinds of motion also recorded, to check the covariance on "
                             "(held out when not among --fit-motion), e.g. "
                             "teleop,sweep,nav2,straight,spin,creep")
    parser.add_argument("--validate-duration", type=number(0.0, 3600.0, strict_low=True,
                                                          unit="s"),
                        help="length of the runs of the --validate-motion kinds not among "
                             "--fit-motion [s] (default: --duration)")
    parser.add_argument("--validate-floor", action="append", type=condition_name,
                        metavar="CONDITION",
                        help="record the --validate-motion kinds on these conditions only, "
                             "repeatable (default: every --condition)")
    parser.add_argument("--check", action="store_true",
                        help="print the coverage of the config's own covariance parameters")
    parser.add_argument("--plot", type=output_file, metavar="PNG",
                        help="with --calibrate/--check: error against sigma, written to PNG")
    parser.add_argument("--profiles", metavar="DIR",
                        help="with --calibrate and several conditions: write one covariance "
                             "profile per floor to DIR/ROBOT_FLOOR.yaml (a params file for "
                             "holonomic-bringup --params-file)")
    parser.add_argument("--recordings", metavar="DIR",
                        help="keep each run's recording in DIR (one .npz per run, named by "
                             "its arguments) and reuse the ones already there: re-calibrate "
                             "or re-check without re-simulating")
    args = parser.parse_args(argv)
    if args.profiles and not args.calibrate:
        parser.error("--profiles needs --calibrate")
    if args.default_floor and not args.calibrate:
        parser.error("--default-floor needs --calibrate")
    if args.self_calibrate and args.duration < SELF_CALIBRATION_DURATION:
        parser.error(f"--self-calibrate needs --duration >= {SELF_CALIBRATION_DURATION:g} s "
                     "(the calibration wants 20 s of driving in each run's first half)")
    for option, floors in (("--default-floor", args.default_floor),
                           ("--validate-floor", args.validate_floor)):
        missing = set(floors or ()) - set(args.condition or CONDITIONS)
        if missing:
            parser.error(f"{option} {sorted(missing)[0]!r} is not among the --condition runs")
    for option, value in (("--validate-floor", args.validate_floor),
                          ("--validate-duration", args.validate_duration)):
        if value and not args.validate_motion:
            parser.error(f"{option} needs --validate-motion")
    if args.fit_motion and not args.calibrate:
        parser.error("--fit-motion needs --calibrate")
    fit_motions = args.fit_motion or ["random"]
    for option, folder in (("--profiles", args.profiles), ("--recordings", args.recordings)):
        try:    # before the runs, not after them
            if folder:
                os.makedirs(folder, exist_ok=True)
        except OSError as exc:
            parser.error(f"{option}: cannot create the folder {folder!r}: {exc.strerror}")
    try:
        drive_overrides = parse_overrides(args.param)
    except ValueError as exc:
        parser.error(str(exc))
    trials, recordings = [], []
    runs = [(condition, motion) for condition in args.condition or list(CONDITIONS)
            for motion in dict.fromkeys(fit_motions + args.validate_motion)
            if motion in fit_motions or args.validate_floor is None
            or condition in args.validate_floor]
    with progress(len(runs) * args.seeds, "holonomic-odometry-experiment", "runs") as bar:
        for condition, motion in runs:
            duration = (args.duration if motion in fit_motions or not args.validate_duration
                        else args.validate_duration)
            for seed in bar.over(range(args.first_seed, args.first_seed + args.seeds)):
                try:
                    drives = not CONDITIONS[condition]["sim.ideal_motors"]
                    extra = drive_overrides if drives else None
                    cached = args.recordings and recording_path(
                        args.recordings, args.robot, condition, seed, duration, args.speed,
                        args.acceleration, extra, motion)
                    rec = None
                    overrides = run_overrides(seed, args.speed, args.acceleration,
                                              {**CONDITIONS[condition], **(extra or {})})
                    if cached and os.path.exists(cached):
                        config = load_config(args.robot, overrides)
                        try:
                            rec = load_recording(cached, args.robot, condition, seed, config,
                                                 motion)
                        except (OSError, ValueError, KeyError) as exc:
                            bar.write(f"{cached}: unreadable ({exc}), simulating the run "
                                      "again")
                    if rec is None:
                        rec = record_run(args.robot, condition, seed, duration,
                                         speed=args.speed, acceleration=args.acceleration,
                                         overrides=extra, motion=motion)
                        if cached:
                            save_recording(rec, cached)
                except ConfigError as exc:      # e.g. per-wheel radii on a DDROT
                    bar.write(f"{condition}: skipped for {args.robot} ({exc})")
                    bar.skip(args.first_seed + args.seeds - seed)
                    break
                note = ""
                if args.self_calibrate:
                    try:
                        rec, radius_error = self_calibrated(rec, overrides)
                    except CalibrationError as exc:
                        bar.write(f"{condition} seed {seed}: left out, the self-calibration "
                                  f"failed ({exc})")
                        continue
                    note = f"  radii calibrated to {radius_error:.2f} %"
                trial = final_errors(rec)
                trials.append(trial)
                if args.calibrate or args.check:
                    recordings.append(rec)
                errs = "  ".join(f"{e} {trial.position_error[e] * 1000:6.1f}mm" for e in ESTIMATORS)
                label = condition if motion == "random" else f"{condition} / {motion}"
                bar.write(f"{label:41s} seed {seed:3d}: {trial.distance:5.1f} m  {errs}  "
                          f"({trial.seconds:.1f} s){note}"
                          f"{'  FAULT: ' + trial.fault if trial.fault else ''}")
    if not trials and args.self_calibrate:
        print("holonomic-odometry-experiment: no run could be self-calibrated (the reasons "
              "above)", file=sys.stderr)
        return 2
    print(summarize(trials))
    if args.json:
        with open(args.json, "w") as handle:
            json.dump([t.__dict__ for t in trials], handle, indent=1)
    if recordings:
        from holonomic_core.odometry_calibration import calibrate_main
        # the replays of the odometry over every run: the long part of --calibrate
        with progress(len(recordings), "holonomic-odometry-experiment replay",
                      "recordings") as bar:
            calibrate_main(recordings, fit_noise=args.calibrate, plot_path=args.plot,
                           per_floor=True, profile_dir=args.profiles,
                           floor_names=PROFILE_NAMES, default_floors=args.default_floor,
                           fit_motions=fit_motions, bar=bar,
                           command=" ".join(["holonomic-odometry-experiment",
                                             *(argv if argv is not None else sys.argv[1:])]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
