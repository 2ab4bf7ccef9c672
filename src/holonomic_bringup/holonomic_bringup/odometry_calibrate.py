"""``holonomic-odometry-calibrate``: calibrate the odometry covariance on your floor.

Reads MCAP recordings made with ``holonomic-bringup ROBOT --record FILE``
(the robot's config, ``joint_states``) plus a reference of the true pose as
``nav_msgs/Odometry`` (``ground_truth/odom`` in the simulator; on a real
robot a motion-capture or total-station topic recorded alongside, e.g.
``--reference-topic /mocap/odom``), replays the odometry over the joint
readings, and fits the ``odometry.*`` covariance parameters exactly as
``holonomic-odometry-experiment --calibrate`` does (same code:
``holonomic_core.odometry_calibration``). Prints the coverage before and
after and the block to paste into the config file. Drive the way the robot
will be driven (speeds, turns, the floors it will see) for a few minutes,
with ``publish_rate`` equal to ``control_rate``: the replay runs at the rate
of the recorded ``joint_states``.

The reference's own frame does not matter: poses are taken relative to the
reference's first pose. Its twist must be in base_link (as nav_msgs/Odometry
specifies); without one (all zeros) the twist coverage is meaningless.

Reading each recording and replaying the odometry over it take seconds per
minute of driving: the progress over them goes to stderr
(holonomic_core.progress), a bar with the time left on a terminal, plain
lines with the time left in a log.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from holonomic_bringup.recording_plot import odom_arrays, load
from holonomic_core.command_line import ArgumentParser
from holonomic_core.config import config_from_flat
from holonomic_core.progress import progress
from holonomic_core.schema import ConfigError
from holonomic_core.se2 import relative_poses, wrap_angle


def recording_from_mcap(path: Path, namespace: str = "", reference_topic: str = "ground_truth/odom"):
    """A :class:`holonomic_core.odometry_calibration.Recording` from one MCAP file."""
    from holonomic_core.odometry_calibration import Recording

    if not path.is_file():
        raise ConfigError("FILE", str(path), "an existing MCAP file")
    try:
        robots, series, _ = load(path)
    except Exception as exc:  # a truncated or foreign file: say so, no traceback
        raise ConfigError("FILE", str(path), f"an MCAP recording ({exc})") from exc
    # the recorder keys robots by their namespace as ROS writes it ("/rec", "")
    wanted = {namespace, "/" + namespace.strip("/")} if namespace.strip("/") else {"", "/"}
    found = [ns for ns in robots if ns in wanted]
    if not found and not namespace and len(robots) == 1:
        found = list(robots)
    if not found:
        raise ConfigError("--namespace", namespace, f"one of the recorded robots {sorted(robots)}")
    cfg = config_from_flat(robots[found[0]], str(path))
    prefix = "/" + found[0].strip("/") if found[0].strip("/") else ""
    joints = series.get(f"{prefix}/joint_states") or series.get("joint_states") or []
    reference = (series.get(reference_topic) or series.get(f"/{reference_topic}")
                 or series.get(f"{prefix}/{reference_topic}") or [])
    if len(joints) < 10 or len(reference) < 10:
        raise ConfigError("FILE", str(path), f"a recording with joint_states and {reference_topic} "
                          f"(found {len(joints)} and {len(reference)} messages)")
    names = cfg.model.joint_names
    order = [list(joints[0][1].name).index(j) for j in names]
    stamps = np.array([t for t, _ in joints])
    positions = np.array([np.asarray(m.position)[order] for _, m in joints])
    t_ref, pose, twist = odom_arrays(reference)
    # the reference's first pose is the odometry's origin; the heading kept
    # unwrapped for the interpolation below
    rel = relative_poses(np.broadcast_to(pose[0], pose.shape), pose)
    rel[:, 2] = np.unwrap(pose[:, 2] - pose[0, 2])
    keep = (stamps >= t_ref[0]) & (stamps <= t_ref[-1])
    stamps, positions = stamps[keep], positions[keep]
    truth = np.column_stack([np.interp(stamps, t_ref, rel[:, k]) for k in range(3)])
    truth[:, 2] = [wrap_angle(v) for v in truth[:, 2]]
    truth_twist = np.column_stack([np.interp(stamps, t_ref, twist[:, k]) for k in range(3)])
    # the odometry starts where the first kept reading is: re-origin the truth there
    truth = relative_poses(np.broadcast_to(truth[0], truth.shape), truth)
    return Recording(cfg.model.name, path.name, 0, cfg, stamps, positions, truth, truth_twist)


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="holonomic-odometry-calibrate",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("files", nargs="+", type=Path, help="MCAP recordings")
    parser.add_argument("--namespace", default="", help="robot namespace in the recording")
    parser.add_argument("--reference-topic", default="ground_truth/odom",
                        help="nav_msgs/Odometry topic of the true pose (default ground_truth/odom)")
    parser.add_argument("--plot", metavar="PNG", help="error against sigma, written to PNG")
    args = parser.parse_args(argv)
    from holonomic_core.odometry_calibration import calibrate_main

    # the steps: reading each recording, then replaying the odometry over each
    with progress(2 * len(args.files), "holonomic-odometry-calibrate", "steps") as bar:
        try:
            recordings = [recording_from_mcap(f, args.namespace, args.reference_topic)
                          for f in bar.over(args.files)]
        except (ConfigError, OSError, ValueError) as exc:
            bar.write(f"holonomic-odometry-calibrate: {exc}")
            return 2
        calibrate_main(recordings, fit_noise=True, plot_path=args.plot, bar=bar)
    return 0


if __name__ == "__main__":
    sys.exit(main())
