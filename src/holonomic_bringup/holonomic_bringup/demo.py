"""``holonomic-demo``: the simulated robot under a scripted teleop, headless.

Starts ``holonomic-bringup ROBOT --enable`` as a separate process (the robot),
then acts as a teleop client over ROS: forward, strafe at constant heading,
diagonal, spin in place, a straight line in the odom frame while spinning,
then home to the start pose by odometry. Prints a table per segment --
commanded and achieved twist (ground truth) and odometry error -- and writes
a PNG of the ground-truth and odometry paths.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from holonomic_bringup.process_guard import STOP, install_signal_handlers
from holonomic_core.command_line import ArgumentParser, ShowDefaults, robot_config
from holonomic_core.se2 import rotate, wrap_angle
from holonomic_core.teleop_script import Segment, body_command, demo_script


SCRIPT = demo_script()
RATE = SCRIPT.rate   # [Hz] teleop publish rate
STEADY = 0.5         # fraction of a segment (its end) averaged as "achieved"


def achieved(samples, frame: str) -> np.ndarray:
    """Mean ground-truth twist in ``frame`` over ``samples``."""
    rows = []
    for s in samples:
        vx, vy, wz = s.twist
        if frame == "odom":
            vx, vy = rotate(vx, vy, s.pose[2])
        rows.append((vx, vy, wz))
    return np.mean(rows, axis=0) if rows else np.full(3, np.nan)


def go_home(client, timeout: float = 12.0) -> float:
    """Drive back to the odometry origin (position and heading); returns seconds."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        x, y, yaw = client.latest_odom().pose
        dist = math.hypot(x, y)
        if dist < 0.01 and abs(yaw) < math.radians(1.0):
            break
        speed = min(0.5, 1.5 * dist)
        vx_w, vy_w = (-x / dist * speed, -y / dist * speed) if dist > 1e-9 else (0.0, 0.0)
        wz = max(-1.5, min(1.5, -2.0 * wrap_angle(yaw)))
        client.publish(*rotate(vx_w, vy_w, -yaw), wz)
        time.sleep(1.0 / RATE)
    client.wait_at_rest(timeout=5.0)
    return time.monotonic() - t0


def error_between(client_odom_pose, truth_pose) -> float:
    return float(np.linalg.norm(np.asarray(client_odom_pose[:2]) - np.asarray(truth_pose[:2])))


