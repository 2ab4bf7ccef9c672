"""The README's Python API: importable from the venv's python with nothing
sourced, and its inputs checked with a ValueError that says what it expected."""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

from holonomic_core.model import load_model


def test_the_api_imports_from_the_venv_python_with_nothing_sourced():
    # The environment a new user has: no PYTHONPATH, no ROS variables.
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "AMENT_PREFIX_PATH", "LD_LIBRARY_PATH", "COLCON_PREFIX_PATH")}
    code = ("from holonomic_core.model import load_model\n"
            "m = load_model('xr4000')\n"
            "rates = m.inverse([0.0] * 8, [0.3, 0.0, 0.2])\n"
            "print(*m.forward([0.0] * 8, rates), sep=',')\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, timeout=60, cwd="/")
    assert proc.returncode == 0, proc.stderr
    # inverse then forward (slip_min) returns the commanded body twist
    assert [float(v) for v in proc.stdout.split(",")] == pytest.approx([0.3, 0.0, 0.2], abs=1e-9)


HAMR = load_model("hamr")
XR = load_model("xr4000")

# (model, call, words of the message)
BAD_CALLS = [
    (HAMR, lambda m: m.inverse([0, 0, 0], [0, 0.3]),
     "twist: expected 3 numbers (vx, vy, wz in base_link), got shape (2,)"),
    (HAMR, lambda m: m.inverse([0, 0], [0, 0.3, 0]),
     "positions: expected 3 numbers (one per joint of hamr: left_wheel_joint, right_wheel_joint, "
     "turret_joint)"),
    (HAMR, lambda m: m.inverse([0, 0, 0], [math.nan, 0, 0]), "twist: expected finite numbers"),
    (XR, lambda m: m.forward([0] * 8, [0] * 7), "velocities: expected 8 numbers"),
    (XR, lambda m: m.forward([0] * 8, [math.inf] + [0] * 7), "velocities: expected finite numbers"),
    (XR, lambda m: m.forward(np.zeros((2, 8)), [0] * 8), "got shape (2, 8)"),
    (XR, lambda m: m.inverse(["a"] * 8, [0, 0, 0]), "positions: expected 8 numbers"),
    (XR, lambda m: m.jacobian([0] * 9), "positions: expected 8 numbers"),
]


@pytest.mark.parametrize("model,call,words", BAD_CALLS, ids=[w[:40] for *_, w in BAD_CALLS])
def test_bad_inputs_raise_a_value_error_saying_what_was_expected(model, call, words):
    with pytest.raises(ValueError) as err:
        call(model)
    assert words in str(err.value)
