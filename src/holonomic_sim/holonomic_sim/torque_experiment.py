"""``holonomic-torque-experiment``: velocity mode vs dynamically decoupled
torque mode, and C#^T vs pinv(C)^T torque distribution, in the simulator.

The XR4000 (or any PCV config) follows two precise moves through
``BaseController.follow`` -- a figure-eight and a square whose corners are
taken at speed -- with the whole control stack and the ``sim`` driver,
stepped as fast as the CPU allows (no ROS). Each run does two laps; the
second is measured:

* tracking error: |true pose - reference| (position RMS and max, heading max);
* slip: the contact slip the encoders see (the slip_min fit residual, per
  caster, mean and max) -- what a distribution that fights itself produces;
* peak traction: the largest friction force of any wheel on the floor
  (pybullet's contact points), i.e. how close to losing grip the base runs;
* a controller fault (e.g. the reading monitor's tracking check on a wheel
  that spins) ends the run; the row says when and why;
* internal force: the part of the wheels' contact forces that produces no
  net force or moment on the base (:mod:`holonomic_sim.contact_forces`:
  ``|(I - W^+ W) f|``), RMS and max -- wheels pushing against each other.

Each mode runs on both motor models: the drive model (the simulator's
default: velocity loops, torque limits, rotor inertia, friction, delays) and
ideal motors (``sim.ideal_motors``, the reference). Prints a table (and writes
it with ``--markdown FILE``).
"""

from __future__ import annotations

import math
import sys

import numpy as np

from holonomic_core.command_line import (ArgumentParser, ShowDefaults, number, output_file,
                                         robot_config)
from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.loop import ManualClock
from holonomic_core.schema import parse_overrides
from holonomic_core.se2 import wrap_angle
from holonomic_sim.contact_forces import internal_force


#: [s] both trajectories start from rest and reach their pace over this time
RAMP = 1.0


def _progress(t: float) -> tuple[float, float, float]:
    """Time-scaling from rest: (tau, d tau/dt, d2 tau/dt2) with tau = t^2 /
    (2 RAMP) while ramping up, t - RAMP/2 after (velocity continuous, the
    acceleration a bounded step)."""
    if t < RAMP:
        return t * t / (2 * RAMP), t / RAMP, 1.0 / RAMP
    return t - 0.5 * RAMP, 1.0, 0.0


def figure_eight(amplitude: float = 0.8, period: float = 8.0):
    """x = A sin(w tau), y = A/2 sin(2 w tau), heading 0 (tau: ``_progress``):
    a trajectory callable (t -> (pose, twist, acceleration)) and its duration
    for two laps after the ramp."""
    w = 2 * math.pi / period
    duration = 2 * period + 0.5 * RAMP

    def sample(t):
        if t > duration:
            return None
        tau, rate, rate_dot = _progress(t)
        sx, cx = math.sin(w * tau), math.cos(w * tau)
        s2, c2 = math.sin(2 * w * tau), math.cos(2 * w * tau)
        pose = (amplitude * sx, 0.5 * amplitude * s2, 0.0)
        dx, dy = amplitude * w * cx, amplitude * w * c2               # d/d tau
        ddx, ddy = -amplitude * w * w * sx, -2 * amplitude * w * w * s2
        twist = (dx * rate, dy * rate, 0.0)
        accel = (ddx * rate * rate + dx * rate_dot, ddy * rate * rate + dy * rate_dot, 0.0)
        return pose, twist, accel
    return sample, duration


