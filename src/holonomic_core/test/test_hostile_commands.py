"""Hostile commands against the controller core (property-based).

Whatever arrives on cmd_vel -- NaN, +-inf, 1e308, -0.0, subnormals, huge
rotation with a tiny translation, signs alternating every cycle -- no
exception escapes, every joint command is finite and within its limit, a
scaled command keeps its direction, and a non-finite command never moves the
robot. Over 10 000 generated twists (fixed seed: hypothesis derandomized).
"""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.mock_driver import MockDriver

CONFIG = load_config("hamr", {"driver": "mock"})
LIMITS = CONFIG.model.max_joint_velocity

hostile_float = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64),
    st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, -0.0, 0.0, 5e-324,
                     -5e-324, 1e-300, 1e300]),
    st.floats(-5.0, 5.0),
)
hostile_twist = st.tuples(hostile_float, hostile_float, hostile_float)
turret = st.floats(-4 * math.pi, 4 * math.pi)


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def armed_controller(turret_angle=0.0):
    clock = Clock()
    driver = MockDriver(CONFIG.model, CONFIG.values, CONFIG.controller.control_rate, clock=clock)
    driver.configure()
    driver._positions[2] = turret_angle
    ctrl = BaseController(CONFIG, driver, clock=clock)
    ctrl.request_enable(True)
    clock.t += ctrl.dt
    ctrl.step()
    assert driver.armed
    return ctrl, clock


def step(ctrl, clock, twist):
    ctrl.set_command(twist)
    clock.t += ctrl.dt
    ctrl.step()


def assert_safe(ctrl):
    command = ctrl.joint_command
    assert np.all(np.isfinite(command))
    assert np.all(np.abs(command) <= LIMITS * (1 + 1e-9))
    assert np.all(np.isfinite(ctrl.twist_command))


@settings(max_examples=4000, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(twist=hostile_twist, phi=turret)
def test_any_single_command_is_safe_and_keeps_its_direction(twist, phi):
    ctrl, clock = armed_controller(phi)
    for _ in range(3):
        step(ctrl, clock, twist)
        assert_safe(ctrl)
    finite = all(math.isfinite(v) for v in twist)
    if not finite:
        # rejected: never motion
        assert np.all(ctrl.joint_command == 0.0)
        assert np.all(ctrl.twist_command == 0.0)
        return
    target = np.array(twist, float)
    out = ctrl.twist_command
    # from rest, the output is the target scaled by one factor in [0, 1]
    # (speed limits, acceleration ramp, joint saturation are all uniform)
    biggest = np.max(np.abs(target))
    if biggest == 0.0:
        return
    unit = target / biggest                 # no overflow for 1e308 components
    unit /= np.linalg.norm(unit)
    along = float(out @ unit)
    assert along >= -1e-12
    assert np.linalg.norm(out - along * unit) <= 1e-9 * max(1.0, np.linalg.norm(out))


@settings(max_examples=3000, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(twists=st.lists(hostile_twist, min_size=1, max_size=8), phi=turret)
def test_any_sequence_of_commands_stays_within_limits(twists, phi):
    ctrl, clock = armed_controller(phi)
    previous = ctrl.twist_command.copy()
    accel = np.maximum(CONFIG.controller.max_acceleration, CONFIG.controller.max_deceleration)
    for twist in twists:
        step(ctrl, clock, twist)
        assert_safe(ctrl)
        # never faster changes than the acceleration/deceleration limits allow
        assert np.all(np.abs(ctrl.twist_command - previous) <= accel * ctrl.dt + 1e-9)
        previous = ctrl.twist_command.copy()


@settings(max_examples=3000, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(junk=st.one_of(st.none(), st.text(max_size=3), st.lists(st.floats(), max_size=2),
                      st.tuples(st.text(max_size=2), st.floats(), st.floats())))
def test_malformed_commands_are_rejected_without_an_exception(junk):
    ctrl, clock = armed_controller()
    message = ctrl.set_command(junk)
    clock.t += ctrl.dt
    ctrl.step()
    assert message is not None and "rejected" in message
    assert np.all(ctrl.joint_command == 0.0)


def test_huge_rotation_with_tiny_translation_is_scaled_keeping_direction():
    ctrl, clock = armed_controller()
    for _ in range(400):
        step(ctrl, clock, (1e-6, 0.0, 1e6))
        assert_safe(ctrl)
    vx, vy, wz = ctrl.twist_command
    # the rotation reaches its limit (joint or twist limit), the translation
    # keeps the 1e-12 ratio, it is not clipped up to a meaningful speed
    assert wz > 1.0 and 0.0 <= vx <= 1e-12 * wz * (1 + 1e-6) and vy == 0.0


def test_signs_alternating_every_cycle_never_exceed_the_limits():
    ctrl, clock = armed_controller(0.7)
    decel = np.array(CONFIG.controller.max_deceleration)
    previous = np.zeros(3)
    for i in range(2000):
        sign = 1.0 if i % 2 else -1.0
        step(ctrl, clock, (sign * 1e3, -sign * 1e3, sign * 1e3))
        assert_safe(ctrl)
        assert np.all(np.abs(ctrl.twist_command - previous) <= decel * ctrl.dt + 1e-9)
        previous = ctrl.twist_command.copy()
    # chattering input averages to nothing: the base stays slow
    assert np.linalg.norm(ctrl.twist_command[:2]) < 0.05


def test_a_non_finite_command_while_moving_stops_the_base():
    ctrl, clock = armed_controller()
    for _ in range(300):
        step(ctrl, clock, (0.5, 0.2, 0.0))
    assert ctrl.twist_command[0] > 0.4
    speeds = []
    for _ in range(200):
        step(ctrl, clock, (math.nan, 0.2, 0.0))
        speeds.append(np.linalg.norm(ctrl.twist_command))
    assert all(b <= a + 1e-12 for a, b in zip(speeds, speeds[1:]))
    # at rest within the braking time: the limiter scales the whole change
    # uniformly, so x (0.5 m/s at 2.0 m/s^2, hamr.yaml) sets it: 0.25 s = 50
    # cycles (+ 1 for rounding) -- well before cmd_timeout (0.5 s = 100
    # cycles) would stop a base that kept the last good command
    brake = math.ceil(0.5 / (2.0 * ctrl.dt)) + 1
    assert brake < ctrl.cmd_timeout / ctrl.dt
    assert speeds[brake] == 0.0, speeds[brake]
    assert ctrl.counters["rejected_commands"] == 200


@pytest.mark.parametrize("bad", [(math.nan, 0, 0), (0, math.inf, 0), (0, 0, -math.inf)])
def test_non_finite_commands_from_rest_never_produce_a_joint_command(bad):
    ctrl, clock = armed_controller()
    for _ in range(100):
        step(ctrl, clock, bad)
        assert np.all(ctrl.joint_command == 0.0)
