"""Calibration model of a DDROT (see holonomic_core.calibration).

Parameters theta: left and right wheel radius [m], half wheel separation a
[m] and the turret encoder's zero [rad] (``joints.turret_joint.zero_correction``).
Three joints for three degrees of freedom leave no fit residual, so the
parameters are fitted to a reference (ground truth): ``body`` is the forward
kinematics of offset_turret.py over each sample's joint displacement.
"""

from __future__ import annotations

import numpy as np

from holonomic_core.calibration import Samples


class TurretCalibration:
    """Body motion of a DDROT as a function of (r_left, r_right, a, o_turret)."""

    self_consistent = False

    def __init__(self, model):
        kin = model.kinematics
        self.b = kin.b
        self._configured_zero = float(model.zero_corrections[2])
        self.keys = ("ddrot.left_wheel_radius", "ddrot.right_wheel_radius",
                     "ddrot.half_wheel_separation", "joints.turret_joint.zero_correction")
        self.labels = ("left wheel radius", "right wheel radius", "half wheel separation a",
                       "turret zero")
        self.kinds = ("radius", "radius", "length", "zero")
        self.nominal = np.array([kin.r_left, kin.r_right, kin.a, self._configured_zero])
        self.length_scale = float(kin.b)

    def slip(self, theta: np.ndarray, samples: Samples) -> np.ndarray:
        """No fit residual (... x 0)."""
        return np.zeros(np.shape(theta)[:-1] + (0,))

    def body(self, theta: np.ndarray, samples: Samples) -> np.ndarray:
        """Body displacement (dx [m], dy [m], dtheta [rad]) of base_link per
        sample (... x N x 3); ``theta`` may carry leading batch axes."""
        theta = np.asarray(theta, float)[..., None, :]
        r_left, r_right, a, zero = (theta[..., k] for k in range(4))
        phi = samples.positions[:, 2] + (zero - self._configured_zero)
        d = samples.displacements
        vl, vr = r_left * d[:, 0], r_right * d[:, 1]
        v, wd = 0.5 * (vl + vr), 0.5 * (vr - vl) / a
        s, c = np.sin(phi), np.cos(phi)
        return np.stack((v * c + self.b * wd * s, -v * s + self.b * wd * c, wd + d[:, 2]),
                        axis=-1)

    def wheel_turn(self, theta: np.ndarray, samples: Samples) -> np.ndarray:
        """The drive's own turn [rad] per sample (... x N), from the wheels
        alone: what an in-place rotation about the axle measures."""
        theta = np.asarray(theta, float)[..., None, :]
        d = samples.displacements
        return 0.5 * (theta[..., 1] * d[:, 1] - theta[..., 0] * d[:, 0]) / theta[..., 2]

    def overlay(self, theta: np.ndarray) -> dict[str, float]:
        return {k: float(v) for k, v in zip(self.keys, theta)}
