"""``holonomic-drive-test ROBOT --joint NAME``: a velocity step on one joint.

The other joints are held at zero speed; the joint's measured speed is
recorded and its step response printed: rise time (10-90 %), overshoot,
settling time (2 %) and steady-state error (``--json``: one object with
``rise_time_s``, ``overshoot``, ``settling_time_s``, ``steady_state_error``
and the context). No ROS: the program owns the driver for the test.

* ``--driver sim`` (default): the simulator holds the base in the air
  (``sim.lifted``) and is sampled at its physics rate (1 ms), so a loop of
  tens of Hz is resolved; ``-p sim.drive.bandwidth:=60`` etc. try other drives.
* ``--driver odrive_can`` / ``cia402``: the real drives. The wheels must be
  off the floor: the program says so and waits for the user to type ``yes``
  at a terminal; without a terminal, or without ``yes``, it exits 2 and
  nothing moves. Sampled at the robot's control rate (the drives' feedback
  rate limits what can be resolved).

Fit ``sim.drive.*`` to a real drive by running both and matching the figures
(docs/drive_model.md).
"""

from __future__ import annotations

import json
import math
import sys
import time

import numpy as np

from holonomic_core.command_line import ArgumentParser

#: [s] held at zero before the step (the drives settle) and after it
_HOLD = 0.3
#: drives whose motors are real: the user must confirm before anything moves
_REAL = ("odrive_can", "cia402")


def _error(message: str) -> int:
    print(f"holonomic-drive-test: {message}", file=sys.stderr)
    return 2


def parse_args(argv):
    from holonomic_core.driver import driver_names

    parser = ArgumentParser(
        prog="holonomic-drive-test",
        description="Velocity step on one joint (the others held); prints rise time, "
                    "overshoot, settling time and steady-state error.")
    parser.add_argument("robot", help="a config name from config/ or a robot YAML")
    parser.add_argument("--joint", required=True, help="the joint to step (a joint name)")
    parser.add_argument("--driver", choices=driver_names(),
                        help="driver backend (default: the config's, normally sim)")
    parser.add_argument("--amplitude", type=float, metavar="RAD_S",
                        help="step size [rad/s] (default: a quarter of the joint's max_velocity)")
    parser.add_argument("--duration", type=float, default=1.0, metavar="S",
                        help="how long the step is held [s] (default 1.0)")
    parser.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="override one parameter, e.g. -p sim.ideal_motors:=true")
    parser.add_argument("--on-floor", action="store_true",
                        help="simulator only: leave the robot on its wheels and step a straight "
                             "run along the wheel's rolling direction (every joint follows the "
                             "inverse kinematics), so the loop drives its share of the base; "
                             "wheel joints only")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    return parser.parse_args(argv)


def _confirm(joint: str, amplitude: float, duration: float) -> bool:
    if not sys.stdin.isatty():
        return False            # nobody to ask: refused, nothing moves
    print(f"holonomic-drive-test: LIFT THE ROBOT so that no wheel touches the floor. "
          f"{joint} will turn at {amplitude:g} rad/s for {duration:g} s, the other joints "
          f"are held at zero speed.", file=sys.stderr)
    print("Type 'yes' to start: ", end="", file=sys.stderr, flush=True)
    try:
        return sys.stdin.readline().strip().lower() == "yes"
    except (OSError, KeyboardInterrupt):
        return False


def floor_step(model, positions, index: int, amplitude: float) -> np.ndarray:
    """Joint rates [rad/s] of the straight run along which joint ``index`` (a
    wheel) turns at ``amplitude`` [rad/s] while no steering or turret joint
    moves: the translation (vx, vy) in the null space of the non-wheel rows of
    the inverse kinematics at ``positions``. Raises ValueError when there is
    none (casters not aligned) or the joint is not a wheel."""
    names = model.joint_names
    if not names[index].endswith("wheel_joint"):
        raise ValueError(f"--on-floor steps wheel joints only ({names[index]} is not one)")
    # d(joint rates) / d(vx, vy): the inverse kinematics is linear in the twist
    rows = np.column_stack([model.inverse(positions, np.array([1.0, 0.0, 0.0])),
                            model.inverse(positions, np.array([0.0, 1.0, 0.0]))])
    others = rows[[i for i, n in enumerate(names) if not n.endswith("wheel_joint")]]
    _, sv, vt = np.linalg.svd(others) if len(others) else (None, np.zeros(0), np.eye(2))
    rank = int(np.sum(sv > 1e-9 * max(1.0, float(np.max(sv, initial=0.0)))))
    if rank >= 2:
        raise ValueError("no straight run leaves the steering joints still at this pose "
                         "(align the casters first)")
    # a one-dimensional null space is the run; with no steering constraint
    # (rank 0) the run is the one that turns this wheel fastest
    direction = vt[-1] if rank == 1 else rows[index] / max(np.linalg.norm(rows[index]), 1e-12)
    rate = float(rows[index] @ direction)
    if abs(rate) < 1e-9:
        raise ValueError(f"{names[index]} does not turn on a straight run at this pose")
    translation = direction * amplitude / rate
    return model.inverse(positions, np.array([translation[0], translation[1], 0.0]))


