"""The robot model's immutable types: :class:`RobotModel` (geometry, joint
limits and every validated parameter of one robot) and :class:`JointLimits`.

A leaf module: :mod:`holonomic_core.config` builds these from a params file,
and :mod:`holonomic_core.model` (the public API, ``load_model``) re-exports
them, so that neither of those two imports the other at module level and
the configuration does not depend on the API that calls it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from holonomic_core.kinematics import BaseKinematics


@dataclass(frozen=True)
class JointLimits:
    """Limits of one joint: speed [rad/s], effort [N m] and position range
    [rad] (``min_position`` / ``max_position``; None: continuous)."""

    max_velocity: float
    max_effort: float
    min_position: float | None = None
    max_position: float | None = None

    @property
    def ranged(self) -> bool:
        """True when the joint has a position range (a steering joint or
        turret with cables), False when it is continuous."""
        return self.min_position is not None


@dataclass(frozen=True)
class RobotModel:
    """Immutable geometry, joint limits and physical parameters of one robot."""

    name: str
    kinematics: BaseKinematics
    joint_limits: tuple[JointLimits, ...]
    #: every validated parameter (read-only), for the simulator's URDF and tools
    params: Mapping[str, Any]

    @property
    def kind(self) -> str:
        return self.kinematics.kind

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.kinematics.joint_names

    @property
    def max_joint_velocity(self) -> np.ndarray:
        """Joint speed limits [rad/s], joint_names order (a fresh array)."""
        return np.array([j.max_velocity for j in self.joint_limits])

    @property
    def zero_corrections(self) -> np.ndarray:
        """Encoder zero corrections [rad], joint_names order (a fresh array):
        the kinematics take ``reading + zero_corrections``."""
        return np.array([self.params[f"joints.{j}.zero_correction"] for j in self.joint_names])

    def inverse(self, positions, twist) -> np.ndarray:
        """Joint rates [rad/s], ``joint_names`` order, for the base_link ``twist``
        (vx, vy, wz) [m/s, m/s, rad/s] at joint ``positions`` [rad].

        Raises ValueError naming the expected length for a wrong-length or
        non-finite input."""
        return self.kinematics.inverse(self._joint_vector("positions", positions),
                                       _vector("twist", twist, 3, "vx, vy, wz in base_link"))

    def forward(self, positions, velocities, estimator: str = "slip_min") -> np.ndarray:
        """Body twist (vx, vy, wz) [m/s, m/s, rad/s] in base_link from joint
        ``positions`` [rad] and ``velocities`` [rad/s] (``joint_names`` order).

        ``estimator``: "slip_min" (C# = Cp+ Cq^-1), "pinv" or "robust". Raises
        ValueError for a wrong-length or non-finite input or an unknown estimator."""
        return self.kinematics.forward(self._joint_vector("positions", positions),
                                       self._joint_vector("velocities", velocities), estimator)

    def jacobian(self, positions) -> np.ndarray:
        """``J_joint_to_base`` (3 x n) at joint ``positions`` [rad]."""
        return self.kinematics.jacobian(self._joint_vector("positions", positions))

    def _joint_vector(self, what: str, value) -> np.ndarray:
        return _vector(what, value, len(self.joint_names),
                       f"one per joint of {self.name}: {', '.join(self.joint_names)}")


def _vector(what: str, value, length: int, meaning: str) -> np.ndarray:
    """``value`` as a finite float vector of ``length``, or ValueError saying
    what was expected."""
    try:
        out = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected {length} numbers ({meaning}), got {value!r}") from None
    if out.shape != (length,):
        raise ValueError(f"{what}: expected {length} numbers ({meaning}), "
                         f"got shape {out.shape}: {value!r}")
    if not np.all(np.isfinite(out)):
        raise ValueError(f"{what}: expected finite numbers ({meaning}), got {value!r}")
    return out
