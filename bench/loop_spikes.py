"""The control loop's rare long cycles, without ROS: the real loop process
(``holonomic_bringup.loop_host``, started by ``LoopClient`` as the node starts
it) at 1 kHz, with commands at 100 Hz like the 1 kHz rows of bench/ros_loop.py,
and the slowest cycle the loop's own status reports.

    python bench/loop_spikes.py [--robot xr4000] [--seconds 60] [--runs 1]
                                [--physics-process] [--velocity] [--no-realtime]

Defaults: the XR4000 in torque mode on the simulator, 1 kHz physics in the loop
process (``--physics-process``: in its own), SCHED_FIFO and mlockall where
permitted. The base is armed at start and driven from the first second. Each
run prints, from the loop's last status (``LoopStats.summary``, since start):
the compute maximum, the slowest cycle's CPU time, page faults and named
parts, the page faults of all cycles, and the periods over 2 ms by cause.
Without ROS, nothing else competes for the CPU but the machine's other load.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

from holonomic_bringup.loop_client import LoopClient
from holonomic_core.config import config_from_flat, read_params_file, resolve_config


def run(robot: str = "xr4000", seconds: float = 60.0, physics_process: bool = False,
        torque: bool = True, realtime: bool = True) -> dict:
    """One run; the loop's last status (its statistics since start) and how
    it was scheduled."""
    path = resolve_config(robot)
    flat = read_params_file(path)
    flat.update({"driver": "sim", "sim.physics_rate": 1000.0, "control_rate": 1000.0,
                 "publish_rate": 1000.0, "loop.realtime": realtime,
                 "loop.watchdog_timeout": 30.0, "enable_on_start": True,
                 "sim.physics_process": physics_process,
                 "control_mode": "torque" if torque else "velocity"})
    cfg = config_from_flat(flat, str(path))
    client = LoopClient([(flat, str(path), cfg.model)], watchdog_timeout=30.0)
    link = client.links[0]
    latest: dict = {}
    link.on_status = lambda status, loop: latest.update(loop)
    client.start()
    try:
        t0 = time.monotonic()
        k = 0
        while time.monotonic() - t0 < seconds:
            # bench/ros_loop.py's cmd_vel: a slow swing in x, constant y and turn
            link.send_command((0.3 * math.sin(0.5 * k / 100.0), 0.2, 0.5), time.monotonic())
            k += 1
            time.sleep(max(0.0, t0 + k / 100.0 - time.monotonic()))
        time.sleep(1.2)                 # one more status
    finally:
        client.stop()
    return dict(latest)


def describe(loop: dict) -> str:
    """The run's spike-related figures, in one paragraph."""
    if "slowest_cycle" in loop:
        parts = ", ".join(f"{k[len('slowest_'):-3]} {v:.2f}" for k, v in loop.items()
                          if k.startswith("slowest_") and k.endswith("_ms")
                          and k != "slowest_cpu_ms")
        slowest = (f"cycle {int(loop['slowest_cycle'])}: CPU {loop['slowest_cpu_ms']:.2f} ms, "
                   f"{int(loop['slowest_page_faults'])} page faults; parts [ms] {parts}; "
                   f"page faults in all cycles {int(loop['page_faults'])} "
                   f"({int(loop['page_fault_cycles'])} cycles)")
    else:   # a loop from before the slowest-cycle record: its largest part
        slowest = f"controller part max {loop.get('controller_max_ms', math.nan):.2f} ms"
    return (f"{loop.get('scheduling', '?')}: compute max {loop['compute_max_ms']:.2f} ms "
            f"({slowest}); periods > 2 ms "
            f"{int(loop['periods_over_2ms'])} (woke late {int(loop['over_2ms_woke_late'])}, "
            f"compute {int(loop['over_2ms_compute'])}, preempted "
            f"{int(loop['over_2ms_preempted'])}), > 5 ms {int(loop['periods_over_5ms'])}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robot", default="xr4000")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--runs", type=int, default=1)
    parser.add_argument("--physics-process", action="store_true")
    parser.add_argument("--velocity", action="store_true", help="velocity mode, not torque")
    parser.add_argument("--no-realtime", action="store_true")
    args = parser.parse_args(argv)
    if not args.seconds > 0 or args.runs < 1:
        print("loop_spikes: error: --seconds must be > 0 and --runs >= 1", file=sys.stderr)
        return 2
    for k in range(args.runs):
        loop = run(args.robot, args.seconds, args.physics_process, not args.velocity,
                   not args.no_realtime)
        print(f"run {k + 1} ({args.seconds:g} s): {describe(loop)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
