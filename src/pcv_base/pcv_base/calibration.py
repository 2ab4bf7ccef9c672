"""Calibration model of a powered-caster vehicle (see holonomic_core.calibration).

Parameters theta, per caster i in config order: wheel radius r_i [m], caster
offset b_i [m], and the steering encoder's zero o_i [rad] (the config key
``joints.<name>_steer_joint.zero_correction``, added to the reading). The residual is the one the
slip-minimising estimator leaves (powered_caster.py, eq. 13): per sample, the
sensed contact displacements ``u_i = b_i dphi_i n_i + r_i drho_i e_i`` at the
contact points ``p_i = s_i - b_i e_i`` minus the rigid-body fit through them,
vectorised over all samples.
"""

from __future__ import annotations

import numpy as np

from holonomic_core.calibration import Samples


class CasterCalibration:
    """Residuals of a PCV's joint motion as functions of (r, b, o)."""

    self_consistent = True

    def __init__(self, model):
        kin = model.kinematics
        names = kin.caster_names
        self.n = len(names)
        self.sx, self.sy = kin.sx, kin.sy
        configured = model.zero_corrections[kin.steer_indices]
        self.keys = tuple([f"pcv.{c}.wheel_radius" for c in names]
                          + [f"pcv.{c}.caster_offset" for c in names]
                          + [f"joints.{c}_steer_joint.zero_correction" for c in names])
        self.labels = tuple([f"caster {c}: wheel radius" for c in names]
                            + [f"caster {c}: caster offset" for c in names]
                            + [f"caster {c}: steering zero" for c in names])
        self.kinds = ("radius",) * self.n + ("offset",) * self.n + ("zero",) * self.n
        self.nominal = np.concatenate((kin.r, kin.b, configured))
        self._configured_zero = configured
        self.length_scale = float(np.sqrt(np.mean(self.sx ** 2 + self.sy ** 2)))

    def _fit(self, theta: np.ndarray, samples: Samples):
        """Per sample the rigid fit (dx, dy, dtheta) (... x N x 3) and the
        residuals (... x N x n x 2); ``theta`` may carry leading batch axes
        (one Jacobian column each)."""
        n = self.n
        theta = np.asarray(theta, float)[..., None, :]        # broadcast over samples
        r, b, zero = theta[..., :n], theta[..., n:2 * n], theta[..., 2 * n:]
        # samples carry the configured corrections already added
        phi = samples.positions[:, 0::2] + (zero - self._configured_zero)
        dphi, drho = samples.displacements[:, 0::2], samples.displacements[:, 1::2]
        c, s = np.cos(phi), np.sin(phi)
        px, py = self.sx - b * c, self.sy - b * s
        u = -b * s * dphi + r * c * drho
        w = b * c * dphi + r * s * drho
        cx, cy = px.mean(axis=-1, keepdims=True), py.mean(axis=-1, keepdims=True)
        mu, mw = u.mean(axis=-1, keepdims=True), w.mean(axis=-1, keepdims=True)
        qx, qy = px - cx, py - cy
        wz = (qx * w - qy * u).sum(axis=-1, keepdims=True) / (qx * qx + qy * qy).sum(
            axis=-1, keepdims=True)
        residual = np.stack((u - mu + wz * qy, w - mw - wz * qx), axis=-1)
        body = np.concatenate((mu + wz * cy, mw - wz * cx, wz), axis=-1)
        return body, residual

    def slip(self, theta: np.ndarray, samples: Samples) -> np.ndarray:
        """Contact displacements [m] the rigid fit leaves (... x N x n x 2)."""
        return self._fit(theta, samples)[1]

    def body(self, theta: np.ndarray, samples: Samples) -> np.ndarray:
        """Body displacement (dx [m], dy [m], dtheta [rad]) per sample (... x N x 3)."""
        return self._fit(theta, samples)[0]

    def overlay(self, theta: np.ndarray) -> dict[str, float]:
        return {k: float(v) for k, v in zip(self.keys, theta)}
