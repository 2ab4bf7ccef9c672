"""``holonomic-demo``: the simulated robot under a scripted teleop, headless.

Starts ``holonomic-bringup ROBOT --enable`` as a separate process (the robot),
then acts as a teleop client over ROS: forward, strafe at constant heading,
diagonal, spin in place, a straight line in the odom frame while spinning,
then home to the start pose by odometry. Prints a table per segment --
commanded and achieved twist (ground truth) and odometry error -- and writes
a PNG of the ground-truth and odometry paths.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Segment:
    """A scripted motion. ``twist`` (vx, vy, wz); in ``frame`` base_link
    (a body twist) or odom (vx, vy in the odom frame, turned into a body
    twist every cycle with the odometry heading)."""

    name: str
    twist: tuple[float, float, float]
    seconds: float
    frame: str = "base_link"


SCRIPT = (
    Segment("forward", (0.5, 0.0, 0.0), 3.0),
    Segment("strafe left (constant heading)", (0.0, 0.4, 0.0), 3.0),
    Segment("diagonal", (0.35, -0.35, 0.0), 3.0),
    Segment("spin in place", (0.0, 0.0, 1.5), 3.0),
    Segment("translate while rotating", (0.3, 0.2, 0.6), 4.0),
    Segment("line in odom while spinning", (-0.3, 0.2, 1.0), 4.0, frame="odom"),
)
RATE = 50.0          # [Hz] teleop publish rate
STEADY = 0.5         # fraction of a segment (its end) averaged as "achieved"


def body_command(seg: Segment, yaw: float) -> tuple[float, float, float]:
    """The body twist to publish now; ``yaw`` [rad]: the odometry heading."""
    vx, vy, wz = seg.twist
    if seg.frame == "odom":
        # The command holds until the next one: aim at the mid-period heading.
        yaw += 0.5 * wz / RATE
        c, s = math.cos(yaw), math.sin(yaw)
        return (c * vx + s * vy, -s * vx + c * vy, wz)
    return seg.twist


def achieved(samples, frame: str) -> np.ndarray:
    """Mean ground-truth twist in ``frame`` over ``samples``."""
    rows = []
    for s in samples:
        vx, vy, wz = s.twist
        if frame == "odom":
            c, si = math.cos(s.pose[2]), math.sin(s.pose[2])
            vx, vy = c * vx - si * vy, si * vx + c * vy
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
        wz = max(-1.5, min(1.5, -2.0 * math.remainder(yaw, 2 * math.pi)))
        c, s = math.cos(yaw), math.sin(yaw)
        client.publish(c * vx_w + s * vy_w, -s * vx_w + c * vy_w, wz)
        time.sleep(1.0 / RATE)
    client.wait_at_rest(timeout=5.0)
    return time.monotonic() - t0


def error_between(client_odom_pose, truth_pose) -> float:
    return float(np.linalg.norm(np.asarray(client_odom_pose[:2]) - np.asarray(truth_pose[:2])))


def plot(path: Path, client, robot: str, marks) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    truth = np.array([s.pose for s in client.truth])
    odom = np.array([s.pose for s in client.odom])
    fig, (ax, axv) = plt.subplots(1, 2, figsize=(13, 6))
    ax.plot(truth[:, 0], truth[:, 1], "k-", lw=2, label="ground truth")
    ax.plot(odom[:, 0], odom[:, 1], "r--", lw=1.5, label="odometry")
    step = max(1, len(truth) // 40)
    ax.quiver(truth[::step, 0], truth[::step, 1], np.cos(truth[::step, 2]),
              np.sin(truth[::step, 2]), color="0.5", scale=30, width=0.003, label="heading")
    for name, pose in marks:
        ax.annotate(name, pose[:2], fontsize=8, color="tab:blue")
        ax.plot(*pose[:2], "o", color="tab:blue", ms=4)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m] (odom)")
    ax.set_ylabel("y [m] (odom)")
    ax.set_title(f"{robot}: path, ground truth vs odometry")
    ax.legend(loc="best")
    t_truth = np.array([s.t for s in client.truth])
    tw = np.array([s.twist for s in client.truth])
    t0 = t_truth[0]
    for i, (label, color) in enumerate((("vx [m/s]", "tab:red"), ("vy [m/s]", "tab:green"),
                                        ("wz [rad/s]", "tab:blue"))):
        axv.plot(t_truth - t0, tw[:, i], color=color, label=label)
    axv.set_xlabel("time [s]")
    axv.set_title("ground-truth body twist")
    axv.legend()
    axv.grid(True, alpha=0.3)
    fig.tight_layout()
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="holonomic-demo", description=__doc__.split("\n")[0])
    parser.add_argument("--robot", default="hamr", help="config name or YAML (default hamr)")
    parser.add_argument("--out", default="out", help="folder for the plot (default out/)")
    args = parser.parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from holonomic_bringup.robot_client import RobotClient, relative_pose

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    log_path = out / f"demo_{Path(args.robot).stem}_bringup.log"
    with open(log_path, "w") as log:
        robot = subprocess.Popen(
            [sys.executable, "-m", "holonomic_bringup.bringup", args.robot, "--enable",
             "--namespace", "demo"], stdout=log, stderr=subprocess.STDOUT)
    rclpy.init()
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
        client.wait_ready(timeout=60.0)
        segs = []
        marks = [("start", client.latest_truth().pose)]
        for seg in SCRIPT:
            client.wait_at_rest()
            o0, g0 = client.latest_odom().pose, client.latest_truth().pose
            t0 = time.monotonic()
            while time.monotonic() - t0 < seg.seconds:
                client.publish(*body_command(seg, client.latest_odom().pose[2]))
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
            marks.append((seg.name.split(" ")[0], client.latest_truth().pose))
        seconds = go_home(client)
        home = Segment("home (by odometry)", (0.0, 0.0, 0.0), seconds, "odom")
        final_truth, final_odom = client.latest_truth().pose, client.latest_odom().pose
        segs.append((home, np.zeros(3), 0.0, error_between(final_odom, final_truth)))
        truth = np.array([s.pose for s in client.truth])
        travelled = float(np.sum(np.linalg.norm(np.diff(truth[:, :2], axis=0), axis=1)))
        err = error_between(final_odom, final_truth)
        final = (f"end: odometry vs ground truth {err * 100:.1f} cm after {travelled:.2f} m "
                 f"({100 * err / travelled:.2f} % of distance); heading error "
                 f"{math.degrees(math.remainder(final_odom[2] - final_truth[2], 2 * math.pi)):+.2f} "
                 f"deg; true distance from start {np.linalg.norm(final_truth[:2]) * 100:.1f} cm")
        print(format_table(segs, final))
        png = out / f"demo_{Path(args.robot).stem}.png"
        plot(png, client, args.robot, marks)
        print(f"plot written to {png.resolve()}")
    except TimeoutError as exc:
        print(f"holonomic-demo: {exc}; see {log_path}", file=sys.stderr)
        code = 1
    finally:
        spinning.clear()
        thread.join(1.0)
        robot.send_signal(signal.SIGINT)
        try:
            robot.wait(15)
        except subprocess.TimeoutExpired:
            robot.kill()
        client.close()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
