"""Online drift watch: is the configured geometry still right?

While the robot drives, the controller feeds every joint reading to a
:class:`DriftWatch`. Every ``BATCH`` samples (taken ``PERIOD`` apart) it
linearises the calibration problem of :mod:`holonomic_core.calibration` at
the configured parameters -- the slip-minimising fit residual and its
Jacobian with respect to the radii, caster offsets and steering zeros -- and
adds the normal equations to a running sum that forgets with a time constant
of ``drift_watch.window`` seconds of motion. One Gauss-Newton step from the
configured parameters then estimates the parameter errors that the recent
motion shows: random slip averages out, a wrong parameter leaves a residual
correlated with the motion, and that is what the step picks up. The mean
radius is held (its scale needs a reference), so radii are judged relative
to the others.

The systematic residual appears only when the joints follow the body (torque
mode): stiff velocity loops impose the configured kinematics on the joints
and the floor takes the conflict as slip (see docs/calibration.md).

The watch runs inside the 1 kHz control cycle, and a batch's work (the
residual, its Jacobian, the solve) takes more CPU than a whole cycle has.
So a full batch is worked off one stage per :meth:`DriftWatch.update` call,
over the next four calls, each a fraction of a cycle; the numbers are the
same, a few milliseconds later (docs/realtime.md).
"""

from __future__ import annotations

import math
from typing import Iterator, Mapping

import numpy as np

from holonomic_core import plugins
from holonomic_core.calibration import (MAX_STDERR, family_for, jacobian, residual_function,
                                        samples_from_readings)
from holonomic_core.schema import ParamSpec

#: spacing [s] of the samples the watch takes, and samples per update
PERIOD, BATCH = 0.05, 40

DRIFT_SPECS = [
    ParamSpec("drift_watch.enabled", "bool",
              "Track the systematic part of the odometry fit residual and warn (diagnostics) "
              "when it says a wheel radius, caster offset or steering zero is off (PCV).",
              default=True),
    ParamSpec("drift_watch.radius_threshold", "double",
              "Warn when a wheel radius looks off by more than this fraction of its "
              "configured value (relative to the mean radius) [-].",
              default=0.01, minimum=0.001, maximum=0.5),
    ParamSpec("drift_watch.offset_threshold", "double",
              "Warn when a caster offset looks off by more than this fraction [-].",
              default=0.15, minimum=0.01, maximum=1.0),
    ParamSpec("drift_watch.zero_threshold", "double",
              "Warn when a steering encoder's zero looks off by more than this [rad].",
              default=0.035, minimum=0.001, maximum=1.0),
    ParamSpec("drift_watch.window", "double",
              "Time constant [s] of driving over which the watch averages.",
              default=120.0, minimum=5.0, maximum=3600.0),
]


