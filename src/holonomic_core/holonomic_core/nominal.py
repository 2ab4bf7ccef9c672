"""The robot as drawn: the nominal description a simulated robot is built from.

A controller's config is what the controller *believes* about the robot. On a
real robot the physical wheels, casters and encoders do not change when a
calibration overlay is loaded (``holonomic-bringup ROBOT --params-file
ROBOT.calibration.yaml``): only the belief does. A simulated robot must
behave the same way, or a calibration could never take effect (the body
would be rebuilt from the estimate and its hidden errors applied again).

The simulated robot is therefore built from the robot's *nominal
description*, the drawing: the robot config file it was started from
(``config/ROBOT.yaml`` or the YAML path given), before any params file or
``-p`` override. Its hidden differences from the drawing are the simulator's
``sim.*`` errors (``sim.wheel_radius_spread``, ``sim.caster_offset_spread``,
``sim.wheel_separation_spread``, ``sim.steer_zero_spread``, drawn from
``sim.seed``).

Which keys are the drawing's: the **kinematic geometry** (every parameter of
the kinematics family: wheel radii, caster offsets and steering-axis
positions, wheel separation, turret offset) and the **encoder zeros**
(``joints.*.zero_correction``). A value given for one of these on top of the
file -- a calibration overlay, or ``-p`` -- changes the controller only.
Every other key (joint speed and torque limits, the body's masses and sizes,
the ``sim.*`` and driver settings) is the same for the controller and the
simulated robot, wherever it was set.

:func:`driver_for` builds a config's driver with that body; every route into
the simulator (the bringup's control loop, the physics process, simulated CAN
drives, the offline experiments) goes through it, so that they all build the
same body.
"""

from __future__ import annotations

from pathlib import Path

from holonomic_core.config import build_model, model_specs, read_params_file
from holonomic_core.schema import ConfigError


def geometry_keys(flat) -> set[str]:
    """The flat keys of the drawing's geometry for the family ``flat``
    names: its kinematics' parameters and every joint's zero correction."""
    _, kinematics, _ = model_specs(flat)
    keys = {spec.name for spec in kinematics.param_specs(flat)}
    return keys | {k for k in flat if k.startswith("joints.") and k.endswith(".zero_correction")}


def nominal_model(config):
    """The :class:`~holonomic_core.model.RobotModel` of ``config``'s robot
    as drawn: its config file's kinematic geometry and encoder zeros, every
    other model key (limits, masses) as in ``config``.

    ``config`` is a :class:`~holonomic_core.config.RobotConfig`; its
    ``source`` names the file. Without a readable file (a config given as
    parameters alone), or when the file alone does not describe the geometry
    (a key it lacks came from an override), the config itself is the drawing.
    """
    path = Path(config.source) if config.source else None
    if path is None or not path.is_file():
        return config.model
    try:
        drawn = read_params_file(path)
    except ConfigError:
        return config.model
    values = dict(config.model.params)
    keys = geometry_keys(values)
    # all of them from the file (missing ones take their defaults there, e.g.
    # per-caster radii from the common one): none left from the overrides
    flat = {k: v for k, v in values.items() if k not in keys}
    flat.update({k: v for k, v in drawn.items() if k in keys})
    try:
        return build_model(flat)[0]
    except ConfigError:
        return config.model


def driver_for(config, model=None, **kwargs):
    """``config``'s driver, not yet configured: ``config.driver_class`` for
    ``model`` (default ``config.model``: the controller's) with the config's
    values and control rate. A driver that simulates the robot
    (``simulates_body``: the sim driver, simulated CAN drives) also gets the
    nominal description as its ``body`` (:func:`nominal_model`).
    ``kwargs``: the driver class's own keyword arguments (a shared world)."""
    cls = config.driver_class
    if getattr(cls, "simulates_body", False):
        kwargs.setdefault("body", nominal_model(config))
    return cls(config.model if model is None else model, config.values,
               config.controller.control_rate, **kwargs)
