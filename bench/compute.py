"""ROS-free benchmarks: control-cycle compute against a straightforward
baseline, and simulation speed against raw pybullet stepping.

Every number that is compared is measured in the same run, on the same
machine, interleaved where it matters, so a noisy machine shifts both sides.
"""

from __future__ import annotations

import math
import time

import numpy as np

from holonomic_core.controller import BaseController, load_config
from holonomic_core.mock_driver import MockDriver


class _Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def _constraint_matrix(kin, q: np.ndarray) -> np.ndarray:
    """Joint rates = C @ twist, built the straightforward way (allocating)."""
    if hasattr(kin, "constraint_matrix"):
        return np.array(kin.constraint_matrix(q))
    return np.linalg.inv(kin.jacobian(q))


class BaselineCycle:
    """The cycle as one would first write it: per-call allocation, per-axis
    numpy clipping, and the numpy pseudo-inverse of C for the odometry."""

    def __init__(self, cfg):
        self.kin = cfg.model.kinematics
        c = cfg.controller
        self.vmax = np.array(c.max_velocity)
        self.amax = np.array(c.max_acceleration)
        self.qdmax = cfg.model.max_joint_velocity
        self.dt = 1.0 / c.control_rate
        self.pose = np.zeros(3)
        self.prev = np.zeros(3)

    def step(self, q, dq, target):
        C = _constraint_matrix(self.kin, q)
        twist = np.clip(np.array(target, dtype=float), -self.vmax, self.vmax)
        twist = self.prev + np.clip(twist - self.prev, -self.amax * self.dt, self.amax * self.dt)
        rates = C @ twist
        scale = np.max(np.abs(rates) / self.qdmax)
        if scale > 1.0:
            rates = rates / scale
        disp = np.linalg.pinv(C) @ dq
        c, s = math.cos(self.pose[2]), math.sin(self.pose[2])
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        self.pose = self.pose + R @ disp
        self.prev = twist
        return rates


def _time_cycles(fn, cycles: int) -> np.ndarray:
    out = np.empty(cycles)
    clock = time.perf_counter_ns
    for i in range(cycles):
        t0 = clock()
        fn(i)
        out[i] = clock() - t0
    return out * 1e-3          # [us]


def cycle_compute(robot: str, cycles: int = 100_000) -> dict:
    """Median [us] of our full control cycle (BaseController.step with the
    mock driver: read, plausibility checks, odometry, limits, IK, saturation,
    write) and of the baseline, measured in alternating blocks."""
    cfg = load_config(robot, {"driver": "mock", "cmd_timeout": 0.0})
    clock = _Clock()
    driver = MockDriver(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock)
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=clock)
    ctrl.request_enable(True)
    ctrl.step()
    rng = np.random.default_rng(0)
    targets = rng.uniform(-1.0, 1.0, (1024, 3)) * np.array(cfg.controller.max_velocity)
    n = len(cfg.model.joint_names)
    qs = rng.uniform(-math.pi, math.pi, (1024, n))
    dqs = rng.uniform(-0.01, 0.01, (1024, n))
    base = BaselineCycle(cfg)

    def ours(i):
        # the command arrives from the ROS thread, outside the cycle: here it
        # changes every 64 cycles (e.g. a 3 Hz teleop at 200 Hz)
        if i & 63 == 0:
            ctrl.set_command(targets[(i >> 6) & 1023])
        clock.t += ctrl.dt
        ctrl.step()

    def baseline(i):
        base.step(qs[i & 1023], dqs[i & 1023], targets[i & 1023])

    block = 5000
    ours_t, base_t = [], []
    for _ in range(max(1, cycles // block)):
        ours_t.append(_time_cycles(ours, block))
        base_t.append(_time_cycles(baseline, block))
    ours_us = float(np.median(np.concatenate(ours_t)))
    base_us = float(np.median(np.concatenate(base_t)))
    return {"robot": robot, "joints": n, "ours_us": ours_us, "baseline_us": base_us,
            "speedup": base_us / ours_us, "cycles": cycles}


def simulation_speed(robot: str, seconds: float = 10.0) -> dict:
    """Real-time factor of the simulator with the controller in the loop, and
    of raw pybullet stepping of the same generated robot, same run."""
    from holonomic_sim.sim_driver import SimDriver

    cfg = load_config(robot, {"cmd_timeout": 0.0, "sim.physics_rate": 1000.0})
    clock = _Clock()
    driver = SimDriver(cfg.model, cfg.values, cfg.controller.control_rate)
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=clock)
    ctrl.request_enable(True)
    ctrl.step()
    steps = int(seconds * cfg.controller.control_rate)
    twist = (0.3, 0.2, 0.5)
    t0 = time.perf_counter()
    for _ in range(steps):
        ctrl.set_command(twist)
        ctrl.step()
        clock.t = ctrl.reading.stamp
    with_controller = seconds / (time.perf_counter() - t0)
    world = driver._world
    t0 = time.perf_counter()
    world.step(steps * driver.substeps)
    raw = seconds / (time.perf_counter() - t0)
    driver.close()
    return {"robot": robot, "with_controller_x": with_controller, "raw_pybullet_x": raw,
            "ratio": with_controller / raw}


def fleet_speed(robot: str, counts=(1, 2, 4, 6, 8, 12, 16), seconds: float = 3.0) -> dict:
    """Real-time factor of N robots in one world, a BaseController each (the
    fleet's cycle: step the world once, then every robot's control cycle)."""
    from holonomic_sim.sim_driver import SimDriver
    from holonomic_sim.world import SimWorld

    results = {}
    for n in counts:
        clock = _Clock()
        cfg0 = load_config(robot, {"cmd_timeout": 0.0})
        world = SimWorld(cfg0.values["sim.physics_rate"])
        ctrls = []
        for i in range(n):
            cfg = load_config(robot, {"cmd_timeout": 0.0, "sim.start_pose": [3.0 * i, 0.0, 0.0]})
            driver = SimDriver(cfg.model, cfg.values, cfg.controller.control_rate, world=world)
            driver.configure()
            ctrls.append(BaseController(cfg, driver, clock=clock))
        world.settle()
        for ctrl in ctrls:
            ctrl.request_enable(True)
            ctrl.set_command((0.3, 0.2, 0.5))
        substeps = ctrls[0].driver.substeps
        steps = int(seconds * cfg0.controller.control_rate)
        t0 = time.perf_counter()
        for _ in range(steps):
            world.step(substeps)
            clock.t = world.time
            for ctrl in ctrls:
                ctrl.step()
        results[n] = seconds / (time.perf_counter() - t0)
        for ctrl in ctrls:
            ctrl.shutdown()
        world.close()
    best = max((n for n, x in results.items() if x >= 1.0), default=0)
    return {"robot": robot, "realtime_factor": results, "largest_n_realtime": best}