def square(side: float = 1.0, speed: float = 0.6, corner_radius: float = 0.15):
    """A square driven at constant speed, heading 0, its corners taken at
    speed on arcs of ``corner_radius`` (a velocity that turned instantly
    would ask the casters to steer infinitely fast: speed / radius = 4 rad/s
    here, 2.4 m/s^2 of centripetal acceleration)."""
    straight = side - 2 * corner_radius
    arc = 0.5 * math.pi * corner_radius
    lap = 4 * (straight + arc)
    directions = ((1, 0), (0, 1), (-1, 0), (0, -1))

    duration = 2 * lap / speed + 0.5 * RAMP

    def sample(t):
        if t > duration:
            return None
        tau, rate, rate_dot = _progress(t)
        pose, twist, accel = _on_square(tau * speed)
        # the path's velocity and acceleration at full speed, time-scaled
        return (pose, tuple(v * rate for v in twist),
                tuple(a * rate * rate + v * rate_dot
                      for a, v in zip(accel, twist)))

    def _on_square(travelled):
        dist = travelled % lap
        corner = np.array([corner_radius, 0.0])      # start of the first leg
        for k in range(4):
            d = np.array(directions[k], float)
            n = np.array((-d[1], d[0]))                # left of the leg: the turn's centre
            if dist <= straight:
                p = corner + d * dist
                return (p[0], p[1], 0.0), (d[0] * speed, d[1] * speed, 0.0), (0.0, 0.0, 0.0)
            dist -= straight
            end = corner + d * straight
            if dist <= arc:
                a = dist / corner_radius                 # angle turned on the arc
                centre = end + n * corner_radius
                radial = -n * math.cos(a) + d * math.sin(a)      # centre -> point
                p = centre + corner_radius * radial
                v = speed * (d * math.cos(a) + n * math.sin(a))
                acc = -speed * speed / corner_radius * radial
                return (p[0], p[1], 0.0), (v[0], v[1], 0.0), (acc[0], acc[1], 0.0)
            dist -= arc
            corner = end + (d + n) * corner_radius
        raise AssertionError("unreachable: dist within one lap")
    return sample, duration


TRAJECTORIES = {"figure-eight": figure_eight, "square": square}
MODES = {  # name -> config overrides
    "velocity": {"control_mode": "velocity"},
    "torque C#^T": {"control_mode": "torque"},
    "torque pinv(C)^T": {"control_mode": "torque"},
}


#: motor models: name -> simulator overrides
MOTORS = {"drive model": {"sim.ideal_motors": False}, "ideal": {"sim.ideal_motors": True}}


def _contact_figures(driver) -> tuple[float, float]:
    """Largest friction force of any wheel on the floor [N] and the size of
    the internal force |f_int| [N], now."""
    positions, forces = driver.wheel_contacts()
    if len(forces) == 0:
        return 0.0, 0.0
    return (float(np.max(np.linalg.norm(forces, axis=1))),
            float(np.linalg.norm(internal_force(positions, forces))))


def run(robot: str, trajectory: str, mode: str, friction: float = 1.0,
        motors: str = "drive model", overrides: dict | None = None) -> dict:
    """One run: ``trajectory`` in ``mode`` on ``motors`` (keys of
    :data:`TRAJECTORIES`, :data:`MODES`, :data:`MOTORS`); ``overrides``: more
    parameters (e.g. ``sim.drive.bandwidth``)."""
    sample, duration = TRAJECTORIES[trajectory]()
    settings = {**MODES[mode], **MOTORS[motors], "cmd_timeout": 0.0,
                "sim.wheel_friction": friction, "enable_on_start": True, **(overrides or {})}
    cfg = load_config(robot, settings)
    clock = ManualClock()
    driver = cfg.driver_class(cfg.model, cfg.values, cfg.controller.control_rate)
    errors, headings, slip, traction, internal = [], [], [], [], []
    fault = None
    with driver:
        ctrl = BaseController(cfg, driver, clock=clock)
        if mode.endswith("pinv(C)^T"):
            ctrl.torque.distribution = "pinv"
        ctrl.request_enable(True)
        ctrl.step()
        clock.now = ctrl.reading.stamp
        start = clock.now
        ctrl.follow(sample)
        while clock.now - start < duration:
            ctrl.step()
            clock.now = ctrl.reading.stamp
            t = clock.now - start
            if ctrl.fault is not None:            # the run ends here; the row says so
                fault = f"fault at {t:.1f} s: {ctrl.fault}"
                break
            if t < duration / 2:
                continue                      # the first lap settles the start
            ref = sample(t)
            if ref is None:
                break
            truth = driver.ground_truth().pose
            errors.append(math.hypot(truth[0] - ref[0][0], truth[1] - ref[0][1]))
            headings.append(abs(wrap_angle(truth[2] - ref[0][2])))
            slip.append(ctrl.odometry.residual.copy())
            peak, inner = _contact_figures(driver)
            traction.append(peak)
            internal.append(inner)
    if not errors:
        return {"trajectory": trajectory, "mode": mode, "motors": motors, "fault": fault}
    slip = np.array(slip)
    return {"trajectory": trajectory, "mode": mode, "motors": motors, "fault": fault,
            "rms_mm": 1e3 * float(np.sqrt(np.mean(np.square(errors)))),
            "max_mm": 1e3 * float(np.max(errors)),
            "max_heading_deg": math.degrees(float(np.max(headings))),
            "slip_mean_mm_s": 1e3 * float(slip.mean()), "slip_max_mm_s": 1e3 * float(slip.max()),
            "peak_traction_n": float(np.max(traction)),
            "internal_rms_n": float(np.sqrt(np.mean(np.square(internal)))),
            "internal_max_n": float(np.max(internal))}


