"""Plugins by entry points: a robot family that is not in the repository
plugs in by installing a distribution with a ``holonomic.kinematics`` entry
point -- no edit of the core -- and the core names no package above it.

The toy family is a three-wheel omni base ("kiwi drive"), written here and
installed into a temporary folder as a real distribution (a ``.dist-info``
with ``entry_points.txt``, what pip or colcon writes), then used from a fresh
interpreter whose path includes that folder.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import holonomic_core

# Wheel i sits at angle alpha_i = 0, 120, 240 deg from base_link x, at
# distance L from the centre, rolling tangentially, direction (-sin a, cos a):
# rim speed = -sin(a) vx + cos(a) vy + L wz, joint rate = rim speed / r.
TOY_FAMILY = '''
import numpy as np

from holonomic_core.kinematics import BaseKinematics
from holonomic_core.schema import ParamSpec

ANGLES = np.radians([0.0, 120.0, 240.0])


class KiwiKinematics(BaseKinematics):
    kind = "kiwi"

    def __init__(self, r, L):
        self.r, self.L = r, L
        self._m = np.column_stack((-np.sin(ANGLES), np.cos(ANGLES), np.full(3, L))) / r

    @property
    def joint_names(self):
        return ("w0_joint", "w1_joint", "w2_joint")

    def inverse(self, positions, twist):
        return self._m @ np.asarray(twist, float)

    def forward(self, positions, velocities, estimator="slip_min"):
        return np.linalg.solve(self._m, np.asarray(velocities, float))

    def jacobian(self, positions):
        return np.linalg.inv(self._m)

    @classmethod
    def param_specs(cls, params):
        return [ParamSpec("kiwi.wheel_radius", "double", "Wheel radius [m].", minimum=0.0,
                          exclusive_minimum=True, maximum=1.0),
                ParamSpec("kiwi.base_radius", "double", "Wheel distance from centre [m].",
                          minimum=0.0, exclusive_minimum=True, maximum=10.0)]

    @classmethod
    def from_params(cls, values):
        return cls(values["kiwi.wheel_radius"], values["kiwi.base_radius"])
'''

TOY_ROBOT = '''
base_controller:
  ros__parameters:
    robot: {name: toy, kinematics: kiwi}
    kiwi: {wheel_radius: 0.05, base_radius: 0.2}
    joints:
      w0_joint: {max_velocity: 30.0}
      w1_joint: {max_velocity: 30.0}
      w2_joint: {max_velocity: 30.0}
    limits:
      linear:
        x: {max_velocity: 1.0, max_acceleration: 1.0, max_deceleration: 1.0}
        y: {max_velocity: 1.0, max_acceleration: 1.0, max_deceleration: 1.0}
      angular:
        z: {max_velocity: 2.0, max_acceleration: 2.0, max_deceleration: 2.0}
'''

# Runs in the fresh interpreter: the controller drives the toy base on the
# mock driver for 2 s of simulated time at (0.3, 0, 0).
DRIVE = '''
import json, sys
from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.loop import ManualClock
from holonomic_core.schema import ConfigError

cfg = load_config(sys.argv[1], {"driver": "mock", "cmd_timeout": 0.0})
clock = ManualClock()
with cfg.driver_class(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock) as drv:
    ctrl = BaseController(cfg, drv, clock=clock)
    ctrl.request_enable(True)
    ctrl.step()
    ctrl.set_command((0.3, 0.0, 0.0))
    for _ in range(400):
        clock.now += ctrl.dt
        ctrl.step()
try:
    load_config(sys.argv[1], {"driver": "mock", "kiwi.wheel_radius": 0.0})
    bad = ""
except ConfigError as exc:
    bad = str(exc)
json.dump({"joint_names": cfg.model.joint_names, "rates": ctrl.joint_command.tolist(),
           "twist": ctrl.odometry.twist.tolist(), "pose": ctrl.odometry.pose.tolist(),
           "bad": bad}, sys.stdout)
'''


@pytest.fixture(scope="module")
def toy_site(tmp_path_factory) -> Path:
    """A folder holding the toy family as an installed distribution."""
    site = tmp_path_factory.mktemp("site")
    (site / "toy_kiwi.py").write_text(TOY_FAMILY)
    info = site / "toy_kiwi-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-kiwi\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[holonomic.kinematics]\nkiwi = toy_kiwi:KiwiKinematics\n")
    (site / "toy.yaml").write_text(TOY_ROBOT)
    return site


def _run(site: Path, code: str, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(site), env.get("PYTHONPATH")) if p)
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          env=env, timeout=120, cwd=site)


def test_a_family_installed_by_entry_point_runs_the_controller_without_a_core_edit(toy_site):
    proc = _run(toy_site, DRIVE, str(toy_site / "toy.yaml"))
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["joint_names"] == ["w0_joint", "w1_joint", "w2_joint"]
    # (0.3, 0, 0) after the 1 m/s^2 ramp (0.3 s of 2 s): rates -sin(a) 0.3 / 0.05
    # = (0, -sin 120 deg, -sin 240 deg) * 6 = (0, -5.196, +5.196) rad/s
    assert out["rates"] == pytest.approx([0.0, -5.196152, 5.196152], abs=1e-5)
    # ideal mock motors: the odometry sees exactly the commanded twist, and
    # the base went straight: 0.3 m/s for 2 s less half the 0.3 s ramp
    # (x = 0.3 * (2.0 - 0.15) = 0.555 m; the first cycle's command starts the
    # ramp one cycle late: +-0.3 * 0.005 m)
    assert out["twist"] == pytest.approx([0.3, 0.0, 0.0], abs=1e-9)
    assert out["pose"][0] == pytest.approx(0.555, abs=0.002)
    assert out["pose"][1:] == pytest.approx([0.0, 0.0], abs=1e-12)
    # the family's own schema validates its keys
    assert "'kiwi.wheel_radius' = 0.0" in out["bad"]


def test_an_unknown_family_names_the_installed_ones_and_the_nearest(toy_site):
    code = ("from holonomic_core.config import load_config\n"
            "from holonomic_core.schema import ConfigError\n"
            "import sys\n"
            "try:\n"
            "    load_config(sys.argv[1], {'robot.kinematics': 'kiwii'})\n"
            "except ConfigError as exc:\n"
            "    print(exc)\n")
    proc = _run(toy_site, code, str(toy_site / "toy.yaml"))
    assert proc.returncode == 0, proc.stderr
    line = proc.stdout.strip()
    assert "\n" not in line
    assert "'robot.kinematics' = 'kiwii'" in line and "did you mean 'kiwi'?" in line
    assert "'ddrot'" in line and "'pcv'" in line      # the families this repository installs


def test_the_core_names_no_package_above_it():
    core = Path(holonomic_core.__file__).resolve().parent
    above = ("hamr_base", "pcv_base", "holonomic_sim", "holonomic_drivers",
             "holonomic_bringup", "holonomic_analysis", "swerve_base")
    for path in sorted(core.rglob("*.py")):
        text = path.read_text()
        for name in above:
            assert name not in text, f"{path.name} names {name}"
