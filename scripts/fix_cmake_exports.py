"""Point the ROS wheels' CMake export files at this interpreter.

The ``ros-*`` wheels are built on manylinux machines; their ``*Export.cmake``
files under ``<venv>/share`` name that machine's Python include folder
(``/opt/python/cpXY-cpXY/include/pythonX.Y``, one per CPython version) and
its numpy include folder (``.../site-packages/numpy/_core/include`` or
``numpy/core/include``). Building a message package (tf2_msgs) against them
fails on any other machine. This rewrites both, in every export file, to the
running interpreter's include folder and ``numpy.get_include()``; it is
idempotent (scripts/setup.sh runs it on every set-up).

Usage: python scripts/fix_cmake_exports.py VENV
"""

from __future__ import annotations

import re
import sys
import sysconfig
from pathlib import Path

#: a manylinux image's interpreter include folder, any version (and free-threaded)
PYTHON_INCLUDE = re.compile(r"/opt/python/cp\d+-cp\d+t?/include/python\d+\.\d+t?")
#: any numpy include folder inside a site-packages (up to a quote or list separator)
NUMPY_INCLUDE = re.compile(r"[^\";]*/site-packages/numpy/(?:_core|core)/include")


def fix_text(text: str, python_include: str, numpy_include: str) -> str:
    """``text`` with the build machine's include folders replaced."""
    text = PYTHON_INCLUDE.sub(lambda m: python_include, text)
    return NUMPY_INCLUDE.sub(lambda m: numpy_include, text)


def fix_tree(prefix: Path, python_include: str, numpy_include: str) -> int:
    """Rewrite every ``*Export.cmake`` under ``prefix/share``; the number changed."""
    changed = 0
    for path in (prefix / "share").rglob("*Export.cmake"):
        text = path.read_text()
        new = fix_text(text, python_include, numpy_include)
        if new != text:
            path.write_text(new)
            changed += 1
    return changed


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: fix_cmake_exports.py VENV", file=sys.stderr)
        return 2
    import numpy
    changed = fix_tree(Path(argv[0]), sysconfig.get_paths()["include"], numpy.get_include())
    if changed:
        print(f"setup: pointed {changed} CMake export file(s) at this interpreter",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