def run_step(driver, index: int, amplitude: float, duration: float, rate: float,
             paced: bool, step: np.ndarray | None = None):
    """Hold, step joint ``index`` to ``amplitude`` [rad/s] for ``duration``
    [s], hold again; returns (times [s], speeds [rad/s], efforts [N m], the
    step's time [s]). ``paced``: sleep to the ``rate`` [Hz] deadlines (real
    drives); else as fast as the driver's ``read`` returns (simulator).
    ``step``: the rates of every joint during the step (default: the others
    held at zero)."""
    n = len(driver.model.joint_names)
    zero = np.zeros(n)
    if step is None:
        step = zero.copy()
        step[index] = amplitude
    period = 1.0 / rate
    times, speeds, efforts = [], [], []
    t_step = None
    deadline = time.monotonic()
    cycles_hold, cycles_step = int(round(_HOLD * rate)), int(round(duration * rate))
    for k in range(cycles_hold + cycles_step + cycles_hold):
        if paced:
            deadline += period
            time.sleep(max(0.0, deadline - time.monotonic()))
        reading = driver.read()
        if cycles_hold <= k < cycles_hold + cycles_step:
            if t_step is None:
                t_step = reading.stamp
            times.append(reading.stamp)
            speeds.append(reading.velocities[index])
            efforts.append(reading.efforts[index])
        driver.write_velocities(step if cycles_hold <= k < cycles_hold + cycles_step - 1
                                else zero)
    return np.array(times), np.array(speeds), np.array(efforts), t_step


def main(argv=None) -> int:
    args = parse_args(argv)
    from holonomic_core.config import load_config
    from holonomic_core.driver import DriverError
    from holonomic_core.schema import ConfigError, parse_overrides
    from holonomic_core.step_response import step_response

    try:
        overrides = parse_overrides(args.param)
        if args.driver:
            overrides["driver"] = args.driver
        cfg = load_config(args.robot, overrides)
    except (ConfigError, ValueError, OSError) as exc:
        return _error(str(exc))
    model = cfg.model
    if args.joint not in model.joint_names:
        return _error(f"no joint {args.joint!r} on {model.name}: one of "
                      f"{', '.join(model.joint_names)}")
    index = model.joint_names.index(args.joint)
    vmax = float(model.max_joint_velocity[index])
    amplitude = 0.25 * vmax if args.amplitude is None else args.amplitude
    if not (math.isfinite(amplitude) and 0.0 < abs(amplitude) <= vmax):
        return _error(f"--amplitude must be non-zero and within the joint's max_velocity "
                      f"(|a| <= {vmax:g} rad/s), got {amplitude:g}")
    if not (math.isfinite(args.duration) and 0.05 <= args.duration <= 30.0):
        return _error(f"--duration must be in [0.05, 30] s, got {args.duration:g}")
    driver_name = cfg.controller.driver
    simulated = driver_name == "sim"
    if args.on_floor and not simulated:
        return _error("--on-floor is for the simulator only (a real robot is stepped lifted)")
    step = None
    if args.on_floor:
        try:
            step = floor_step(model, np.zeros(len(model.joint_names)), index, amplitude)
        except ValueError as exc:
            return _error(str(exc))
        if np.any(np.abs(step) > model.max_joint_velocity):
            return _error(f"--amplitude {amplitude:g}: the straight run would exceed a joint's "
                          f"max_velocity; use a smaller step")
    if simulated:
        # the bench test of a real robot: wheels in the air (or, --on-floor,
        # on them); sampled at the physics rate so that the loop's
        # milliseconds are resolved
        rate = float(cfg.values["sim.physics_rate"])
        try:
            cfg = load_config(args.robot, {**overrides, "sim.lifted": not args.on_floor,
                                           "control_rate": rate})
        except ConfigError as exc:
            return _error(str(exc))
    else:
        rate = cfg.controller.control_rate
        if driver_name in _REAL and not _confirm(args.joint, amplitude, args.duration):
            return _error("a real drive moves only after 'yes' typed at a terminal (lift the "
                          "robot first): not confirmed, nothing moved")
    driver = cfg.driver_class(model, cfg.values, rate)
    try:
        with driver:
            driver.activate()
            t, y, effort, t_step = run_step(driver, index, amplitude, args.duration, rate,
                                            paced=not simulated, step=step)
    except DriverError as exc:
        print(f"holonomic-drive-test: driver failure: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("holonomic-drive-test: interrupted: motors stopped", file=sys.stderr)
        return 130
    try:
        # the first sample is the reading before the step was written
        result = step_response(t, y, amplitude, t_step)
    except ValueError as exc:
        print(f"holonomic-drive-test: {args.joint}: {exc}", file=sys.stderr)
        return 1
    limit = model.joint_limits[index].max_effort
    saturated = bool(np.nanmax(np.abs(effort)) >= 0.98 * limit) if np.any(
        np.isfinite(effort)) else None
    out = {"robot": model.name, "joint": args.joint, "driver": driver_name,
           "ideal_motors": bool(cfg.values.get("sim.ideal_motors", False)) if simulated
           else None, "on_floor": bool(args.on_floor),
           "tuned_on": cfg.values.get("sim.drive.tuned_on") if simulated else None,
           "sample_rate_hz": rate, **result.as_dict(),
           "torque_saturated": saturated}
    if saturated:
        print(f"holonomic-drive-test: the step reached {args.joint}'s torque limit "
              f"({limit:g} N m): the rise time is set by that limit, not by the loop; "
              "try a smaller --amplitude", file=sys.stderr)
    if args.json:
        print(json.dumps(out))
    else:
        print(f"{model.name} {args.joint} ({driver_name}): step {amplitude:g} rad/s, "
              f"sampled at {rate:g} Hz")
        print(f"  rise time (10-90 %)   {1e3 * result.rise_time_s:8.2f} ms")
        print(f"  overshoot             {100 * result.overshoot:8.1f} %")
        print(f"  settling time (2 %)   {1e3 * result.settling_time_s:8.2f} ms")
        print(f"  steady-state error    {result.steady_state_error:8.4f} rad/s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
