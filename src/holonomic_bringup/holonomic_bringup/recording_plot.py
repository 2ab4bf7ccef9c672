"""``holonomic-plot run.mcap``: figures of a recording made with
``holonomic-bringup --record``.

For each robot in the file (one per namespace): the path by odometry and by
ground truth (simulator), the commanded, estimated and true body velocities
over time, and -- for a powered-caster vehicle -- each caster's slip
residual, recomputed from the recorded joint states with the robot's own
model (its configuration is stored in the file). Prints a summary: duration,
messages per topic, final odometry error against ground truth.
"""

from __future__ import annotations

import os
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import yaml

from holonomic_core.command_line import ArgumentParser, ShowDefaults
from holonomic_core.se2 import wrap_angle, yaw_of_quaternion


def _yaw(q) -> float:
    return yaw_of_quaternion((q.x, q.y, q.z, q.w))


def load(path: Path) -> tuple[dict, dict[str, list], dict[str, str]]:
    """(robots: namespace -> flat config, topic -> [(t [s], msg)], topic -> type)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    robots: dict[str, dict] = {}
    series: dict[str, list] = defaultdict(list)
    types: dict[str, str] = {}
    with open(path, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        for record in reader.iter_metadata():
            if record.name == "holonomic_robot":
                doc = yaml.safe_load(record.metadata["config"])
                robots[record.metadata["namespace"]] = doc["base_controller"]["ros__parameters"]
        t0 = None
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            t = message.log_time * 1e-9
            t0 = t if t0 is None else t0
            series[channel.topic].append((t - t0, decoded))
            types[channel.topic] = schema.name
    return robots, series, types


def odom_arrays(samples):
    t = np.array([s[0] for s in samples])
    pose = np.array([(m.pose.pose.position.x, m.pose.pose.position.y,
                      _yaw(m.pose.pose.orientation)) for _, m in samples])
    twist = np.array([(m.twist.twist.linear.x, m.twist.twist.linear.y,
                       m.twist.twist.angular.z) for _, m in samples])
    return t, pose, twist


def _cmd_arrays(samples):
    t = np.array([s[0] for s in samples])
    rows = []
    for _, m in samples:
        body = m.twist if hasattr(m, "header") else m
        rows.append((body.linear.x, body.linear.y, body.angular.z))
    return t, np.array(rows)


def joint_arrays(model, samples) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """From joint_states samples: (header stamps [s], positions, velocities
    (N x joints) in ``model.joint_names`` order, receive times [s])."""
    order = None
    stamps, pos, vel, t = [], [], [], []
    for received, m in samples:
        if order is None:
            order = [list(m.name).index(j) for j in model.joint_names]
        stamps.append(m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec)
        pos.append(np.asarray(m.position)[order])
        vel.append(np.asarray(m.velocity)[order])
        t.append(received)
    n = len(model.joint_names)
    return (np.array(stamps), np.array(pos).reshape(-1, n), np.array(vel).reshape(-1, n),
            np.array(t))


def stamped_poses(samples) -> dict[float, np.ndarray]:
    """Odometry messages -> {header stamp [s]: (x, y, yaw) [m, m, rad]}."""
    return {m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec: np.array(
        (m.pose.pose.position.x, m.pose.pose.position.y, _yaw(m.pose.pose.orientation)))
        for _, m in samples}


def slip_residuals(flat: dict, samples) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Per-unit slip residuals [m/s] from joint_states samples, with the model
    of ``flat``; empty for a base without redundancy (the DDROT)."""
    from holonomic_core.config import build_model
    model = build_model(flat)[0]
    kin = model.kinematics
    names = list(getattr(kin, "caster_names", ()))
    if not names or not samples:
        return np.zeros(0), np.zeros((0, 0)), names
    estimator = flat.get("estimator", "slip_min")
    _, positions, velocities, t = joint_arrays(model, samples)
    rows = [kin.fit_residual(q, v, estimator) for q, v in zip(positions, velocities)]
    return t, np.array(rows), names


