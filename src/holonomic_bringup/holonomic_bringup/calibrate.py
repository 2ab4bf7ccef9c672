"""``holonomic-calibrate ROBOT RECORDING.mcap``: the robot's kinematic
parameters from a recording of ordinary driving (``holonomic-bringup --record``).

Reads the joint states (and the simulator's ground truth) with the recorded
configuration's model -- the one the controller ran, whose encoder zeros the
recorded joint positions already have subtracted -- estimates the parameters
(holonomic_core.calibration: a PCV's wheel radii, caster offsets and steering
zeros, the common scale from a measured distance, best a straight run:
``--distance D --straight-run``; a DDROT's wheel radii, wheel separation and
turret zero), prints each
estimate with its standard error and writes a ROS 2 params-file overlay that
``holonomic-bringup ROBOT --params-file OVERLAY`` loads over the robot config.
Bad input (no such file, not a recording, too little or too one-sided
motion) is one line on stderr and exit status 2.
"""

from __future__ import annotations

import datetime
import math
import sys
from pathlib import Path

import numpy as np
import yaml

from holonomic_core.command_line import ArgumentParser

#: node key of the overlay: every node of the bringup, under any namespace
OVERLAY_NODE = "/**"


def overlay_document(values: dict[str, float]) -> dict:
    """Flat config keys -> a nested ROS 2 params-file document."""
    tree: dict = {}
    for key, value in values.items():
        node = tree
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = round(float(value), 7)
    return {OVERLAY_NODE: {"ros__parameters": tree}}