def table(rows) -> str:
    head = ("| trajectory | motors | mode | position RMS | max | heading max | slip mean "
            "| slip max | peak traction | internal force RMS | max |")
    out = [head, "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "rms_mm" not in r:                     # faulted before the measured lap
            out.append(f"| {r['trajectory']} | {r['motors']} | {r['mode']} | "
                       f"{r['fault']} |" + " |" * 9)
            continue
        mode = r["mode"] + (f" ({r['fault']}; the rest of the lap not measured)"
                            if r["fault"] else "")
        out.append(f"| {r['trajectory']} | {r['motors']} | {mode} | {r['rms_mm']:.1f} mm | "
                   f"{r['max_mm']:.1f} mm | {r['max_heading_deg']:.2f} deg | "
                   f"{r['slip_mean_mm_s']:.2f} mm/s | {r['slip_max_mm_s']:.1f} mm/s | "
                   f"{r['peak_traction_n']:.0f} N | {r['internal_rms_n']:.1f} N | "
                   f"{r['internal_max_n']:.1f} N |")
    return "\n".join(out)


def main(argv=None) -> int:
    parser = ArgumentParser(prog="holonomic-torque-experiment", formatter_class=ShowDefaults,
                            description=__doc__.split("\n\n")[0])
    parser.add_argument("--robot", type=robot_config, default="xr4000",
                        help="a PCV config name or YAML")
    parser.add_argument("--friction", type=number(0.0, 10.0, strict_low=True), default=1.0,
                        help="wheel friction coefficient")
    parser.add_argument("--motors", action="append", choices=list(MOTORS),
                        help="motor model(s) (default: both)")
    parser.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="override a parameter, e.g. -p sim.drive.bandwidth:=10")
    parser.add_argument("--markdown", type=output_file, metavar="FILE",
                        help="also write the table to FILE")
    args = parser.parse_args(argv)
    kind = load_config(args.robot).model.kind
    if kind != "pcv":
        parser.error(f"--robot: {args.robot} is a {kind}; the experiment needs a "
                     "powered-caster vehicle (pcv), e.g. xr4000 or comr3")
    try:
        overrides = parse_overrides(args.param)
    except ValueError as exc:
        parser.error(str(exc))
    rows = []
    for trajectory in TRAJECTORIES:
        for motors in args.motors or list(MOTORS):
            for mode in MODES:
                rows.append(run(args.robot, trajectory, mode, args.friction, motors, overrides))
                print(f"{trajectory:13s} {motors:12s} {mode:17s} done", file=sys.stderr,
                      flush=True)
    text = table(rows)
    print(text)
    if args.markdown:
        with open(args.markdown, "w") as handle:
            handle.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
