"""Kinds of motion for the odometry experiment: how the base is driven.

A covariance fitted on one kind of driving must hold on the others a user
drives, so the experiment can drive each of these and fit on some, validate
on the rest (``holonomic-odometry-experiment --fit-motion random
--validate-motion teleop,sweep,nav2,straight,spin,creep``):

* ``random`` -- the paper's: random target poses inside an area, steered by
  ground truth (:func:`holonomic_sim.odometry_experiment.simulate` drives it,
  and returns to the start at the end);
* ``teleop`` -- a joystick held, then released: a body twist held 1-3 s
  (forward or back, a strafe, a turn, or a mix), then released for 1-2 s
  (long enough to come to rest under the experiment's deceleration limits);
* ``sweep`` -- smooth, never stopping: each axis a sinusoid of its own
  period (5-20 s) and phase;
* ``nav2`` -- what a path follower sends a base: turns in place to a new
  heading, straight runs along the body's x (0.5-2.5 m), arcs (radius
  0.5-2 m, up to 90 degrees), with short pauses after a turn in place;
* ``straight`` -- long straight runs along the body's x, 4-6 m out and the
  same back, a stop at each end, never turning;
* ``spin`` -- turns in place, either way, 2-6 s each at 50-100 % of the turn
  rate, with stops: no translation is commanded;
* ``creep`` -- slow creeping: under 5 cm/s and 0.1 rad/s, in a new direction
  every 2-5 s.

Every kind but ``random`` is an open-loop schedule of body twists drawn from
the seed (the controller's acceleration limits shape the ramps, as they do a
teleop's): :func:`schedule` returns it as piecewise-constant segments and
:func:`twist_at` evaluates it (the sweep's sinusoids too).
"""

from __future__ import annotations

import math

import numpy as np

#: every kind of motion, in the order the tables list them
MOTION_KINDS = ("random", "teleop", "sweep", "nav2", "straight", "spin", "creep")
#: creep's bounds [m/s], [rad/s]
CREEP_SPEED = 0.05
CREEP_TURN_RATE = 0.1


def motion_list(text: str) -> list[str]:
    """An argparse type: comma-separated kinds of motion (``teleop,spin``;
    ``all``: every kind)."""
    import argparse
    names = [t.strip() for t in text.split(",") if t.strip()]
    if names == ["all"]:
        return list(MOTION_KINDS)
    bad = [n for n in names if n not in MOTION_KINDS]
    if bad or not names:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated kinds of motion among {', '.join(MOTION_KINDS)} (or "
            f"all), got {text!r}")
    return list(dict.fromkeys(names))


