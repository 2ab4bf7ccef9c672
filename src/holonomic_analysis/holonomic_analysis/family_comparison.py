"""The families side by side: the measured holonomicity H (Costa & Yim,
:mod:`holonomic_analysis.holonomicity`) and the time to reverse direction
at speed, with the control stack in the loop, for any robots.

Reversal: from rest the base is commanded ``speed`` [m/s] along base_link
``alpha`` until it runs steadily (2 s), then the opposite; the reversal
time is from that command until the base's velocity along the new
direction first reaches 90 % of ``speed`` (the plant's: ground truth in
the simulator, the odometry of the commanded joints on ``mock``). A
base whose wheels must turn first (a swerve module across the motion, a
powered caster swinging round) pays that here; a swerve reversing along
its modules flips its wheels instead.

    python -m holonomic_analysis.family_comparison hamr xr4000 swerve4 [--driver sim] [-p K:=V]
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from holonomic_analysis.holonomicity import measure
from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.loop import ManualClock
from holonomic_core.schema import ConfigError, parse_overrides

#: seconds of steady running before the reversal, and the reversal's timeout
RUN_UP, TIMEOUT = 2.0, 10.0


def reversal_time(robot: str, speed: float, alpha: float = 0.0, driver: str = "mock",
                  overrides=None) -> float:
    """Seconds [s] from the reversal command until the base moves at 90 %
    of ``speed`` [m/s] the other way along base_link direction ``alpha``
    [rad] (inf when it does not within TIMEOUT); ``overrides``: flat config keys."""
    cfg = load_config(robot, {**(overrides or {}), "driver": driver, "cmd_timeout": 0.0,
                              "enable_on_start": True})
    c = cfg.controller
    clock = ManualClock()
    args = (cfg.model, cfg.values, c.control_rate)
    drv = cfg.driver_class(*args, clock=clock) if driver == "mock" else cfg.driver_class(*args)
    direction = np.array([math.cos(alpha), math.sin(alpha)])
    dt = 1.0 / c.control_rate
    with drv:
        ctrl = BaseController(cfg, drv, clock=clock)
        ctrl.request_enable(True)

        def step() -> None:
            if driver == "mock":
                clock.now += dt
            ctrl.step()
            if driver != "mock":
                clock.now = ctrl.reading.stamp
            if ctrl.fault is not None:
                raise RuntimeError(f"{cfg.model.name}: the controller faulted: {ctrl.fault}")

        def velocity() -> np.ndarray:
            """The base's velocity [m/s] in base_link."""
            if driver == "mock":
                return ctrl.odometry.twist[:2]
            return drv.ground_truth().twist[:2]

        step()
        start = clock.now
        while clock.now - start < RUN_UP:
            ctrl.set_command((*(speed * direction), 0.0))
            step()
        start = clock.now
        while clock.now - start < TIMEOUT:
            ctrl.set_command((*(-speed * direction), 0.0))
            step()
            if float(velocity() @ -direction) >= 0.9 * speed:
                return clock.now - start
    return math.inf


def compare(robots, speed: float, driver: str, overrides=None) -> list[dict]:
    """Per robot: H over 8 directions at d_T = 1 m (theta_T = 0), and the
    reversal times along base_link x and y."""
    rows = []
    for robot in robots:
        h = measure(robot, 1.0, 8, (0.0,), driver, overrides)
        rows.append({"robot": h.robot, "H": h.H,
                     "t_min": min(m.seconds for m in h.moves),
                     "t_max": max(m.seconds for m in h.moves),
                     "reverse_x": reversal_time(robot, speed, 0.0, driver, overrides),
                     "reverse_y": reversal_time(robot, speed, math.pi / 2, driver,
                                                overrides)})
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m holonomic_analysis.family_comparison",
        description="Measured holonomicity H and the time to reverse at speed, per robot.")
    parser.add_argument("robots", nargs="+", help="config names or robot YAMLs")
    parser.add_argument("--driver", choices=("mock", "sim"), default="mock",
                        help="plant: mock (ideal joints) or sim (pybullet, drive model)")
    parser.add_argument("--speed", type=float, default=0.5,
                        help="reversal speed [m/s], in (0, 5] (default 0.5)")
    parser.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="override a config parameter of every robot, e.g. "
                             "-p sim.ideal_motors:=true")
    args = parser.parse_args(argv)
    try:
        overrides = parse_overrides(args.param)
    except ValueError as exc:
        print(f"-p: {exc}", file=sys.stderr)
        return 2
    if not (0.0 < args.speed <= 5.0):
        print(f"--speed: must be in (0, 5] m/s, got {args.speed:g}", file=sys.stderr)
        return 2
    try:
        rows = compare(args.robots, args.speed, args.driver, overrides)
    except (ConfigError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"| robot | H (d_T = 1 m) | t_min [s] | t_max [s] | reverse along x at "
          f"{args.speed:g} m/s [s] | reverse along y [s] |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['robot']} | {r['H']:.3f} | {r['t_min']:.2f} | {r['t_max']:.2f} | "
              f"{r['reverse_x']:.2f} | {r['reverse_y']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