def plot_robot(ns: str, flat: dict, series: dict, out: Path, stem: str) -> tuple[list[Path], dict]:
    """The figures of one robot; returns (paths, summary numbers)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    prefix = "" if ns == "/" else ns
    name = flat.get("robot.name", "robot")
    label = name if ns == "/" else f"{name} in {ns}"
    tag = stem + ("" if ns == "/" else "_" + ns.strip("/").replace("/", "_"))
    figures, summary = [], {}
    odom = series.get(f"{prefix}/odom", [])
    truth = series.get(f"{prefix}/ground_truth/odom", [])
    cmd = series.get(f"{prefix}/cmd_vel", [])
    if odom:
        t_o, pose_o, tw_o = odom_arrays(odom)
        fig, (ax, axv) = plt.subplots(1, 2, figsize=(13, 5.5))
        ax.plot(pose_o[:, 0], pose_o[:, 1], "r--", label="odometry")
        if truth:
            t_g, pose_g, tw_g = odom_arrays(truth)
            ax.plot(pose_g[:, 0], pose_g[:, 1], "k-", lw=2, alpha=0.7, label="ground truth")
            summary["final_position_error_m"] = float(np.hypot(*(pose_o[-1, :2] - pose_g[-1, :2])))
            summary["final_heading_error_rad"] = abs(wrap_angle(pose_o[-1, 2] - pose_g[-1, 2]))
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x [m] (odom)")
        ax.set_ylabel("y [m] (odom)")
        ax.set_title(f"{label}: path")
        ax.legend(fontsize=8)
        colors = ("tab:red", "tab:green", "tab:blue")
        for i, comp in enumerate(("vx [m/s]", "vy [m/s]", "wz [rad/s]")):
            axv.plot(t_o, tw_o[:, i], color=colors[i])
            if truth:
                axv.plot(t_g, tw_g[:, i], color=colors[i], alpha=0.35, lw=3)
            if cmd:
                t_c, c = _cmd_arrays(cmd)
                axv.step(t_c, c[:, i], where="post", color=colors[i], linestyle=":")
        axv.set_xlabel("time [s]")
        axv.set_ylabel("body twist in base_link")
        axv.set_title(f"{label}: body velocity")
        # One legend for every line: the colour says the component, the
        # style the source.
        from matplotlib.lines import Line2D
        handles = [Line2D([], [], color=c, label=comp) for c, comp in
                   zip(colors, ("vx [m/s]", "vy [m/s]", "wz [rad/s]"))]
        handles.append(Line2D([], [], color="0.3", label="odometry"))
        if truth:
            handles.append(Line2D([], [], color="0.3", alpha=0.35, lw=3, label="ground truth"))
        if cmd:
            handles.append(Line2D([], [], color="0.3", ls=":", label="cmd_vel"))
        axv.legend(handles=handles, fontsize=8, ncol=2)
        axv.grid(True, alpha=0.3)
        fig.tight_layout()
        path = out / f"{tag}_motion.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        figures.append(path)
    t_s, slip, units = slip_residuals(flat, series.get(f"{prefix}/joint_states", []))
    if len(t_s):
        fig, ax = plt.subplots(figsize=(10, 4))
        for k, unit in enumerate(units):
            ax.plot(t_s, 1e3 * slip[:, k], label=unit)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("slip residual [mm/s]")
        ax.set_title(f"{label}: per-caster contact slip the odometry fit cannot explain")
        ax.legend()
        fig.tight_layout()
        path = out / f"{tag}_slip.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        figures.append(path)
        summary["max_slip_residual_m_s"] = float(slip.max())
    return figures, summary


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="holonomic-plot", description=__doc__.split("\n\n")[0],
                            formatter_class=ShowDefaults)
    parser.add_argument("recording", type=Path, help="an MCAP file from holonomic-bringup --record")
    parser.add_argument("--out", type=Path, help="folder of the PNGs (default: beside the file)")
    args = parser.parse_args(argv)
    if not args.recording.is_file():
        parser.error(f"no such file: {args.recording}")
    try:
        robots, series, types = load(args.recording)
    except Exception as exc:  # a truncated or foreign file: say so, no traceback
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        parser.error(f"cannot read {args.recording} as an MCAP recording: {first}")
    if not robots:
        parser.error(f"{args.recording} has no robot (not made by holonomic-bringup --record)")
    out = args.out or args.recording.parent
    try:
        out.mkdir(parents=True, exist_ok=True)
        if not os.access(out, os.W_OK):
            raise PermissionError(13, "not writable")
    except OSError as exc:
        parser.error(f"--out: cannot write into {str(out)!r}: {exc.strerror}")
    duration = max((s[-1][0] for s in series.values() if s), default=0.0)
    print(f"{args.recording}: {duration:.1f} s, {len(robots)} robot(s)")
    for topic in sorted(series):
        print(f"  {topic:40s} {types[topic]:36s} {len(series[topic]):6d} messages")
    for ns, flat in robots.items():
        figures, summary = plot_robot(ns, flat, series, out, args.recording.stem)
        numbers = ", ".join(f"{k} {v:.4f}" for k, v in summary.items())
        print(f"{ns}: {numbers or 'no odometry recorded'}")
        for path in figures:
            print(f"  wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
