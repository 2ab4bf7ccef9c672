"""``holonomic-calibration-experiment``: self-calibration against the simulator's hidden truth.

For each robot: the simulator gets seeded geometry errors the controller does
not know (``sim.wheel_radius_spread``, ``sim.caster_offset_spread`` or
``sim.wheel_separation_spread``, ``sim.steer_zero_spread``); the base drives
``--duration`` seconds of random teleop-like moves (the odometry experiment's
driver, offline: controller core + sim driver, no ROS); holonomic_core's
calibration estimates the parameters from the joint readings (with the ground
truth as the scale reference, and for a PCV also without it); the table
compares true and estimated values. Then the odometry experiment runs on the
same faulty robot with the configured and with the calibrated parameters,
and without faults, over ``--seeds`` paths: the final position error of the
slip-minimising odometry before and after calibration.

The steps (a measured drive, a calibration per reference, an odometry path
per seed; with ``--routes``, the trials) report their progress on stderr
(holonomic_core.progress): a bar with the time left on a terminal, plain
lines with the time left in a log. The tables stay on stdout, unchanged.
"""

from __future__ import annotations

import math
import sys

import numpy as np

from holonomic_core.calibration import (CalibrationError, calibrate, calibrate_measured,
                                        family_for, find_reference_segments,
                                        samples_from_readings)
from holonomic_core.command_line import ArgumentParser
from holonomic_core.model import load_model
from holonomic_core.progress import Progress, progress
from holonomic_core.schema import ConfigError
from holonomic_sim.calibration_drives import CALIBRATION_DRIVE, FAULTS, reference_drive
from holonomic_sim.calibration_routes import ROUTES, TABLE_HEAD, route_trial
from holonomic_sim.odometry_experiment import final_errors, record_run, simulate

#: the calibration's targets: relative error of lengths, absolute error of zeros [rad]
TARGETS = {("pcv", "radius"): 0.002, ("pcv", "offset"): 0.02, ("pcv", "zero"): math.radians(0.2),
           ("ddrot", "radius"): 0.003, ("ddrot", "length"): 0.003,
           ("ddrot", "zero"): math.radians(0.2)}


def calibration_run(robot: str, sim_seed: int, duration: float = 60.0,
                    reference: str = "ground_truth", faults: dict | None = None,
                    passes: int = 2, control_mode: str | None = None):
    """(result, truth, errors) of a simulated calibration: ``passes``
    drives of ``duration`` [s], each with the previous pass's estimate
    loaded; ``control_mode`` overrides CALIBRATION_DRIVE's. Errors per
    parameter: relative for lengths, radians for zeros."""
    kind = load_model(robot).kind
    faults = FAULTS[kind] if faults is None else faults
    drive = dict(CALIBRATION_DRIVE[kind])
    if control_mode is not None:
        drive["control_mode"] = control_mode
    overlay = None
    for _ in range(passes):
        run = simulate(robot, sim_seed, duration,
                       overrides={**faults, **drive, "sim.seed": sim_seed},
                       calibration=overlay)
        samples = samples_from_readings(run.stamps, run.positions, run.truth)
        result = calibrate(run.config.model, samples, reference)
        overlay = result.overlay()
    fam = result.family
    # the truth of every parameter: hidden where perturbed, else the config's
    configured = load_model(robot).params
    truth = {key: run.hidden_truth.get(key, configured[key]) for key in fam.keys}
    errors = [result.theta[i] - truth[key] if fam.kinds[i] == "zero"
              else result.theta[i] / truth[key] - 1.0 for i, key in enumerate(fam.keys)]
    return result, truth, np.array(errors)


#: the odometry experiment's condition of the before/after runs: nominal
#: floor on the simulator's default drive model (as the calibration drives)
ODOMETRY_CONDITION = "drives, nominal (mu 1.0)"


