"""Stop distance and time of the emergency stop from 1 m/s, on each backend:
the simulator (lock-step, its own drive model) and the CAN drivers against
emulated drives whose motors are the simulator's joints (``--sim-drives``,
on the wall clock).

    python bench/estop_stop.py [--robot hamr] [--backends sim cia402 odrive_can odrive_can_0.5]

The base controller (ROS-free) drives base_link x at 1 m/s for 2 s, then
the e-stop is pressed; the figures are from the simulator's ground truth:
the distance base_link travels after the press and the time until its speed
stays below 1 cm/s. A backend whose stop coasts (ODrive 0.6's Estop
disarms the axes) shows it here as a long stop.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController

#: as test_sim_drives: slack for a loaded machine, not about timing
_CAN = {"safety.reading_timeout": 0.2}
OVERRIDES = {
    "sim": {"driver": "sim"},
    "cia402": {"driver": "cia402", "sim_drives": True, "cia402.feedback_timeout": 0.2,
               "cia402.heartbeat_timeout": 1.0, "cia402.drive_watchdog": 1.0, **_CAN},
    "odrive_can": {"driver": "odrive_can", "sim_drives": True,
                   "odrive_can.feedback_timeout": 0.2, "odrive_can.heartbeat_timeout": 1.0,
                   **_CAN},
    "odrive_can_0.5": {"driver": "odrive_can", "sim_drives": True, "odrive_can.firmware": "0.5",
                       "odrive_can.feedback_timeout": 0.2, "odrive_can.heartbeat_timeout": 1.0,
                       **_CAN},
}
SPEED = 1.0          # [m/s]
REST = 0.01          # [m/s]


def measure(backend: str, robot: str = "hamr") -> dict:
    cfg = load_config(robot, OVERRIDES[backend])
    driver = cfg.driver_class(cfg.model, cfg.values, cfg.controller.control_rate)
    driver.configure()
    lockstep = backend == "sim"
    ctrl = BaseController(cfg, driver, **({"clock": driver.sim_time} if lockstep else {}))
    clock = driver.sim_time if lockstep else time.monotonic
    try:
        ctrl.request_enable(True)
        next_time = time.monotonic()

        def cycle(twist=None):
            nonlocal next_time
            if twist is not None:
                ctrl.set_command(twist)
            ctrl.step()
            if not lockstep:
                next_time += ctrl.dt
                time.sleep(max(0.0, next_time - time.monotonic()))

        start = clock()
        while clock() - start < 2.0:
            cycle((SPEED, 0.0, 0.0))
        truth = driver.ground_truth()
        speed = float(truth.twist[0])
        pressed_at, pressed_pose = clock(), truth.pose.copy()
        ctrl.request_estop(True, "bench")
        rest_at = None
        while clock() - pressed_at < 3.0:
            cycle()
            t = driver.ground_truth()
            if np.hypot(*t.twist[:2]) >= REST:
                rest_at = None
            elif rest_at is None:
                rest_at = clock()
        final = driver.ground_truth().pose
        return {"backend": backend, "speed_at_press_m_s": round(speed, 3),
                "stop_distance_m": round(float(np.hypot(*(final[:2] - pressed_pose[:2]))), 3),
                "stop_time_s": None if rest_at is None else round(rest_at - pressed_at, 3),
                "driver_state": driver.state.value, "estop": ctrl.status().estop,
                "fault": ctrl.fault}
    finally:
        driver.close()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default="hamr")
    p.add_argument("--backends", nargs="+", choices=tuple(OVERRIDES), default=tuple(OVERRIDES))
    args = p.parse_args(argv)
    for backend in args.backends:
        print(json.dumps(measure(backend, args.robot)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
