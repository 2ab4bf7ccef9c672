"""pybullet stand-in for the hardware: URDF from the robot config, the `sim` driver backend.

pybullet's C module prints its build date when it is first imported -- on
every start of every program, even ``--help``. The package imports it once
here with the process's stdout and stderr (file descriptors 1 and 2) pointed
at /dev/null, and flushes C's stdio buffers there (when output is a pipe or a
file the line would otherwise wait in them until the process exits). An
import error still raises, after the descriptors are back.
"""

import ctypes as _ctypes
import os as _os
import sys as _sys
from ctypes.util import find_library as _find_library


def _import_pybullet_quietly() -> None:
    _sys.stdout.flush()
    _sys.stderr.flush()
    saved = {fd: _os.dup(fd) for fd in (1, 2)}
    null = _os.open(_os.devnull, _os.O_WRONLY)
    try:
        for fd in saved:
            _os.dup2(null, fd)
        try:
            import pybullet  # noqa: F401
        finally:
            _ctypes.CDLL(_find_library("c")).fflush(None)
    finally:
        for fd, copy in saved.items():
            _os.dup2(copy, fd)
            _os.close(copy)
        _os.close(null)


_import_pybullet_quietly()
