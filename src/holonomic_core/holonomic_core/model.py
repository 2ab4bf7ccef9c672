"""The robot model: immutable geometry, joint limits and parameters.

``load_model("hamr")`` returns an immutable :class:`RobotModel` (pinocchio's
*Model*): the kinematics, joint limits and every validated parameter of one
robot, built once from its YAML params file by :mod:`holonomic_core.config`.
Its ``inverse``/``forward``/``jacobian`` check their inputs and say what
they expected. The types live in :mod:`holonomic_core.robot_model` (which
the configuration builds, without importing this module) and are
re-exported here.
"""

from __future__ import annotations

import os
from typing import Any, Mapping

from holonomic_core.robot_model import JointLimits, RobotModel

__all__ = ["JointLimits", "RobotModel", "load_model"]


def load_model(source: str | os.PathLike, overrides: Mapping[str, Any] | None = None) -> RobotModel:
    """Load the immutable robot model from a config name or YAML path.

    ``overrides`` are flat keys (``{"ddrot.turret_offset": 0.2}``) applied on
    top of the file, e.g. for design sweeps. The documented Python API
    (docs/conventions.md); the loading itself is
    :func:`holonomic_core.config.load_model`.
    """
    # imported when called, so that importing this module for its types does
    # not load the configuration (yaml, the schema, every plugin's entry points)
    from holonomic_core.config import load_model as load
    return load(source, overrides)