def read_recording(path: Path, robot: str, namespace: str | None):
    """(model, recorded flat config, stamps [s], positions (N x joints) [rad],
    true poses or None) of one robot of the recording; raises ValueError with
    a one-line reason."""
    from holonomic_bringup.recording_plot import joint_arrays, load, stamped_poses
    from holonomic_core.config import build_model, load_model

    try:
        robots, series, _ = load(path)
    except Exception as exc:  # a truncated or foreign file
        raise ValueError(f"cannot read {path} as an MCAP recording: {exc}") from exc
    if not robots:
        raise ValueError(f"{path} has no robot (not made by holonomic-bringup --record)")
    if namespace is None:
        if len(robots) > 1:
            raise ValueError(f"{path} holds {len(robots)} robots: choose one with --namespace "
                             f"({', '.join(sorted(robots))})")
        namespace = next(iter(robots))
    ns = "/" + namespace.strip("/") if namespace.strip("/") else "/"
    if ns not in robots:
        raise ValueError(f"no robot in namespace {ns} (recorded: {', '.join(sorted(robots))})")
    model = build_model(robots[ns])[0]
    expected = load_model(robot).name
    if model.name != expected:
        raise ValueError(f"the recording is of robot '{model.name}', not '{expected}'")
    prefix = "" if ns == "/" else ns
    joints = series.get(f"{prefix}/joint_states", [])
    if len(joints) < 2:
        raise ValueError(f"too short: {len(joints)} joint_states messages in {path}")
    stamps, positions, _, _ = joint_arrays(model, joints)
    truth = None
    gt = stamped_poses(series.get(f"{prefix}/ground_truth/odom", []))
    if gt:
        # ground truth is published with the joint states of the same cycle
        matched = [k for k, s in enumerate(stamps) if s in gt]
        stamps, positions = stamps[matched], positions[matched]
        truth = np.array([gt[s] for s in stamps]) if len(matched) else None
    return model, robots[ns], stamps, positions, truth


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="holonomic-calibrate",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("robot", help="config name or YAML of the recorded robot")
    parser.add_argument("recording", type=Path, help="an MCAP file from holonomic-bringup --record")
    parser.add_argument("--reference", choices=("none", "ground_truth"), default="none",
                        help="ground_truth: the simulator's true motion fixes the scale "
                             "(a DDROT needs it)")
    parser.add_argument("--distance", type=float, metavar="METRES",
                        help="a PCV: measured straight-line distance from where the recording "
                             "starts to where it ends, or with --straight-run the length of its "
                             "straight run (fixes the scale of the radii); a DDROT: "
                             "how far the straight run ended along its start heading")
    parser.add_argument("--straight-run", action="store_true",
                        help="a PCV: --distance is the measured length of the recording's last "
                             "stretch of motion, a straight run at constant heading after a "
                             "pause (default: from where the recording starts to where it ends)")
    parser.add_argument("--lateral", type=float, default=0.0, metavar="METRES",
                        help="a DDROT: how far the straight run ended to the left (negative: "
                             "right) of its start heading (default 0)")
    parser.add_argument("--turns", type=float, metavar="N",
                        help="a DDROT: revolutions of the recording's rotation in place "
                             "(counted, the remainder measured; with --distance)")
    parser.add_argument("--heading-deg", type=float, metavar="DEG",
                        help="a DDROT: measured change of heading over the straight run "
                             "(counter-clockwise positive); with it the turret zero is "
                             "estimated too")
    parser.add_argument("--namespace", help="the robot's namespace in a fleet recording")
    parser.add_argument("--output", type=Path,
                        help="overlay to write (default: RECORDING with .calibration.yaml)")
    args = parser.parse_args(argv)

    from holonomic_core.calibration import (CalibrationError, calibrate, calibrate_measured,
                                            family_for, find_reference_segments,
                                            last_straight_run, samples_from_readings)
    from holonomic_core.schema import ConfigError

    def fail(message: str) -> int:
        print(f"holonomic-calibrate: {message}", file=sys.stderr)
        return 2

    if args.distance is not None and args.reference == "ground_truth":
        return fail("give either --reference ground_truth or --distance, not both")
    if args.distance is not None and not args.distance > 0:
        return fail(f"--distance must be a measured distance > 0 m, got {args.distance:g}")
    if args.turns is not None and not args.turns > 0:
        return fail(f"--turns must be a counted number of turns > 0, got {args.turns:g}")
    if args.heading_deg is not None and args.turns is None:
        return fail("--heading-deg needs --distance and --turns (a DDROT's measured run)")
    if args.straight_run and args.distance is None:
        return fail("--straight-run needs --distance: the measured length of the straight run")
    if args.straight_run and args.turns is not None:
        return fail("--straight-run is for a pcv; a ddrot's --distance with --turns is already "
                    "its straight run")
    if args.turns is not None and args.distance is None:
        return fail("--turns needs --distance: the straight run fixes the radii, the rotation "
                    "the separation")
    if not args.recording.is_file():
        return fail(f"no such file: {args.recording}")
    try:
        model, recorded, stamps, positions, truth = read_recording(
            args.recording, args.robot, args.namespace)
        if args.reference == "ground_truth" and truth is None:
            raise CalibrationError("--reference ground_truth needs ground_truth/odom in the "
                                   "recording (simulator runs publish it)")
        if args.straight_run and model.kind != "pcv":
            raise CalibrationError(f"--straight-run is for a pcv, not a {model.kind} (a ddrot's "
                                   "--distance with --turns is its straight run)")
        measured = model.kind == "ddrot" and args.distance is not None
        if measured:
            if args.turns is None:
                raise CalibrationError("a ddrot needs --turns with --distance: the rotation in "
                                       "place fixes the wheel separation")
            reference = "measured"
            segments = find_reference_segments(family_for(model), stamps, positions)
            result = calibrate_measured(
                model, segments, args.distance, args.lateral, args.turns,
                None if args.heading_deg is None else math.radians(args.heading_deg))
        else:
            if args.turns is not None:
                raise CalibrationError(f"--turns is for a ddrot (a {model.kind} calibrates "
                                       "from its own redundancy plus --distance)")
            samples = samples_from_readings(stamps, positions,
                                            truth if args.reference == "ground_truth" else None)
            reference = "distance" if args.distance is not None else args.reference
            line = None
            if args.straight_run:
                first, last = last_straight_run(family_for(model), stamps, positions)
                line = samples_from_readings(stamps[first:last + 1], positions[first:last + 1])
            result = calibrate(model, samples, reference, args.distance, distance_samples=line)
    except (ValueError, ConfigError) as exc:   # CalibrationError is a ValueError
        return fail(str(exc))
    fit = "" if reference == "measured" else \
        f", rms residual {result.rms_residual * 1e6:.1f} um"
    print(f"{model.name} ({model.kind}) from {args.recording}: {result.samples} samples, "
          f"reference {reference}{fit}")
    print(result.table())
    if model.kind == "pcv" and recorded.get("control_mode", "velocity") == "velocity":
        result.notes.append("recorded in velocity mode: the wheel and steering loops impose the "
                            "configured kinematics on the joints, so errors hardly show in them; "
                            "record with -p control_mode:=torque (docs/calibration.md)")
    for note in result.notes:
        print(f"note: {note}")
    out = args.output or args.recording.with_suffix(".calibration.yaml")
    header = (f"# holonomic-calibrate {args.robot} {args.recording.name} (reference "
              f"{reference}), {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC\n"
              "# load with: holonomic-bringup ROBOT --params-file THIS_FILE\n")
    for line in result.table().splitlines():
        header += f"#   {line}\n"
    try:
        out.write_text(header + yaml.safe_dump(overlay_document(result.overlay()),
                                               sort_keys=False))
    except OSError as exc:
        return fail(f"cannot write {out}: {exc}")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