def plot(path: Path, client, robot: str, marks) -> None:
    """The demo's PNG: paths (ground truth, odometry, headings) with each
    segment's start numbered, and the true body twist over time with the same
    numbers over each segment's span. ``marks``: [(name, start pose (x, y,
    yaw) in odom, start, end [s, time.monotonic])] in script order."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    truth = np.array([s.pose for s in client.truth])
    odom = np.array([s.pose for s in client.odom])
    # path on top (its own aspect ratio, the full width), twist below
    fig, (ax, axv) = plt.subplots(2, 1, figsize=(11, 11), height_ratios=(1.1, 1))
    step = max(1, len(truth) // 40)
    ax.quiver(truth[::step, 0], truth[::step, 1], np.cos(truth[::step, 2]),
              np.sin(truth[::step, 2]), color="0.65", scale=30, width=0.003, zorder=1,
              label="heading (ground truth)")
    ax.plot(truth[:, 0], truth[:, 1], "k-", lw=2, label="ground truth", zorder=2)
    ax.plot(odom[:, 0], odom[:, 1], "r--", lw=1.5, label="odometry", zorder=3)
    # Segments are numbered where they start (several start at the same
    # place, e.g. spin in place: their numbers share one label there).
    starts: list[tuple[np.ndarray, list[str]]] = []
    for i, (_, pose, _, _) in enumerate(marks, 1):
        for point, numbers in starts:
            if np.linalg.norm(point - pose[:2]) < 0.03:
                numbers.append(str(i))
                break
        else:
            starts.append((np.asarray(pose[:2]), [str(i)]))
    for point, numbers in starts:
        ax.plot(*point, "o", color="tab:blue", ms=5, zorder=4)
        ax.annotate(",".join(numbers), point, xytext=(6, 6), textcoords="offset points",
                    fontsize=9, color="tab:blue", zorder=5,
                    bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="tab:blue", lw=0.5))
    ax.set_aspect("equal")
    ax.margins(0.08)
    ax.set_xlabel("x [m] (odom)")
    ax.set_ylabel("y [m] (odom)")
    ax.set_title(f"{robot}: path, ground truth vs odometry")
    handles, _ = ax.get_legend_handles_labels()
    handles.append(Line2D([], [], marker="o", ls="", color="tab:blue",
                          label="start of segment n (table)"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8,
              borderaxespad=0.0)

    t_truth = np.array([s.t for s in client.truth])
    tw = np.array([s.twist for s in client.truth])
    t0 = t_truth[0]
    for i, (label, color) in enumerate((("vx [m/s]", "tab:red"), ("vy [m/s]", "tab:green"),
                                        ("wz [rad/s]", "tab:blue"))):
        axv.plot(t_truth - t0, tw[:, i], color=color, label=label)
    top = max(1.0, float(np.max(tw))) * 1.18
    axv.set_ylim(min(-1.0, float(np.min(tw)) * 1.1), top)
    for i, (name, _, start, end) in enumerate(marks, 1):
        axv.axvspan(start - t0, end - t0, color="0.5" if i % 2 else "0.8", alpha=0.12, lw=0)
        axv.text(0.5 * (start + end) - t0, top * 0.97, str(i), ha="center", va="top",
                 fontsize=9, color="tab:blue")
    axv.set_xlabel("time [s]")
    axv.set_ylabel("body twist in base_link")
    axv.set_title("ground-truth body twist; shaded: segment n of the table")
    axv.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0)
    axv.grid(True, alpha=0.3)
    key = "   ".join(f"{i} {name}" for i, (name, _, _, _) in enumerate(marks, 1))
    fig.text(0.5, 0.005, "segments: " + key, ha="center", va="bottom", fontsize=8.5, wrap=True)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def format_table(rows, final) -> str:
    head = (f"{'segment':34s} {'frame':9s} {'commanded (vx, vy, wz)':>24s} "
            f"{'achieved (ground truth)':>26s} {'track err':>9s} {'odom err':>9s}")
    lines = [head, "-" * len(head)]
    for seg, ach, err_pct, odom_err in rows:
        cmd = "({:+.2f}, {:+.2f}, {:+.2f})".format(*seg.twist)
        got = "({:+.3f}, {:+.3f}, {:+.3f})".format(*ach)
        lines.append(f"{seg.name:34s} {seg.frame:9s} {cmd:>24s} {got:>26s} "
                     f"{err_pct:8.1f}% {odom_err * 100:7.1f}cm")
    lines.append("-" * len(head))
    lines.append(final)
    return "\n".join(lines)


class Interrupted(Exception):
    """SIGINT/SIGTERM during the demo."""


def _check(robot: subprocess.Popen, log_path: Path) -> None:
    """Raise when the user stopped the demo or the robot process has ended."""
    if STOP.is_set():
        raise Interrupted
    if robot.poll() is not None:
        last = [line for line in log_path.read_text().splitlines() if line.strip()][-1:]
        raise RuntimeError(f"the robot (holonomic-bringup) exited with status {robot.returncode}"
                           + (f": {last[0]}" if last else ""))


def parse_args(argv):
    parser = ArgumentParser(prog="holonomic-demo", description=__doc__.split("\n\n")[0],
                            formatter_class=ShowDefaults)
    parser.add_argument("--robot", type=robot_config, default="hamr",
                        help="config name (hamr, xr4000, comr3) or a robot YAML")
    parser.add_argument("--out", default="out", type=Path,
                        help="folder for the plot and the robot's log")
    args = parser.parse_args(argv)
    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        parser.error(f"--out: cannot create {str(args.out)!r}: {exc.strerror}")
    return args


def main(argv: list[str] | None = None) -> int:
    install_signal_handlers()
    args = parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from holonomic_bringup.robot_client import RobotClient
    from holonomic_core.se2 import relative_pose

    out = args.out
    log_path = out / f"demo_{Path(args.robot).stem}_bringup.log"
    with open(log_path, "w") as log:
        # its own session: a Ctrl-C in the terminal reaches the demo, which
        # then stops the robot itself (SIGINT below)
        robot = subprocess.Popen(
            [sys.executable, "-m", "holonomic_bringup.bringup", args.robot, "--enable",
             "--namespace", "demo"], stdout=log, stderr=subprocess.STDOUT,
            start_new_session=True)
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("holonomic_demo_teleop")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinning = threading.Event()
    spinning.set()

    def spin():
        while spinning.is_set():
            executor.spin_once(timeout_sec=0.05)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    client = RobotClient(node, "demo")
    code = 0
    try:
        print(f"starting the simulated {args.robot} (log: {log_path}) ...", flush=True)
        deadline = time.monotonic() + 60.0
        while True:
            _check(robot, log_path)
            try:
                client.wait_ready(timeout=0.5)
                break
            except TimeoutError:
                if time.monotonic() > deadline:
                    raise
        segs = []
        # (segment, start pose in odom, start and end time [s, monotonic])
        marks = []
        for seg in SCRIPT.segments:
            client.wait_at_rest()
            o0, g0 = client.latest_odom().pose, client.latest_truth().pose
            t0 = time.monotonic()
            while time.monotonic() - t0 < seg.seconds:
                _check(robot, log_path)
                client.publish(*body_command(seg, client.latest_odom().pose[2], RATE))
                time.sleep(1.0 / RATE)
            ach = achieved(client.truth_since(t0 + (1 - STEADY) * seg.seconds), seg.frame)
            client.wait_at_rest()
            cmd = np.array(seg.twist)
            scale = max(np.linalg.norm(cmd[:2]), 1e-9) if np.any(cmd[:2]) else abs(cmd[2])
            err = np.linalg.norm((ach - cmd)[:2] if np.any(cmd[:2]) else (ach - cmd)[2:]) / scale
            # odometry error accumulated over the segment: relative motions compared
            d_odom = relative_pose(o0, client.latest_odom().pose)
            d_truth = relative_pose(g0, client.latest_truth().pose)
            segs.append((seg, ach, 100 * err, float(np.linalg.norm(d_odom[:2] - d_truth[:2]))))
            marks.append((seg.name, g0, t0, t0 + seg.seconds))
        _check(robot, log_path)
        g0, t0 = client.latest_truth().pose, time.monotonic()
        seconds = go_home(client)
        home = Segment("home (by odometry)", (0.0, 0.0, 0.0), seconds, "odom")
        marks.append((home.name, g0, t0, t0 + seconds))
        final_truth, final_odom = client.latest_truth().pose, client.latest_odom().pose
        segs.append((home, np.zeros(3), 0.0, error_between(final_odom, final_truth)))
        truth = np.array([s.pose for s in client.truth])
        travelled = float(np.sum(np.linalg.norm(np.diff(truth[:, :2], axis=0), axis=1)))
        err = error_between(final_odom, final_truth)
        final = (f"end: odometry vs ground truth {err * 100:.1f} cm after {travelled:.2f} m "
                 f"({100 * err / travelled:.2f} % of distance); heading error "
                 f"{math.degrees(wrap_angle(final_odom[2] - final_truth[2])):+.2f} "
                 f"deg; true distance from start {np.linalg.norm(final_truth[:2]) * 100:.1f} cm")
        print(format_table(segs, final))
        png = out / f"demo_{Path(args.robot).stem}.png"
        plot(png, client, args.robot, marks)
        print(f"plot written to {png.resolve()}")
    except Interrupted:
        print("holonomic-demo: interrupted; stopping the robot", file=sys.stderr)
        code = 130
    except (TimeoutError, RuntimeError) as exc:
        print(f"holonomic-demo: {exc}; see {log_path}", file=sys.stderr)
        code = 1
    finally:
        for _ in range(3):
            client.publish()      # zero twist: stop before the robot shuts down
        spinning.clear()
        thread.join(1.0)
        if robot.poll() is None:
            robot.send_signal(signal.SIGINT)
        try:
            robot.wait(15)
        except subprocess.TimeoutExpired:
            robot.kill()
            robot.wait()
        client.close()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
