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
  heading, rad), over ``--seeds`` seeds x the slip conditions.

Prints a table (mean and median per estimator and condition, and the ratios
to ``pinv``) and, with ``--json``, writes every trial.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from holonomic_core.controller import BaseController, load_config
from holonomic_core.kinematics import ESTIMATORS
from holonomic_core.loop import ManualClock
from holonomic_core.odometry import Odometry, wrap_angle
from holonomic_core.schema import ConfigError

#: slip conditions: name -> simulator overrides (per-wheel friction spread is
#: re-drawn from each trial's seed)
CONDITIONS = {
    "nominal (mu 1.0)": {"sim.wheel_friction": 1.0, "sim.friction_spread": 0.0},
    "uneven (mu 0.8 +-40 %)": {"sim.wheel_friction": 0.8, "sim.friction_spread": 0.4},
    "slippery (mu 0.3 +-30 %)": {"sim.wheel_friction": 0.3, "sim.friction_spread": 0.3},
    "worn tyres (r +-2 %)": {"sim.wheel_friction": 1.0, "sim.friction_spread": 0.0,
                             "sim.wheel_radius_spread": 0.02},
}


@dataclass
class Trial:
    robot: str
    condition: str
    seed: int
    distance: float                      # [m] true path length
    position_error: dict = field(default_factory=dict)   # estimator -> [m]
    heading_error: dict = field(default_factory=dict)    # estimator -> [rad]
    seconds: float = 0.0                 # [s] wall time of the simulation


def _body_command(pose, target, speed: float, wz_max: float) -> tuple[float, float, float]:
    """Proportional move to ``target`` (odom frame), as a body twist."""
    ex, ey = target[0] - pose[0], target[1] - pose[1]
    dist = math.hypot(ex, ey)
    v = min(speed, 2.0 * dist)
    vx_w, vy_w = (ex / dist * v, ey / dist * v) if dist > 1e-9 else (0.0, 0.0)
    wz = max(-wz_max, min(wz_max, 2.5 * wrap_angle(target[2] - pose[2])))
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return (c * vx_w + s * vy_w, -s * vx_w + c * vy_w, wz)


@dataclass
class Run:
    """The recording of one simulated run: every joint reading as the
    controller saw it (encoder zeros subtracted) and the true pose."""

    config: object                       # the RobotConfig the controller ran
    stamps: list = field(default_factory=list)       # [s]
    positions: list = field(default_factory=list)    # joint positions [rad]
    truths: list = field(default_factory=list)       # (x, y, yaw) [m, m, rad] in odom
    hidden_truth: dict = field(default_factory=dict)  # the simulator's hidden geometry


def simulate(robot: str, seed: int, duration: float = 60.0, area=(1.5, 2.5),
             speed: float = 1.25, acceleration: float = 2.0,
             overrides: dict | None = None, calibration: dict | None = None) -> Run:
    """Random moves inside ``area`` [m] for ``duration`` [s] (targets drawn
    from ``seed``), then back to the start. ``overrides``: config keys for
    the controller and the simulated robot (e.g. simulator faults);
    ``calibration``: config keys for the controller only (a calibration
    overlay), so the simulated robot keeps its geometry and faults."""
    merged = {"sim.seed": seed, "cmd_timeout": 0.0, "enable_on_start": True}
    for axis in ("x", "y"):
        merged[f"limits.linear.{axis}.max_velocity"] = speed
        merged[f"limits.linear.{axis}.max_acceleration"] = acceleration
        merged[f"limits.linear.{axis}.max_deceleration"] = acceleration
    merged.update(overrides or {})
    cfg = load_config(robot, {**merged, **(calibration or {})})
    physical = load_config(robot, merged).model if calibration else cfg.model
    clock = ManualClock()
    driver = cfg.driver_class(physical, cfg.values, cfg.controller.control_rate)
    rng = np.random.default_rng(seed)
    wz_max = min(1.5, cfg.controller.max_velocity[2])
    run = Run(cfg)
    readings, truths = run.positions, run.truths
    with driver:
        ctrl = BaseController(cfg, driver, clock=clock)
        ctrl.request_enable(True)

        def step():
            ctrl.step()
            clock.now = ctrl.reading.stamp
            run.stamps.append(ctrl.reading.stamp)
            readings.append(ctrl.reading.positions.copy())
            truths.append(driver.ground_truth().pose.copy())

        step()
        half = np.array(area) / 2.0
        target, target_since = None, 0.0
        while clock.now < duration:
            pose = truths[-1]
            reached = target is not None and math.hypot(*(target[:2] - pose[:2])) < 0.05
            if target is None or reached or clock.now - target_since > 4.0:
                target = np.array([rng.uniform(-half[0], half[0]), rng.uniform(-half[1], half[1]),
                                   rng.uniform(-math.pi, math.pi)])
                target_since = clock.now
            ctrl.set_command(_body_command(pose, target, speed, wz_max))
            step()
        home = np.zeros(3)
        deadline = clock.now + 15.0
        while clock.now < deadline:
            pose = truths[-1]
            if math.hypot(*pose[:2]) < 0.01 and abs(wrap_angle(pose[2])) < 0.02:
                break
            ctrl.set_command(_body_command(pose, home, speed, wz_max))
            step()
        ctrl.set_command((0.0, 0.0, 0.0))
        for _ in range(int(0.5 * cfg.controller.control_rate)):
            step()
        run.hidden_truth = dict(getattr(driver, "hidden_truth", {}))
    return run


