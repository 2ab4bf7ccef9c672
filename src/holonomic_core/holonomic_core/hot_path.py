"""Which implementation of the control cycle's closed forms runs: compiled or pure Python.

The closed forms of a cycle -- the twist limits, the inverse kinematics
(DDROT and PCV), the joint-rate saturation, the slip_min fit and the DDROT's
forward kinematics, the odometry's increment, arc and covariance, the twist
window's line fit, the reading checks, the PCV's operational-space terms
of torque mode -- exist twice: the pure-Python
reference (in the modules that own each equation) and the C extension
``holonomic_core._hot_path``, built by ``make setup`` (colcon builds it from
``_hot_path.c``), which does each of them in one call with the same
arithmetic in the same order (docs/hot_path.md: which results are bitwise
equal and which agree to a few ulp).

Selection: the environment variable ``HOLONOMIC_HOT_PATH``, read when a
cycle object is built (``TwistLimiter``, a kinematics object, ``Odometry``,
``ReadingMonitor``, ``BaseController``'s saturation, ``PcvDynamics``):

* ``auto`` (default): the compiled module when it is built, else the pure
  path with one warning line on stderr -- the numbers are the same, only
  the cycle costs several times more, which a 200 Hz loop affords;
* ``compiled``: the compiled module, or ImportError (a 1 kHz robot that
  needs it should not start without it);
* ``pure``: the pure-Python path (debugging, profiling the reference).

The dispatching methods (docs/hot_path.md has the table): ``TwistLimiter.limit``,
``limits.joint_rate_saturation()``, ``inverse`` and ``estimate`` of the
kinematics families, ``Odometry.update`` (through the families'
``hot_path_geometry``) and ``_update_twist``, ``ReadingMonitor.check``,
``PcvDynamics.terms``.
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
#: the compiled PCV fit's fixed buffers hold this many casters (more: pure path)
MAX_CASTERS = 64

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
              f"running the pure-Python cycle (same numbers, 4-8x the compute; `make setup` "
              f"builds it, {ENV}=pure silences this)", file=sys.stderr)
    return None


def name() -> str:
    """``"compiled"`` or ``"pure"``: what a cycle object built now would use."""
    return "pure" if module() is None else "compiled"