def odometry_errors(robot: str, sim_seed: int, overlay: dict, seeds: int,
                    faults: dict, condition: str = ODOMETRY_CONDITION,
                    bar: Progress | None = None) -> dict[str, list[float]]:
    """Final slip_min position errors [m] per path seed under the odometry
    experiment's ``condition``: without faults, with the faults and the
    configured parameters, with the faults and the calibrated ones.
    ``bar``: advanced once per path, and each run's line written through it
    (on stderr, above the bar on a terminal)."""
    out = {"no faults": [], "faults, configured": [], "faults, calibrated": []}
    fixed = {**faults, "sim.seed": sim_seed}
    bar = bar or Progress(seeds, "odometry paths")     # the lines alone, no display
    for seed in bar.over(range(seeds)):
        for name, overrides, calibration in (("no faults", {}, None),
                                             ("faults, configured", fixed, None),
                                             ("faults, calibrated", fixed, overlay)):
            trial = final_errors(record_run(robot, condition, seed,
                                            overrides=overrides, calibration=calibration))
            out[name].append(trial.position_error["slip_min"])
            bar.write(f"  {name:20s} path {seed}: {trial.position_error['slip_min'] * 1e3:6.1f} "
                      f"mm over {trial.distance:.1f} m")
    return out


def print_measured(robot: str, sim_seed: int, faults: dict) -> bool:
    """Calibrate a DDROT from a measured line and rotation (reference_drive)
    without and with the run's heading change; print the true-vs-estimated
    tables. False when the calibration refused."""
    run = reference_drive(robot, sim_seed, faults=faults)
    fam = family_for(run.config.model)
    truth = {k: run.hidden_truth.get(k, run.config.model.params[k]) for k in fam.keys}
    print(f"\n{robot}: measured line and rotation (5 m forward, 3 turns about the axle, drive "
          f"model), faults {faults}; the user measures forward {run.forward:.4f} m, lateral "
          f"{run.lateral:.4f} m, heading {math.degrees(run.heading):+.3f} deg, "
          f"{run.turns:.4f} turns")
    try:
        segments = find_reference_segments(fam, run.stamps, run.positions)
        for heading in (None, run.heading):
            result = calibrate_measured(run.config.model, segments, run.forward, run.lateral,
                                        run.turns, heading)
            print(f"  {'with' if heading is not None else 'without'} --heading-deg:")
            print("\n".join("    " + line for line in result.table(truth).splitlines()))
            for i, key in enumerate(fam.keys):
                if fam.kinds[i] != "zero":
                    print(f"    error {fam.labels[i]}: "
                          f"{100 * (result.theta[i] / truth[key] - 1):+.3f} %")
    except CalibrationError as exc:
        print(f"{robot}: {exc}")
        return False
    return True


def _references(kind: str, ground_truth_only: bool) -> tuple[str, ...]:
    """The references a family is calibrated against: a PCV also without one."""
    return ("ground_truth", "none") if kind == "pcv" and not ground_truth_only \
        else ("ground_truth",)


