"""Plugins: what the packages above the core provide, found by entry points.

The core names none of the packages that build on it. Each package declares
what it provides in its ``setup.py`` under a Python entry point group
(python-can's ``can.interface`` pattern), and the core looks it up by name::

    entry_points={
        "holonomic.kinematics": ["mecanum = my_base.kinematics:MecanumKinematics"],
        "holonomic.drivers": ["my_drive = my_drives.backend:MyDriveDriver"],
    }

A new robot family or driver is a new package with its entry points: no
edit of the core. The groups (:data:`GROUPS`), each keyed by the name the
YAML uses:

* ``holonomic.kinematics``: a :class:`~holonomic_core.kinematics.BaseKinematics`
  subclass per family (``robot.kinematics``);
* ``holonomic.description``: the family's physical body (``body.*``) and URDF,
  a :class:`~holonomic_core.description.Description` subclass;
* ``holonomic.dynamics``: the family's dynamic model for torque mode (a class
  with ``from_model(model)``);
* ``holonomic.calibration``: the family's self-calibration model;
* ``holonomic.drivers``: a :class:`~holonomic_core.driver.Driver` subclass
  per backend (``driver``);
* ``holonomic.driver_adapters``: functions of a driver class to a driver
  class (``sim_drives``: a CAN backend on emulated drives);
* ``holonomic.emulated_drives``: the emulated device of a backend that has
  one (``driver``; ``--sim-drives`` and the CAN test rig run it), a class
  built as ``cls(node_id, channel, **cls.settings_for(params, joint))``.

Entry points are read once per process (installed packages do not change
while it runs). Plugins are imported only when used, so that a DDROT user
needs no PCV code and a simulator user no CAN library.
"""

from __future__ import annotations

import difflib
import functools
from importlib import metadata
from typing import Any

from holonomic_core.schema import ConfigError

#: role -> entry point group
GROUPS = {
    "kinematics": "holonomic.kinematics",
    "description": "holonomic.description",
    "dynamics": "holonomic.dynamics",
    "calibration": "holonomic.calibration",
    "drivers": "holonomic.drivers",
    "driver_adapters": "holonomic.driver_adapters",
    "emulated_drives": "holonomic.emulated_drives",
}


@functools.cache
def _entry_points(role: str) -> dict[str, metadata.EntryPoint]:
    # one distribution may be on the path twice (a colcon build folder and
    # its install folder): the first one found wins, as for imports
    found: dict[str, metadata.EntryPoint] = {}
    for entry in metadata.entry_points(group=GROUPS[role]):
        found.setdefault(entry.name, entry)
    return found


def names(role: str) -> tuple[str, ...]:
    """The installed plugins of ``role`` (a key of :data:`GROUPS`), sorted."""
    return tuple(sorted(_entry_points(role)))


def provides(role: str, name: str) -> bool:
    """Whether an installed package provides plugin ``name`` of ``role``."""
    return name in _entry_points(role)


def load(role: str, name: str, key: str, wanted: str | None = None) -> Any:
    """The object plugin ``name`` of ``role`` points at, imported now.

    Raises :class:`ConfigError` on ``key`` (the parameter that named it): for
    an unknown name, listing the installed ones and the nearest ("did you
    mean"); for a package that fails to import, saying why. ``wanted``
    replaces the list of installed names in the first message.
    """
    entries = _entry_points(role)
    entry = entries.get(name)
    if entry is None:
        installed = sorted(entries)
        nearest = difflib.get_close_matches(str(name), installed, n=1)
        text = wanted or (f"one of {installed} (the installed '{GROUPS[role]}' entry points)"
                          if installed else f"an installed '{GROUPS[role]}' entry point (none is)")
        if nearest:
            text += f"; did you mean '{nearest[0]}'?"
        raise ConfigError(key, name, text)
    try:
        return entry.load()
    except (ImportError, AttributeError) as exc:
        # one line: the import error of a package that is missing a dependency
        reason = " ".join(str(exc).split())
        raise ConfigError(key, name, f"a plugin that loads ({entry.value}: {reason})") from exc
