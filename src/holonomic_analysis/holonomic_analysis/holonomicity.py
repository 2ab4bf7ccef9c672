"""Measured holonomicity (Costa & Yim, Sec. VII, eq. 2) with the control
stack in the loop.

From rest at the start pose S, the base moves to a target T at distance
``d_T`` in direction ``alpha`` (in S's frame) with heading change ``theta_T``
and stops there; ``t(alpha, theta_T)`` is the time from the first command to
being stopped at T. ``H(theta) = t_min / t_max`` over the directions, and
``H`` is the worst ``H(theta)``.

The move is "time-optimal enough" under the robot's configured limits: every
cycle the target's remaining distance ``e`` and heading error ``e_theta``
become a twist toward T at the speed from which the base can still stop in
time, ``min(v_max, sqrt(2 a e))`` (and the same for the turn), in the start
frame, turned into base_link with the true heading. The real
:class:`BaseController` then applies the twist limits, the acceleration
limits and the joint-speed saturation, exactly as for a teleop command --
so the DDROT swings its drive base and the PCV its casters as the inverse
kinematics dictate, and their time to do so is in t.

Two plants: ``sim`` (pybullet, ground-truth pose at the readings' sample
time: with the drive model that is its feedback delay old, a steering latency
like a motion-capture system's) and ``mock`` (ideal joints:
the pose is the odometry of the commanded joint motion, i.e. the exact
kinematics). With ``mock`` and unbounded acceleration the measured H tends to
``H_hat`` as ``d_T`` shrinks, as the paper says; with acceleration limits it
tends to 1 instead (tiny moves are all acceleration), which is why the paper's
limit needs "instantaneous changes in velocity".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.loop import ManualClock
from holonomic_core.se2 import rotate, wrap_angle
from holonomic_core.teleop_script import body_command


@dataclass(frozen=True)
class Move:
    """One timed move: direction ``alpha`` and heading change ``theta`` [rad],
    time [s] (inf if T was not reached within the timeout), and the final
    position [m] and heading [rad] errors."""

    alpha: float
    theta: float
    seconds: float
    position_error: float
    heading_error: float


@dataclass
class Measurement:
    """All moves of one measurement and the holonomicity they give."""

    robot: str
    driver: str
    distance: float
    moves: list[Move] = field(default_factory=list)

    def h_of(self, theta: float) -> float:
        """H(theta) = t_min / t_max over the directions (0 if one failed)."""
        times = [m.seconds for m in self.moves if m.theta == theta]
        return 0.0 if not times or math.isinf(max(times)) else min(times) / max(times)

    @property
    def thetas(self) -> list[float]:
        return list(dict.fromkeys(m.theta for m in self.moves))

    @property
    def H(self) -> float:
        return min(self.h_of(t) for t in self.thetas)

    def as_dict(self) -> dict:
        return {
            "robot": self.robot, "driver": self.driver, "d_T": self.distance, "H": self.H,
            "H_theta": {f"{math.degrees(t):g}": self.h_of(t) for t in self.thetas},
            "moves": [{"alpha_deg": math.degrees(m.alpha), "theta_deg": math.degrees(m.theta),
                       "seconds": m.seconds, "position_error": m.position_error,
                       "heading_error": m.heading_error} for m in self.moves],
        }


def _stop_speed(limit: float, deceleration: float, error: float) -> float:
    """Speed toward a target ``error`` away from which the base can still stop
    (90 % of the deceleration limit, for the one-cycle lag of the loop)."""
    return min(limit, math.sqrt(2.0 * 0.9 * deceleration * error))


def time_move(robot, alpha: float, theta: float, distance: float, driver: str = "sim",
              overrides: Mapping[str, object] | None = None, timeout: float = 20.0,
              tolerance: float | None = None) -> Move:
    """Time one move from rest to rest (see the module doc).

    ``robot``: config name or YAML; ``overrides``: flat config keys (limits,
    control rate...). ``tolerance`` [m]: arrival radius (default 1 % of the
    distance, at least 2 mm); the heading must be within 1 degree and the
    base stopped (below 2 % of its speed limit).
    """
    cfg = load_config(robot, {**(overrides or {}), "driver": driver, "cmd_timeout": 0.0,
                              "enable_on_start": True})
    c = cfg.controller
    clock = ManualClock()
    if driver == "mock":
        drv = cfg.driver_class(cfg.model, cfg.values, c.control_rate, clock=clock)
    else:
        drv = cfg.driver_class(cfg.model, cfg.values, c.control_rate)
    tol = max(0.002, 0.01 * distance) if tolerance is None else tolerance
    tol_heading = math.radians(1.0)
    v_max = min(c.max_velocity[0], c.max_velocity[1])
    a_dec = min(c.max_deceleration[0], c.max_deceleration[1])
    w_max, alpha_dec = c.max_velocity[2], c.max_deceleration[2]
    target = np.array([distance * math.cos(alpha), distance * math.sin(alpha), theta])
    dt = 1.0 / c.control_rate
    with drv:
        ctrl = BaseController(cfg, drv, clock=clock)
        ctrl.request_enable(True)

        def pose() -> np.ndarray:
            if driver == "mock":
                return ctrl.odometry.pose.copy()
            return drv.ground_truth().pose.copy()

        def step() -> None:
            if driver == "mock":
                clock.now += dt
            ctrl.step()
            if driver != "mock":
                clock.now = ctrl.reading.stamp

        step()
        if ctrl.fault is not None:
            raise RuntimeError(f"{cfg.model.name}: could not arm the {driver} driver: {ctrl.fault}")
        start_time = clock.now
        last = pose()
        while clock.now - start_time < timeout:
            now_pose = pose()
            speed = np.hypot(*(now_pose[:2] - last[:2])) / dt
            turn = abs(wrap_angle(now_pose[2] - last[2])) / dt
            last = now_pose
            err = target[:2] - now_pose[:2]
            dist = float(np.hypot(*err))
            err_heading = wrap_angle(target[2] - now_pose[2])
            inside = dist < tol and abs(err_heading) < tol_heading
            if inside and speed < 0.02 * v_max and turn < 0.02 * w_max:
                seconds = clock.now - start_time
                break
            if inside:
                twist_world = (0.0, 0.0, 0.0)
            else:
                v = _stop_speed(v_max, a_dec, dist)
                w = _stop_speed(w_max, alpha_dec, abs(err_heading))
                vx, vy = (err / dist * v) if dist > 1e-12 else (0.0, 0.0)
                twist_world = (vx, vy, math.copysign(w, err_heading))
            # the world-frame twist in base_link
            ctrl.set_command((*rotate(twist_world[0], twist_world[1], -now_pose[2]),
                              twist_world[2]))
            step()
            if ctrl.fault is not None:
                raise RuntimeError(f"{cfg.model.name}: the controller faulted during the move "
                                   f"(alpha {math.degrees(alpha):.0f} deg): {ctrl.fault}")
        else:
            seconds = math.inf
        final = pose()
    return Move(alpha, theta, seconds, float(np.hypot(*(target[:2] - final[:2]))),
                abs(wrap_angle(target[2] - final[2])))


def measure(robot, distance: float = 1.0, directions: int = 8,
            thetas: Sequence[float] = (0.0,), driver: str = "sim",
            overrides: Mapping[str, object] | None = None, progress=None) -> Measurement:
    """Measured holonomicity over ``directions`` evenly spaced directions and
    the heading changes ``thetas`` [rad]; ``progress(move)`` is called after
    each move."""
    name = load_config(robot, {**(overrides or {}), "driver": driver}).model.name
    result = Measurement(name, driver, distance)
    for theta in thetas:
        for k in range(directions):
            move = time_move(robot, 2.0 * math.pi * k / directions, theta, distance, driver,
                             overrides)
            result.moves.append(move)
            if progress is not None:
                progress(move)
    return result


def kinematic_overrides(robot=None) -> dict:
    """Overrides for the kinematic limit (``mock`` driver): twist limits far
    above what the joints allow, accelerations at the schema's maximum, no
    speed norm, jerk or (for ``robot``, a config name or path) joint
    acceleration limit, and a 1 kHz loop, so that only the joint speed limits
    shape the motion."""
    out: dict = {"control_rate": 1000.0, "publish_rate": 50.0,
                 "limits.linear.max_speed": 0.0}
    for axis in ("linear.x", "linear.y", "angular.z"):
        out[f"limits.{axis}.max_velocity"] = 100.0
        out[f"limits.{axis}.max_acceleration"] = 1000.0
        out[f"limits.{axis}.max_deceleration"] = 1000.0
        out[f"limits.{axis}.max_jerk"] = 0.0
    if robot is not None:
        for joint in load_config(robot, {"driver": "mock"}).model.joint_names:
            out[f"joints.{joint}.max_acceleration"] = 0.0
    return out


def rollout(robot, script, sample_rate: float = 20.0,
            overrides: Mapping[str, object] | None = None):
    """Drive the ``mock`` plant through the scripted teleop ``script`` (a
    :class:`~holonomic_core.teleop_script.Script`, e.g. the demo's) with the real
    controller and the configured limits, from the start configuration (all
    joints at 0).

    Returns ``(times [s], positions (k x n) [rad], starts)``: joint positions
    sampled at ``sample_rate`` and ``(start time, name)`` of each segment.
    """
    cfg = load_config(robot, {**(overrides or {}), "driver": "mock", "cmd_timeout": 0.0,
                              "enable_on_start": True})
    clock = ManualClock()
    drv = cfg.driver_class(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock)
    dt = 1.0 / cfg.controller.control_rate
    every = max(1, round(cfg.controller.control_rate / sample_rate))
    times, samples, starts = [], [], []
    with drv:
        ctrl = BaseController(cfg, drv, clock=clock)
        ctrl.request_enable(True)
        cycle = 0
        for seg in script.segments:
            starts.append((clock.now, seg.name))
            for _ in range(round(seg.seconds / dt)):
                ctrl.set_command(body_command(seg, ctrl.odometry.pose[2], script.rate))
                clock.now += dt
                ctrl.step()
                if ctrl.fault is not None:
                    raise RuntimeError(f"{cfg.model.name}: controller fault: {ctrl.fault}")
                if cycle % every == 0:
                    times.append(clock.now)
                    samples.append(ctrl.reading.positions.copy())
                cycle += 1
    return np.array(times), np.array(samples), starts