def schedule(kind: str, seed: int, duration: float, speed: float,
             turn_rate: float) -> list[tuple[float, tuple[float, float, float]]]:
    """The body-twist schedule of ``kind`` (not ``random`` or ``sweep``):
    segments (seconds, (vx, vy, wz)) [s, m/s, m/s, rad/s] covering at least
    ``duration`` [s], drawn from ``seed``; ``speed`` [m/s] and ``turn_rate``
    [rad/s] are the top speeds the segments stay under."""
    rng = np.random.default_rng([seed, MOTION_KINDS.index(kind)])
    out: list = []
    total = 0.0

    def add(seconds, twist):
        nonlocal total
        out.append((float(seconds), tuple(float(v) for v in twist)))
        total += seconds

    while total < duration:
        if kind == "teleop":
            mode = rng.integers(4)
            v = rng.uniform(0.3, 1.0) * speed * rng.choice((-1.0, 1.0))
            w = rng.uniform(0.3, 1.0) * turn_rate * rng.choice((-1.0, 1.0))
            twist = [(v, 0.0, 0.0), (0.0, v, 0.0), (0.0, 0.0, w),
                     (0.7 * v, 0.7 * v * rng.choice((-1.0, 1.0)), 0.5 * w)][mode]
            add(rng.uniform(1.0, 3.0), twist)
            add(rng.uniform(1.0, 2.0), (0.0, 0.0, 0.0))
        elif kind == "nav2":
            step = rng.integers(3)
            v = rng.uniform(0.6, 0.9) * speed
            if step == 0:       # turn in place to a new heading, then a pause
                w = 0.6 * turn_rate
                angle = rng.uniform(0.5, math.pi)
                add(angle / w, (0.0, 0.0, w * rng.choice((-1.0, 1.0))))
                add(0.3, (0.0, 0.0, 0.0))
            elif step == 1:     # a straight run
                add(rng.uniform(0.5, 2.5) / v, (v, 0.0, 0.0))
            else:               # an arc
                radius = rng.uniform(0.5, 2.0)
                w = min(v / radius, turn_rate)
                add(rng.uniform(0.3, 0.5 * math.pi) / w,
                    (w * radius, 0.0, w * rng.choice((-1.0, 1.0))))
        elif kind == "straight":
            run = rng.uniform(4.0, 6.0) / speed
            add(run, (speed, 0.0, 0.0))
            add(1.0, (0.0, 0.0, 0.0))
            add(run, (-speed, 0.0, 0.0))
            add(1.0, (0.0, 0.0, 0.0))
        elif kind == "spin":
            w = rng.uniform(0.5, 1.0) * turn_rate * rng.choice((-1.0, 1.0))
            add(rng.uniform(2.0, 6.0), (0.0, 0.0, w))
            add(rng.uniform(0.5, 1.5), (0.0, 0.0, 0.0))
        elif kind == "creep":
            heading = rng.uniform(-math.pi, math.pi)
            v = rng.uniform(0.3, 1.0) * CREEP_SPEED
            add(rng.uniform(2.0, 5.0), (v * math.cos(heading), v * math.sin(heading),
                                        rng.uniform(-1.0, 1.0) * CREEP_TURN_RATE))
        else:
            raise ValueError(f"no schedule for the kind of motion {kind!r}")
    return out


def sweep_axes(seed: int, speed: float, turn_rate: float) -> np.ndarray:
    """The sweep's sinusoids: (3, 3) rows (amplitude, angular frequency,
    phase) per axis vx, vy, wz [m/s or rad/s, rad/s, rad]."""
    rng = np.random.default_rng([seed, MOTION_KINDS.index("sweep")])
    amp = rng.uniform(0.4, 0.8, 3) * np.array([speed, speed, turn_rate]) / 2.0
    omega = 2.0 * math.pi / rng.uniform(5.0, 20.0, 3)
    phase = rng.uniform(-math.pi, math.pi, 3)
    return np.stack([amp, omega, phase], axis=1)


class MotionPlan:
    """The command of an open-loop kind of motion at time ``t`` [s] from its
    start (:func:`twist_at`); ``random`` has none (it is steered by ground
    truth)."""

    def __init__(self, kind: str, seed: int, duration: float, speed: float, turn_rate: float):
        if kind not in MOTION_KINDS or kind == "random":
            raise ValueError(f"no open-loop plan for the kind of motion {kind!r}")
        self.kind = kind
        if kind == "sweep":
            self.axes = sweep_axes(seed, speed, turn_rate)
            self.segments = []
        else:
            self.segments = schedule(kind, seed, duration, speed, turn_rate)
            self.ends = np.cumsum([s for s, _ in self.segments])

    def twist_at(self, t: float) -> tuple[float, float, float]:
        """Body twist [m/s, m/s, rad/s] commanded at ``t`` [s]."""
        if self.kind == "sweep":
            a, w, p = self.axes.T
            # sin(w t + p) - sin(p): every axis starts from rest
            return tuple((a * (np.sin(w * t + p) - np.sin(p))).tolist())
        k = int(np.searchsorted(self.ends, t, side="right"))
        return self.segments[min(k, len(self.segments) - 1)][1]