def routes_main(kinds: list[tuple[str, str]], seeds: int, only: list[str] | None) -> int:
    """``--routes``: every route of every robot ((robot, its family) pairs)
    over fault seeds 1..``seeds``; prints the table (stdout) and each trial as
    it ends (stderr), with the progress over the trials. 1 when a trial missed
    the route's criterion."""
    rows, failed = [], False
    trials = [(robot, route, seed) for robot, kind in kinds
              for route in ROUTES.get(kind, ()) if not only or route in only
              for seed in range(1, seeds + 1)]
    with progress(len(trials), "holonomic-calibration-experiment", "trials") as bar:
        for robot, route, seed in bar.over(trials):
            try:
                trial = route_trial(robot, route, seed)
            except CalibrationError as exc:
                rows.append(f"| {seed} | {robot} | {route} | refused: {exc} | | | **no** |")
                failed = True
                continue
            rows.append(trial.row())
            failed |= not trial.passed()
            bar.write(rows[-1] + f" path {trial.path_length:.1f} m")
    print(TABLE_HEAD)
    print("\n".join(rows))
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="holonomic-calibration-experiment",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--robot", action="append",
                        help="config name or YAML (repeatable; default xr4000, comr3, hamr)")
    parser.add_argument("--duration", type=float, default=60.0,
                        help="each calibration drive [s] (default: 2 passes x 60 s)")
    parser.add_argument("--sim-seed", type=int, default=1, help="seed of the hidden faults")
    parser.add_argument("--passes", type=int, default=2,
                        help="calibration drives, each with the previous estimate loaded")
    parser.add_argument("--seeds", type=int, default=3,
                        help="odometry runs (paths) per condition; 0 skips them")
    parser.add_argument("--control-mode", choices=("torque", "velocity"),
                        help="of the calibration drives (default: torque for a PCV, velocity "
                             "for a DDROT)")
    parser.add_argument("--faults", choices=("all", "tyres"), default="all",
                        help="all hidden faults, or the wheel radii only (the odometry "
                             "experiment's 'worn tyres' condition)")
    parser.add_argument("--ground-truth-only", action="store_true",
                        help="a PCV: skip the calibration without a reference")
    parser.add_argument("--measured-only", action="store_true",
                        help="a DDROT: only the measured line-and-rotation calibration "
                             "(reference_drive), not the random drives")
    parser.add_argument("--routes", type=int, metavar="N",
                        help="instead: the documented calibration routes end to end "
                             "(holonomic_sim.calibration_routes) over fault seeds 1..N, "
                             "a markdown table of the held-out path's position errors")
    parser.add_argument("--route", action="append", choices=("ground_truth", "distance", "tape"),
                        help="with --routes: only this route (repeatable; default: every "
                             "route of each robot's family)")
    args = parser.parse_args(argv)
    if args.routes is not None:
        if not 1 <= args.routes <= 100:
            parser.error(f"--routes N must be 1..100, got {args.routes}")
    elif args.route:
        parser.error("--route needs --routes N")
    robots = args.robot or (["xr4000", "hamr"] if args.routes is not None
                            else ["xr4000", "comr3", "hamr"])
    try:    # every robot's family before the first drive: the progress's total needs them
        kinds = [(robot, load_model(robot).kind) for robot in robots]
    except ConfigError as exc:
        print(f"holonomic-calibration-experiment: {exc}", file=sys.stderr)
        return 2
    if args.routes is not None:
        return routes_main(kinds, args.routes, args.route)
    # the steps: a measured drive (DDROT), a calibration per reference, an odometry path per seed
    seeds = max(args.seeds, 0)
    total = sum((kind == "ddrot") + (0 if args.measured_only else
                                      len(_references(kind, args.ground_truth_only)) + seeds)
                for _, kind in kinds)
    failed = False
    with progress(total, "holonomic-calibration-experiment", "steps") as bar:
        for robot, kind in kinds:
            if kind == "ddrot":
                failed |= not print_measured(robot, args.sim_seed,
                                             FAULTS[kind] if args.faults == "all" else
                                             {"sim.wheel_radius_spread": 0.02})
                bar.advance()
            if args.measured_only:
                continue
            faults = FAULTS[kind] if args.faults == "all" else {"sim.wheel_radius_spread": 0.02}
            references = _references(kind, args.ground_truth_only)
            overlay = None
            for reference in bar.over(references):
                try:
                    result, truth, errors = calibration_run(robot, args.sim_seed, args.duration,
                                                            reference, faults, args.passes,
                                                            args.control_mode)
                except CalibrationError as exc:
                    print(f"{robot}: {exc}")
                    failed = True
                    continue
                fam = result.family
                print(f"\n{robot} ({kind}), {args.passes} x {args.duration:g} s drive, "
                      f"faults {faults}, reference {reference}: {result.samples} samples, "
                      f"rms residual {result.rms_residual * 1e6:.1f} um")
                print(result.table(truth))
                for note in result.notes:
                    print(f"  note: {note}")
                for k in dict.fromkeys(fam.kinds):
                    sel = [i for i, kk in enumerate(fam.kinds) if kk == k]
                    worst = float(np.max(np.abs(errors[sel])))
                    target = TARGETS.get((kind, k))
                    shown = (f"{math.degrees(worst):.3f} deg" if k == "zero"
                             else f"{100 * worst:.3f} %")
                    goal = "" if target is None else (
                        f" (target {math.degrees(target):.1f} deg)" if k == "zero"
                        else f" (target {100 * target:.1f} %)")
                    print(f"  worst {k} error: {shown}{goal}")
                if reference == "ground_truth":
                    overlay = result.overlay()
            if overlay is not None and args.seeds > 0:
                errs = odometry_errors(robot, args.sim_seed, overlay, args.seeds, faults, bar=bar)
                print(f"{robot}: final slip_min odometry error, mean of {args.seeds} random "
                      "60 s runs (odometry experiment):")
                for name, values in errs.items():
                    print(f"  {name:20s} {np.mean(values) * 1e3:6.1f} mm")
            else:
                bar.skip(seeds)                 # no calibration to run them with
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
