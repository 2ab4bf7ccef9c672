"""ROS-free benchmarks: control-cycle compute against a straightforward
baseline, and simulation speed against raw pybullet stepping.

Every number that is compared is measured in the same run, on the same
machine, interleaved where it matters, so a noisy machine shifts both sides.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.loop import ManualClock
from holonomic_core.mock_driver import MockDriver


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


def _with_hot_path(selected: str, factory):
    """``factory()`` with HOLONOMIC_HOT_PATH=selected (read when cycle objects are built)."""
    from holonomic_core import hot_path

    before = os.environ.get(hot_path.ENV)
    os.environ[hot_path.ENV] = selected
    try:
        return factory()
    finally:
        if before is None:
            del os.environ[hot_path.ENV]
        else:
            os.environ[hot_path.ENV] = before


def _cycle_functions(robot: str, targets, qs):
    """(compute, full) cycle functions with objects built under the current selection."""
    from holonomic_core.limits import TwistLimiter, joint_rate_saturation
    from holonomic_core.odometry import Odometry

    cfg = load_config(robot, {"driver": "mock", "cmd_timeout": 0.0})
    c = cfg.controller
    model = cfg.model
    dt = 1.0 / c.control_rate
    limiter = TwistLimiter(c.max_velocity, c.max_acceleration, c.max_deceleration)
    kin, max_rates = model.kinematics, model.max_joint_velocity
    saturate = joint_rate_saturation()
    odometry = Odometry(model, c.estimator, c.noise)
    state = {"prev": np.zeros(3)}

    def compute(i):
        k = i & 1023
        twist = limiter.limit(targets[k], state["prev"], dt)
        rates, _ = saturate(kin.inverse(qs[k], twist), max_rates)
        odometry.update(qs[k], i * dt)
        state["prev"] = twist

    clock = ManualClock()
    driver = MockDriver(model, cfg.values, c.control_rate, clock=clock)
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=clock)
    ctrl.request_enable(True)
    ctrl.step()

    def full(i):
        # the command arrives from the ROS thread, outside the cycle: here it
        # changes every 64 cycles (e.g. a 3 Hz teleop at 200 Hz)
        if i & 63 == 0:
            ctrl.set_command(targets[(i >> 6) & 1023])
        clock.now += ctrl.dt
        ctrl.step()

    return compute, full, ctrl


def cycle_compute(robot: str, cycles: int = 100_000) -> dict:
    """Median [us] per cycle, in alternating blocks of the same run, of

    * ``compute`` / ``compute_pure``: the work the baseline does -- twist
      limits, exact inverse kinematics, joint-rate saturation, odometry
      (slip_min fit, SE(2) composition, covariance) -- with our classes, on
      the compiled hot path and on the pure-Python path
      (:mod:`holonomic_core.hot_path`);
    * ``baseline``: the same work written the straightforward way
      (:class:`BaselineCycle`: numpy pinv of C and fresh arrays every cycle);
    * ``full_cycle`` / ``full_cycle_pure``: ``BaseController.step`` with the
      mock driver (driver read and write, plausibility checks, command
      timeout, the twist window's line fit, all of the above), compiled / pure.
    """
    from holonomic_core import hot_path

    cfg = load_config(robot, {"driver": "mock", "cmd_timeout": 0.0})
    c = cfg.controller
    n = len(cfg.model.joint_names)
    rng = np.random.default_rng(0)
    targets = rng.uniform(-1.0, 1.0, (1024, 3)) * np.array(c.max_velocity)
    qs = np.cumsum(rng.uniform(-0.01, 0.01, (1024, n)), axis=0)   # a smooth encoder walk
    dqs = np.diff(qs, axis=0, prepend=qs[:1])

    hot_path.module("compiled")          # ImportError here: `make setup` did not build it
    compute, full, ctrl = _with_hot_path("compiled", lambda: _cycle_functions(robot, targets, qs))
    compute_pure, full_pure, ctrl_pure = _with_hot_path(
        "pure", lambda: _cycle_functions(robot, targets, qs))
    base = BaselineCycle(cfg)

    def baseline(i):
        k = i & 1023
        base.step(qs[k], dqs[k], targets[k])

    block = 5000
    fns = (("compute", compute), ("compute_pure", compute_pure), ("baseline", baseline),
           ("full_cycle", full), ("full_cycle_pure", full_pure))
    times = {name: [] for name, _ in fns}
    for _ in range(max(1, cycles // block)):
        for name, fn in fns:
            times[name].append(_time_cycles(fn, block))
    med = {k: float(np.median(np.concatenate(v))) for k, v in times.items()}
    for controller in (ctrl, ctrl_pure):
        if controller.fault:
            raise RuntimeError(f"{robot}: the controller faulted during the benchmark: "
                               f"{controller.fault}")
    # both paths computed the same cycles: the same joint commands and pose
    same = (np.array_equal(ctrl.joint_command, ctrl_pure.joint_command)
            and np.array_equal(ctrl.odometry.pose, ctrl_pure.odometry.pose))
    return {"robot": robot, "joints": n, "compute_us": med["compute"],
            "compute_pure_us": med["compute_pure"], "baseline_us": med["baseline"],
            "full_cycle_us": med["full_cycle"], "full_cycle_pure_us": med["full_cycle_pure"],
            "speedup": med["baseline"] / med["compute"],
            "speedup_pure": med["baseline"] / med["compute_pure"],
            "same_numbers": bool(same), "cycles": cycles}


def simulation_speed(robot: str, seconds: float = 10.0,
                     ideal_motors: bool = True) -> dict:
    """Real-time factor of the simulator with the controller in the loop, and
    of raw ``pybullet.stepSimulation`` for the very same run: every physics
    step's ``stepSimulation`` call is timed on its own, so the raw figure is
    what pybullet alone spends on this robot doing this motion (``seconds`` of
    simulated time). ``ideal_motors``: pybullet's velocity motors
    (``sim.ideal_motors``), else the drive model on every joint. Timed with
    ``perf_counter`` around each call (``process_time`` is a system call of
    several microseconds on a loaded machine, a cost of its own); being
    descheduled by other load then lands on both sides in proportion."""
    import pybullet as pb

    from holonomic_sim.sim_driver import SimDriver
    from holonomic_sim.world import SimWorld

    cfg = load_config(robot, {"cmd_timeout": 0.0, "sim.physics_rate": 1000.0,
                              "sim.ideal_motors": ideal_motors})
    clock = ManualClock()
    # a world of our own, stepped here (as the fleet runner does) so that the
    # stepSimulation calls can be timed apart from the robot's per-step hooks
    world = SimWorld(cfg.values["sim.physics_rate"])
    driver = SimDriver(cfg.model, cfg.values, cfg.controller.control_rate, world=world)
    driver.configure()
    world.settle()
    ctrl = BaseController(cfg, driver, clock=clock)
    ctrl.request_enable(True)
    ctrl.step()
    (sim_robot,) = world.robots
    twist = (0.3, 0.2, 0.5)
    cycles = max(1, int(seconds * cfg.controller.control_rate))
    now, client = time.perf_counter, world.client
    raw = 0.0
    start = now()
    for _ in range(cycles):
        for _ in range(driver.substeps):         # SimWorld.step, its physics call timed
            sim_robot.before_step()
            t0 = now()
            pb.stepSimulation(physicsClientId=client)
            raw += now() - t0
            world.steps += 1
            sim_robot.after_step()
        clock.now = world.time
        ctrl.set_command(twist)
        ctrl.step()
    total = now() - start
    fault = ctrl.fault
    driver.close()
    world.close()
    if fault:
        raise RuntimeError(f"{robot}: the controller faulted during the benchmark: {fault}")
    simulated = cycles / cfg.controller.control_rate
    return {"robot": robot, "motors": "ideal" if ideal_motors else "drive model",
            "with_controller_x": simulated / total, "raw_pybullet_x": simulated / raw,
            "ratio": raw / total}


def fleet_speed(robot: str, counts=(1, 2, 4, 6, 8, 12, 16), seconds: float = 3.0) -> dict:
    """Real-time factor of N robots in one world, a BaseController each (the
    fleet's cycle: step the world once, then every robot's control cycle)."""
    from holonomic_sim.sim_driver import SimDriver
    from holonomic_sim.world import SimWorld

    results = {}
    for n in counts:
        clock = ManualClock()
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
            clock.now = world.time
            for ctrl in ctrls:
                ctrl.step()
        results[n] = seconds / (time.perf_counter() - t0)
        for ctrl in ctrls:
            ctrl.shutdown()
        world.close()
    best = max((n for n, x in results.items() if x >= 1.0), default=0)
    return {"robot": robot, "realtime_factor": results, "largest_n_realtime": best}