class DriftWatch:
    """Running estimate of the parameter errors of a PCV's configured model."""

    def __init__(self, model, radius_threshold: float = 0.01, offset_threshold: float = 0.15,
                 zero_threshold: float = 0.035, window: float = 120.0):
        self.family = family_for(model)
        self.thresholds = {"radius": radius_threshold, "offset": offset_threshold,
                           "zero": zero_threshold}
        self.window = window
        p = len(self.family.nominal)
        self._info = np.zeros((p, p))
        self._gradient = np.zeros(p)
        self._sq = 0.0             # forgotten sum of squared residuals [m^2]
        self._count = 0.0          # forgotten number of residual entries
        self._stamps: list[float] = []
        self._positions: list[np.ndarray] = []
        #: the batch being worked off, one stage per update (None: none)
        self._pending: Iterator[None] | None = None
        #: seconds of motion taken into account (forgetting applied)
        self.moving_time = 0.0
        #: latest estimate of theta - nominal [m, rad] (None before enough motion)
        self.error: np.ndarray | None = None
        self._radius = np.array([k == "radius" for k in self.family.kinds])

    @classmethod
    def from_config(cls, model, values: Mapping) -> "DriftWatch | None":
        """The watch configured by ``drift_watch.*``, or None where it does not
        apply (disabled, or a family whose joints alone cannot tell its
        parameters: no redundant joints, or no calibration model)."""
        if not values["drift_watch.enabled"] or not plugins.provides("calibration", model.kind) \
                or not family_for(model).self_consistent:
            return None
        return cls(model, values["drift_watch.radius_threshold"],
                   values["drift_watch.offset_threshold"],
                   values["drift_watch.zero_threshold"], values["drift_watch.window"])

    def update(self, stamp: float, positions: np.ndarray) -> None:
        """One joint reading (kinematic angles [rad]) at ``stamp`` [s]. Also
        does the next stage of a batch in progress (see the module docstring)."""
        if self._pending is not None and next(self._pending, StopIteration) is StopIteration:
            self._pending = None
        if self._stamps and stamp - self._stamps[-1] < PERIOD - 1e-9:
            return
        self._stamps.append(stamp)
        self._positions.append(np.array(positions, float))
        if len(self._stamps) > BATCH:
            self.flush()        # the batch before, if it is still in progress
            self._pending = self._batch(self._stamps, np.array(self._positions))
            self._stamps, self._positions = self._stamps[-1:], self._positions[-1:]

    def flush(self) -> None:
        """Finish the batch in progress now (e.g. at the end of a recording)."""
        if self._pending is not None:
            for _ in self._pending:
                pass
            self._pending = None

    def _batch(self, stamps: list[float], positions: np.ndarray) -> Iterator[None]:
        """One batch's work in four stages, with a yield between each: the
        residual, its Jacobian, the normal equations, the solve."""
        samples = samples_from_readings(stamps, positions)
        if len(samples) < BATCH // 2:          # mostly standing still: nothing to learn
            return
        fun, scale = residual_function(self.family, samples)
        z = np.zeros(len(scale))
        r = fun(z)
        yield
        J = jacobian(fun, z)
        yield
        duration = float(samples.durations.sum())
        keep = math.exp(-duration / self.window)
        self._info = keep * self._info + J.T @ J
        self._gradient = keep * self._gradient + J.T @ r
        self._sq = keep * self._sq + float(r @ r)
        self._count = keep * self._count + len(r)
        self.moving_time = keep * self.moving_time + duration
        yield
        self._solve(scale)

    def _solve(self, scale: np.ndarray) -> None:
        if self.moving_time < 0.25 * self.window:
            return
        # hold the mean radius: one stiff row on the radii's mean (relative)
        gauge = self._radius / self._radius.sum()
        info = self._info + 1e6 * np.outer(gauge, gauge) * np.trace(self._info)
        sigma2 = self._sq / max(self._count, 1.0)
        se = np.sqrt(np.maximum(np.diag(np.linalg.pinv(info)), 0.0) * sigma2)
        tol = np.array([MAX_STDERR[k] for k in self.family.kinds])
        if np.any(se > tol):
            return                              # the motion does not show everything yet
        self.error = scale * np.linalg.solve(info, -self._gradient)

    def findings(self) -> list[str]:
        """One sentence per parameter beyond its threshold, worst first."""
        if self.error is None:
            return []
        fam = self.family
        found = []
        for i, kind in enumerate(fam.kinds):
            err = self.error[i]
            size = abs(err) if kind == "zero" else abs(err / fam.nominal[i])
            if size <= self.thresholds[kind]:
                continue
            unit, what = fam.labels[i].split(": ", 1)
            if kind == "zero":
                text = f"{what} looks {math.degrees(err):+.1f} deg off"
            else:
                text = (f"{what} looks {100 * size:.1f} % "
                        f"{'larger' if err > 0 else 'smaller'} than configured")
            found.append((size / self.thresholds[kind],
                          f"{unit}: {text}; run holonomic-calibrate"))
        return [text for _, text in sorted(found, reverse=True)]

    def values(self) -> dict[str, str]:
        """The current estimates, for diagnostics key/values."""
        out = {"moving_time_s": f"{self.moving_time:.0f}"}
        if self.error is not None:
            for key, err, kind in zip(self.family.keys, self.error, self.family.kinds):
                out[key] = f"{math.degrees(err):+.2f} deg" if kind == "zero" else \
                    f"{1e3 * err:+.3f} mm"
        return out
