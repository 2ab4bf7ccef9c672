"""A/B of the XR4000 torque-mode 1 kHz loop with the simulator's physics in
the loop process (``sim.physics_process: false``, the default) and in a
process of its own (``true``), in one window, without and with real-time
scheduling; the traffic of bench/ros_loop.py's 1 kHz rows (cmd_vel 100 Hz
in; odom, joint_states, /tf at 1 kHz out). Per row it adds what those rows
do not: the physics process's CPU and sim time over wall time (from the
driver's diagnostics). ``--profile``: instead, where the control cycle's
time goes with the physics in its own process (cProfile, ROS-free).

    python bench/physics_process_ab.py [SECONDS]      # 4 rows, default 60 s each
    python bench/physics_process_ab.py --profile

Numbers in docs/realtime.md ("The simulator's physics in a process of its own").
"""

from __future__ import annotations

import json
import os
import sys
import time

import ros_loop        # bench/, the script's own directory

CASE = ["xr4000", "--driver", "sim", "-p", "control_mode:=torque",
        "-p", "sim.physics_rate:=1000.0"]
#: the row's keys printed (bench/ros_loop.py's result, and the ones added here)
KEYS = ("physics_process", "realtime", "rate_hz", "period_p99_ms_median_window",
        "period_p99_ms_worst_window", "period_max_ms", "periods_over_2ms", "periods_over_5ms",
        "node_cpu_percent", "loop_cpu_percent", "physics_cpu_percent", "sim_per_wall",
        "physics_status", "split", "over_2ms_causes")


def _row(physics_process: bool, realtime: bool, seconds: float) -> dict:
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray

    ns = f"ab_pp{int(physics_process)}_rt{int(realtime)}"
    samples = []           # (wall [s], sim time [s], physics_process status)

    def on_diag(msg):
        for status in msg.status:
            if status.name.endswith("driver"):
                values = {kv.key: kv.value for kv in status.values}
                if "sim_time_s" in values:
                    samples.append((time.monotonic(), float(values["sim_time_s"]),
                                    values.get("physics_process", "")))

    node = rclpy.create_node(f"{ns}_diag")
    node.create_subscription(DiagnosticArray, f"/{ns}/diagnostics", on_diag, 10)
    finish = ros_loop._spin([node])
    extra = {}

    def started(proc):
        # the physics process is the loop process's child
        physics = [c for loop in ros_loop._children(proc.pid) for c in ros_loop._children(loop)]
        cpu0, t0, first = [ros_loop._cpu_seconds(p) for p in physics], time.monotonic(), \
            len(samples)

        def after():
            elapsed = time.monotonic() - t0
            extra["physics_cpu_percent"] = sum(
                100.0 * (ros_loop._cpu_seconds(p) - c) / elapsed for p, c in zip(physics, cpu0)
            ) if physics else None
            window = samples[first:]
            if len(window) >= 2:
                extra["sim_per_wall"] = ((window[-1][1] - window[0][1])
                                         / (window[-1][0] - window[0][0]))
                extra["physics_status"] = window[-1][2]
        return after

    try:
        result = ros_loop._measure_loop(
            [*CASE, "-p", f"sim.physics_process:={str(physics_process).lower()}",
             "-p", f"loop.realtime:={str(realtime).lower()}",
             "-p", "loop.watchdog_timeout:=30.0"],
            ns, ns, seconds, started=started, publish_rate=1000.0, outside=True)
    finally:
        finish()
        node.destroy_node()
    return {"physics_process": physics_process, "realtime": realtime, **result, **extra}


def profile(cycles: int = 2000) -> None:
    """The top functions of BaseController.step (torque mode, 1 kHz, the
    physics in its own process), by own time."""
    import cProfile
    import pstats

    from holonomic_core.config import load_config
    from holonomic_core.controller import BaseController
    from holonomic_sim.sim_driver import SimDriver

    cfg = load_config("xr4000", {"control_mode": "torque", "control_rate": 1000.0,
                                 "sim.physics_process": True, "cmd_timeout": 0.0})
    driver = SimDriver(cfg.model, cfg.values, 1000.0)
    driver.configure()
    ctrl = BaseController(cfg, driver)
    try:
        armed = ctrl.request_enable(True)
        while not armed.done():
            ctrl.step()
            time.sleep(1e-3)
        ctrl.set_command((0.2, 0.0, 0.1))
        profiler = cProfile.Profile()
        for _ in range(cycles):
            profiler.enable()
            ctrl.step()
            profiler.disable()
            time.sleep(8e-4)            # about the 1 kHz pace of the physics
        pstats.Stats(profiler).sort_stats("cumulative").print_stats(15)
    finally:
        ctrl.shutdown()


def main(argv: list[str]) -> int:
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "97")
    if argv[:1] == ["--profile"]:
        profile()
        return 0
    seconds = float(argv[0]) if argv else 60.0
    import rclpy

    rclpy.init()
    try:
        for realtime in (False, True):
            for physics_process in (False, True):
                row = _row(physics_process, realtime, seconds)
                print(json.dumps({k: row[k] for k in KEYS if k in row}), flush=True)
    finally:
        rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
