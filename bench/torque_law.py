"""Cost of the torque-mode control law of the PCVs: ``OperationalSpaceController.step``
(eqs. 5, 6 and 14, what ``BaseController.step`` adds in torque mode), with its two
parts ``PcvDynamics.terms`` (Lambda, mu) and the C#^T F distribution, on the path
the product selects (``HOLONOMIC_HOT_PATH``, default: the compiled ``terms``), on
the pure-Python path, and as the numpy implementation the scalar code replaced
(``holonomic_testing.pcv_numpy_reference``).

    python bench/torque_law.py [--robot xr4000] [--cycles 10000]

The three run on the same inputs in alternating 1000-call blocks of one run, so a
loaded machine shifts all of them; the figures are medians [us] per call. The last
line checks that the product and the numpy reference computed the same torques
(relative difference, ~1e-16).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from holonomic_core import hot_path
from holonomic_core.config import load_config
from holonomic_core.torque import OperationalSpaceController
from holonomic_testing.pcv_numpy_reference import RefLaw, ref_terms, ref_torque_distribution

BLOCK = 1000
K = 1024            # distinct inputs, cycled


def torque_law(robot: str = "xr4000", cycles: int = 10_000) -> dict:
    """Median [us] per call of the law's step, terms and distribution: the
    product (on the selected hot path: ``path``), the pure-Python path
    (``*_pure_us``) and numpy (the reference, ``*_numpy_us``), and the ratios
    numpy / product."""
    cfg = load_config(robot, {"control_mode": "torque"})
    c, model = cfg.controller, cfg.model
    efforts = [j.max_effort for j in model.joint_limits]
    dt = 1.0 / c.control_rate
    law = OperationalSpaceController(model, c.torque_kp, c.torque_kv, efforts)
    dyn = law.dynamics
    selected = os.environ.get(hot_path.ENV)
    os.environ[hot_path.ENV] = "pure"           # read when the dynamics are built
    try:
        pure = OperationalSpaceController(model, c.torque_kp, c.torque_kv, efforts)
    finally:
        if selected is None:
            del os.environ[hot_path.ENV]
        else:
            os.environ[hot_path.ENV] = selected
    dyn_pure = pure.dynamics
    ref = RefLaw(dyn, c.torque_kp, c.torque_kv, efforts, (0.0, 0.0, 0.0))
    rng = np.random.default_rng(0)
    n = len(model.joint_names)
    # realistic inputs: an encoder walk, a pose that drifts, twists within the
    # limits and a command near them
    qs = np.cumsum(rng.uniform(-0.02, 0.02, (K, n)), axis=0)
    poses = np.cumsum(rng.uniform(-1e-3, 1e-3, (K, 3)), axis=0)
    twists = rng.uniform(-1.0, 1.0, (K, 3)) * np.array(c.max_velocity)
    commands = twists + rng.uniform(-0.05, 0.05, (K, 3))
    wrenches = rng.uniform(-100.0, 100.0, (K, 3))
    law.reset(poses[0])
    pure.reset(poses[0])
    kin = model.kinematics
    sides = {
        "step": (lambda k: law.step(qs[k], poses[k], twists[k], commands[k], dt),
                 lambda k: pure.step(qs[k], poses[k], twists[k], commands[k], dt),
                 lambda k: ref.step(qs[k], poses[k], twists[k], commands[k], dt)),
        "terms": (lambda k: dyn.terms(qs[k], twists[k]),
                  lambda k: dyn_pure.terms(qs[k], twists[k]),
                  lambda k: ref_terms(dyn, qs[k], twists[k])),
        "distribution": (lambda k: dyn.torque_distribution(qs[k], wrenches[k]),
                         lambda k: dyn_pure.torque_distribution(qs[k], wrenches[k]),
                         lambda k: ref_torque_distribution(kin, qs[k], wrenches[k])),
    }
    clock = time.perf_counter_ns
    out = {"robot": robot, "cycles": cycles, "path": hot_path.name()}
    for name, fns in sides.items():
        times = ([], [], [])
        for b in range(max(1, cycles // BLOCK)):
            for t, fn in zip(times, fns):
                for i in range(b * BLOCK, (b + 1) * BLOCK):
                    k = i & (K - 1)
                    t0 = clock()
                    fn(k)
                    t.append(clock() - t0)
        for key, t in zip(("us", "pure_us", "numpy_us"), times):
            out[f"{name}_{key}"] = float(np.median(t)) * 1e-3
        out[f"{name}_ratio"] = out[f"{name}_numpy_us"] / out[f"{name}_us"]
    # one more cycle from the same state on both: the same torques
    law.reset(poses[0])
    ref.ref_pose, ref.ref_twist = np.array(poses[0]), np.zeros(3)
    a = law.step(qs[5], poses[5], twists[5], commands[5], dt)
    b = ref.step(qs[5], poses[5], twists[5], commands[5], dt)
    out["torque_rel_diff"] = float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robot", default="xr4000", choices=("xr4000", "comr3"))
    parser.add_argument("--cycles", type=int, default=10_000)
    args = parser.parse_args(argv)
    if args.cycles < BLOCK:
        print(f"torque_law: error: --cycles must be >= {BLOCK}", file=sys.stderr)
        return 2
    r = torque_law(args.robot, args.cycles)
    for name in ("step", "terms", "distribution"):
        print(f"{r['robot']} {name:12s} {r['path']} {r[name + '_us']:7.1f} us   pure "
              f"{r[name + '_pure_us']:7.1f} us   numpy {r[name + '_numpy_us']:7.1f} us   "
              f"numpy/{r['path']} {r[name + '_ratio']:4.1f}x")
    print(f"same torques: max relative difference {r['torque_rel_diff']:.1e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
