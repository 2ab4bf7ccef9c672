"""Calibration model of a swerve base (see holonomic_core.calibration).

Parameters theta, per module i in config order: wheel radius r_i [m] and
the steering encoder's zero o_i [rad] (the config key
``joints.<name>_steer_joint.zero_correction``, added to the reading). The
residual is the one the least-squares odometry leaves
(:mod:`swerve_base.odometry_fit`): per sample, the measured module
displacements ``u_i = r_i drho_i e(phi_i + o_i)`` at the steering axes
minus the rigid-body fit through them, vectorised over all samples. A
wrong radius leaves a residual along the module's heading, a wrong zero
one across it; one overall scale (every radius together) needs the
reference, as for the powered caster.
"""

from __future__ import annotations

import numpy as np

from holonomic_core.calibration import Samples


class SwerveCalibration:
    """Residuals of a swerve base's joint motion as functions of (r, o)."""

    self_consistent = True

    def __init__(self, model):
        kin = model.kinematics
        names = kin.module_names
        self.n = len(names)
        self.sx, self.sy = kin.sx, kin.sy
        configured = model.zero_corrections[kin.steer_indices]
        self.keys = tuple([f"swerve.{m}.wheel_radius" for m in names]
                          + [f"joints.{m}_steer_joint.zero_correction" for m in names])
        self.labels = tuple([f"module {m}: wheel radius" for m in names]
                            + [f"module {m}: steering zero" for m in names])
        self.kinds = ("radius",) * self.n + ("zero",) * self.n
        self.nominal = np.concatenate((kin.r, configured))
        self._configured_zero = configured
        self.length_scale = float(np.sqrt(np.mean(self.sx ** 2 + self.sy ** 2)))

    def _fit(self, theta: np.ndarray, samples: Samples):
        """Per sample the rigid fit (dx, dy, dtheta) (... x N x 3) and the
        residuals (... x N x n x 2); ``theta`` may carry leading batch axes."""
        n = self.n
        theta = np.asarray(theta, float)[..., None, :]        # broadcast over samples
        r, zero = theta[..., :n], theta[..., n:]
        # samples carry the configured corrections already added
        phi = samples.positions[:, 0::2] + (zero - self._configured_zero)
        drho = samples.displacements[:, 1::2]
        u, w = r * np.cos(phi) * drho, r * np.sin(phi) * drho
        cx, cy = self.sx.mean(), self.sy.mean()
        qx, qy = self.sx - cx, self.sy - cy
        mu, mw = u.mean(axis=-1, keepdims=True), w.mean(axis=-1, keepdims=True)
        wz = (qx * w - qy * u).sum(axis=-1, keepdims=True) / float((qx * qx + qy * qy).sum())
        residual = np.stack((u - mu + wz * qy, w - mw - wz * qx), axis=-1)
        body = np.concatenate((mu + wz * cy, mw - wz * cx, wz), axis=-1)
        return body, residual

    def slip(self, theta: np.ndarray, samples: Samples) -> np.ndarray:
        """Module displacements [m] the rigid fit leaves (... x N x n x 2)."""
        return self._fit(theta, samples)[1]

    def body(self, theta: np.ndarray, samples: Samples) -> np.ndarray:
        """Body displacement (dx [m], dy [m], dtheta [rad]) per sample (... x N x 3)."""
        return self._fit(theta, samples)[0]

    def overlay(self, theta: np.ndarray) -> dict[str, float]:
        return {k: float(v) for k, v in zip(self.keys, theta)}
