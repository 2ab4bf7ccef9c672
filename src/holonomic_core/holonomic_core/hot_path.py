"""Which implementation of the control cycle's closed forms runs: compiled or pure Python.

The closed forms of a cycle -- the twist limits, the inverse kinematics
(DDROT and PCV), the joint-rate saturation, the slip_min fit and the DDROT's
forward kinematics, the odometry's arc and covariance -- exist twice: the
pure-Python reference (in the modules that own each equation) and the C
extension ``holonomic_core._hot_path``, built by ``make setup`` (colcon
builds it from ``_hot_path.c``), which does each of them in one call with
the same arithmetic in the same order (docs/hot_path.md: which results are
bitwise equal and which agree to a few ulp).

Selection: the environment variable ``HOLONOMIC_HOT_PATH``, read when a
cycle object (``TwistLimiter``, a kinematics object, ``Odometry``) is built
and when this module is first imported (``saturate_joint_rates``):

* ``auto`` (default): the compiled module when it is built, else the pure
  path with one warning line on stderr -- the numbers are the same, only
  the cycle costs about 3x more, which a 200 Hz loop affords;
* ``compiled``: the compiled module, or ImportError (a 1 kHz robot that
  needs it should not start without it);
* ``pure``: the pure-Python path (debugging, profiling the reference).

The dispatching functions: ``TwistLimiter.limit``,
``holonomic_core.limits.saturate_joint_rates``, ``BaseKinematics.inverse``
and ``.estimate`` of the families that give a ``hot_path_geometry``, and
``Odometry.update`` (one ``odometry_step`` call for an increment with dt > 0).
"""

from __future__ import annotations

import importlib
import os
import sys
from types import ModuleType

#: the environment variable that selects the path
ENV = "HOLONOMIC_HOT_PATH"
CHOICES = ("auto", "compiled", "pure")
#: kinematics kinds of the compiled module (its KIND_* constants)
KIND_DDROT = 1
KIND_PCV = 2

_loaded: ModuleType | None = None
_import_error: str | None = None
_warned = False


def choice() -> str:
    """The selected path (``HOLONOMIC_HOT_PATH``, default ``auto``); ValueError if invalid."""
    value = os.environ.get(ENV, "auto").strip().lower() or "auto"
    if value not in CHOICES:
        raise ValueError(f"{ENV}={value!r}: must be one of {', '.join(CHOICES)}")
    return value


def _import() -> ModuleType | None:
    global _loaded, _import_error
    if _loaded is None and _import_error is None:
        try:
            _loaded = importlib.import_module("holonomic_core._hot_path")
        except ImportError as exc:
            _import_error = str(exc)
    return _loaded


def module(selected: str | None = None) -> ModuleType | None:
    """The compiled module to dispatch to, or None for the pure-Python path.

    ``selected``: one of CHOICES (default: :func:`choice`). Under ``auto`` a
    missing module prints one warning line on stderr (once per process).
    """
    global _warned
    selected = choice() if selected is None else selected
    if selected == "pure":
        return None
    compiled = _import()
    if compiled is not None:
        return compiled
    if selected == "compiled":
        raise ImportError(f"{ENV}=compiled but holonomic_core._hot_path is not built "
                          f"({_import_error}); run `make setup`")
    if not _warned:
        _warned = True
        print(f"holonomic_core: warning: the compiled hot path is not built ({_import_error}); "
              f"running the pure-Python cycle (same numbers, ~3x the compute; `make setup` "
              f"builds it, {ENV}=pure silences this)", file=sys.stderr)
    return None


def name() -> str:
    """``"compiled"`` or ``"pure"``: what a cycle object built now would use."""
    return "pure" if module() is None else "compiled"