def run_trial(robot: str, condition: str, seed: int, duration: float = 60.0,
              area=(1.5, 2.5), speed: float = 1.25, acceleration: float = 2.0,
              overrides: dict | None = None, calibration: dict | None = None) -> Trial:
    """One random run and return; the final error of every estimator.
    ``overrides``: config keys applied over the condition's (e.g. a fixed
    ``sim.seed`` for one set of tyres); ``calibration``: a calibration
    overlay for the controller (see :func:`simulate`)."""
    t_wall = time.perf_counter()
    run = simulate(robot, seed, duration, area, speed, acceleration,
                   {**CONDITIONS[condition], **(overrides or {})}, calibration)
    cfg, truths = run.config, run.truths
    readings = list(zip(run.stamps, run.positions))
    truth_end = truths[-1]
    path = np.array(truths)
    trial = Trial(robot, condition, seed,
                  float(np.sum(np.linalg.norm(np.diff(path[:, :2], axis=0), axis=1))),
                  seconds=time.perf_counter() - t_wall)
    for estimator in ESTIMATORS:
        odo = Odometry(cfg.model, estimator, cfg.controller.noise)
        for stamp, positions in readings:
            odo.update(positions, stamp)
        trial.position_error[estimator] = float(np.linalg.norm(odo.pose[:2] - truth_end[:2]))
        trial.heading_error[estimator] = abs(wrap_angle(odo.pose[2] - truth_end[2]))
    return trial


def summarize(trials: list[Trial]) -> str:
    """The table: per condition and estimator, mean/median errors, ratios to
    pinv and in how many runs the estimator ended closer than pinv."""
    lines = []
    head = (f"{'condition':26s} {'estimator':9s} {'mean err':>9s} {'median':>8s} "
            f"{'mean hdg':>9s} {'mean/pinv':>9s} {'median/pinv':>11s} {'< pinv':>7s}")
    lines += [head, "-" * len(head)]
    for condition in dict.fromkeys(t.condition for t in trials):
        group = [t for t in trials if t.condition == condition]
        pos = {e: np.array([t.position_error[e] for t in group]) for e in ESTIMATORS}
        hdg = {e: np.array([t.heading_error[e] for t in group]) for e in ESTIMATORS}
        for e in ESTIMATORS:
            mean, median = pos[e].mean(), np.median(pos[e])
            lines.append(
                f"{condition:26s} {e:9s} {mean * 1000:7.1f}mm {median * 1000:6.1f}mm "
                f"{math.degrees(hdg[e].mean()):7.2f}deg {mean / pos['pinv'].mean():9.2f} "
                f"{median / np.median(pos['pinv']):11.2f} "
                f"{'' if e == 'pinv' else str(int(np.sum(pos[e] < pos['pinv']))):>7s}")
        dist = np.mean([t.distance for t in group])
        lines.append(f"{'':26s} ({len(group)} runs, mean true path {dist:.1f} m)")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="holonomic-odometry-experiment",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--robot", default="xr4000", help="config name or YAML (default xr4000)")
    parser.add_argument("--seeds", type=int, default=20, help="random runs per condition")
    parser.add_argument("--duration", type=float, default=60.0, help="random motion [s]")
    parser.add_argument("--speed", type=float, default=1.25, help="top speed [m/s]")
    parser.add_argument("--acceleration", type=float, default=2.0, help="[m/s^2]")
    parser.add_argument("--condition", action="append", choices=list(CONDITIONS),
                        help="slip condition(s) (default: all)")
    parser.add_argument("--json", metavar="FILE", help="write every trial to FILE")
    args = parser.parse_args(argv)
    trials = []
    for condition in args.condition or list(CONDITIONS):
        for seed in range(args.seeds):
            try:
                trial = run_trial(args.robot, condition, seed, args.duration,
                                  speed=args.speed, acceleration=args.acceleration)
            except ConfigError as exc:      # e.g. per-wheel radii on a DDROT
                print(f"{condition}: skipped for {args.robot} ({exc})", file=sys.stderr)
                break
            trials.append(trial)
            errs = "  ".join(f"{e} {trial.position_error[e] * 1000:6.1f}mm" for e in ESTIMATORS)
            print(f"{condition:26s} seed {seed:3d}: {trial.distance:5.1f} m  {errs}  "
                  f"({trial.seconds:.1f} s)", file=sys.stderr, flush=True)
    print(summarize(trials))
    if args.json:
        with open(args.json, "w") as handle:
            json.dump([t.__dict__ for t in trials], handle, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
