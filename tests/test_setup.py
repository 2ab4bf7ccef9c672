"""The set-up's rewrite of the ROS wheels' CMake export files works for any
interpreter version and any wheel build path (the cp311-only rewrite broke
the tf2_msgs build on Python 3.12)."""

from __future__ import annotations

import importlib.util
import sys
import sysconfig
from pathlib import Path

import numpy

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("fix_cmake_exports",
                                               ROOT / "scripts" / "fix_cmake_exports.py")
fix_cmake_exports = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fix_cmake_exports)


def test_every_manylinux_python_and_numpy_path_is_pointed_at_this_interpreter(tmp_path):
    # Lines as the ros-* wheels ship them (one per CPython build), with the
    # build machine's numpy in a pip build environment and in a plain venv.
    lines = {
        "cp311": '"/opt/python/cp311-cp311/include/python3.11;'
                 '/tmp/pip-build-env-x1/overlay/lib/python3.11/site-packages/numpy/_core/include"',
        "cp312": '"/opt/python/cp312-cp312/include/python3.12;'
                 '/tmp/pip-build-env-y2/overlay/lib/python3.12/site-packages/numpy/core/include"',
        "cp313": 'INTERFACE_INCLUDE_DIRECTORIES "/opt/python/cp313-cp313/include/python3.13"',
    }
    share = tmp_path / "share" / "pkg" / "cmake"
    share.mkdir(parents=True)
    for tag, text in lines.items():
        (share / f"pkg_{tag}Export.cmake").write_text(text + "\n")
    (share / "untouched.cmake").write_text(lines["cp312"])
    assert fix_cmake_exports.fix_tree(tmp_path, "/py/include", "/np/include") == 3
    assert (share / "pkg_cp311Export.cmake").read_text() == '"/py/include;/np/include"\n'
    assert (share / "pkg_cp312Export.cmake").read_text() == '"/py/include;/np/include"\n'
    assert (share / "pkg_cp313Export.cmake").read_text() == \
        'INTERFACE_INCLUDE_DIRECTORIES "/py/include"\n'
    assert (share / "untouched.cmake").read_text() == lines["cp312"]   # not an export file
    # idempotent: a second run changes nothing
    assert fix_cmake_exports.fix_tree(tmp_path, "/py/include", "/np/include") == 0


def test_the_installed_wheels_name_only_this_interpreter():
    # The venv the tests run in, after `make setup`: no build-machine path left.
    exports = list((Path(sys.prefix) / "share").rglob("*Export.cmake"))
    assert exports, f"no CMake export files under {sys.prefix}/share"
    py_inc, np_inc = sysconfig.get_paths()["include"], numpy.get_include()
    for path in exports:
        text = path.read_text()
        assert "/opt/python/" not in text, path
        for match in fix_cmake_exports.NUMPY_INCLUDE.findall(text):
            assert match == np_inc, (path, match)
    assert any(py_inc in p.read_text() for p in exports)
