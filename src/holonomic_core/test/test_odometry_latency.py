"""The latency term of the pose covariance (OdometryNoise.latency_variance).

By hand: readings that lag their stamps by tau put the published pose
tau * u behind the true one, u = (R(yaw) (vx, vy), wz) the twist in odom;
with E[tau^2] = latency_variance the term is latency_variance * u u^T. It
follows the current twist: it is there while the base moves and gone when
it stops (it does not accumulate like the per-metre or slip terms).
"""

import math

import numpy as np
import pytest

from holonomic_core.model import load_model
from holonomic_core.odometry import Odometry, OdometryNoise
from test_limits_odometry import drive   # constant body twist -> encoder readings

#: every test here runs on both implementations of the cycle's closed forms
#: ([pure], [compiled]: the hot_path_mode fixture of holonomic_testing)
pytestmark = pytest.mark.usefixtures("hot_path_mode")

ZERO = (0.0, 0.0, 0.0)
LATENCY = OdometryNoise(0.0, 0.0, 0.0, 0.0, 0.0, ZERO, ZERO, ZERO, latency_variance=1e-4,
                        slip4_position_gain=0.0, slip4_heading_gain=0.0)


def test_straight_motion_adds_variance_along_the_motion_only():
    model = load_model("hamr")
    odo = Odometry(model, noise=LATENCY, twist_window=0.03)
    odo.reset((0.0, 0.0, math.pi / 2))
    q = np.zeros(3)
    odo.update(q, 0.0)
    # body x at 1 m/s, heading pi/2: u = (0, 1, 0) m/s in odom, so the
    # covariance is 1e-4 s^2 * (1 m/s)^2 = 1e-4 m^2 along y, nothing else
    q, t = drive(model, odo, q, np.array([1.0, 0.0, 0.0]), 0.5)
    expected = np.diag([0.0, 1e-4, 0.0])
    assert odo.pose_covariance == pytest.approx(expected, abs=1e-9)


def test_turning_adds_heading_variance_that_goes_when_the_base_stops():
    model = load_model("xr4000")
    odo = Odometry(model, noise=LATENCY, twist_window=0.03)
    q = np.zeros(len(model.joint_names))
    odo.update(q, 0.0)
    # a turn on the spot at 2 rad/s: u = (0, 0, 2), heading variance
    # 1e-4 s^2 * (2 rad/s)^2 = 4e-4 rad^2
    q, t = drive(model, odo, q, np.array([0.0, 0.0, 2.0]), 0.5)
    assert odo.pose_covariance[2, 2] == pytest.approx(4e-4, rel=1e-3)
    assert odo.pose_covariance[:2, :2] == pytest.approx(np.zeros((2, 2)), abs=1e-9)
    # stopped for longer than the twist window: the twist is 0, and so is
    # the term (nothing else in this noise accumulates)
    for _ in range(20):
        t += 0.005
        odo.update(q, t)
    assert odo.pose_covariance == pytest.approx(np.zeros((3, 3)), abs=1e-15)


def test_without_latency_variance_the_covariance_is_the_accumulated_one():
    model = load_model("hamr")
    noise = OdometryNoise(linear_variance_per_meter=1e-3, angular_variance_per_radian=0.0,
                          angular_variance_per_meter=0.0, slip_position_gain=0.0,
                          slip_heading_gain=0.0, latency_variance=0.0)
    odo = Odometry(model, noise=noise, twist_window=0.03)
    odo.update(np.zeros(3), 0.0)
    drive(model, odo, np.zeros(3), np.array([1.0, 0.0, 0.0]), 1.0)
    # along-track: 1e-3 m^2/m * 1 m, no term from the 1 m/s twist
    assert odo.pose_covariance[0, 0] == pytest.approx(1e-3, rel=1e-3)
