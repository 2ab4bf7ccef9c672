"""The compiled hot path gives the pure-Python path's numbers (ROS-free).

Every dispatching function is run on the same inputs twice: objects built
with HOLONOMIC_HOT_PATH=pure and with HOLONOMIC_HOT_PATH=compiled (the env
var is read when an object is built), or the compiled module's function
against its pure reference. The C code repeats the Python expressions
operation for operation, without fused multiply-add, and calls the same
libm, so most results must be *bitwise* equal. Three kinds of result are
not, and are compared to a tolerance a few times the measured difference:

* the per-caster residual, the slip and the distance: Python's math.hypot
  is CPython's own algorithm, not libm's hypot (1 ulp apart in ~0.1 % of
  inputs), and numpy's dot sums in its own order; with what they feed, the
  pose covariance (distance, slip terms) and the twist covariance (slip):
  measured <= 5.7e-16 of the largest entry; tolerance 2e-15;
* the windowed twist (a line fit over ``odometry.twist_window``): numpy
  sums the means pairwise and the fit in BLAS, the C code in row order:
  measured <= 3.8e-15 of the largest component (a fast turn); tolerance
  2e-14; and its covariance, whose lag term divides the twist's difference
  by the window (measured <= 4.5e-14 of the largest variance; tolerance 2e-13).

Measured with this file's inputs (a python -c loop over _odometry_states).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from holonomic_core import hot_path
from holonomic_core.config import load_config
from holonomic_core.limits import TwistLimiter, saturate_joint_rates_pure
from holonomic_core.odometry import Odometry

COMPILED = hot_path.module("compiled")     # ImportError: `make setup` did not build it
ROBOTS = ("hamr", "xr4000")
REL_ULPS = 2e-15
#: geometries unlike the shipped configs' symmetric ones, so that a twin that
#: mixes up two parameters the configs give equal values (the left and right
#: wheel radius, the half separation a and the turret offset b, one caster's
#: h, beta, r or b and another's) cannot agree with the other twin
IRREGULAR = {
    # a worn left tyre, a new right one, b != a (0.23 against 0.1641 m)
    "hamr_uneven": ("hamr", {"ddrot.left_wheel_radius": 0.0601,
                             "ddrot.right_wheel_radius": 0.0632,
                             "ddrot.turret_offset": 0.23}),
    # every caster its own h, beta, wheel radius and offset
    "xr4000_irregular": ("xr4000", {
        "pcv.front_left.h": 0.26, "pcv.front_left.beta": 0.70,
        "pcv.front_left.wheel_radius": 0.057, "pcv.front_left.caster_offset": 0.018,
        "pcv.rear_left.h": 0.22, "pcv.rear_left.beta": 2.50,
        "pcv.rear_left.wheel_radius": 0.052, "pcv.rear_left.caster_offset": 0.026,
        "pcv.rear_right.h": 0.25, "pcv.rear_right.beta": -2.20,
        "pcv.rear_right.wheel_radius": 0.055, "pcv.rear_right.caster_offset": 0.021,
        "pcv.front_right.h": 0.21, "pcv.front_right.beta": -0.90,
        "pcv.front_right.wheel_radius": 0.0585, "pcv.front_right.caster_offset": 0.015}),
}
GEOMETRIES = ROBOTS + tuple(IRREGULAR)


def robot_config(geometry):
    """load_config of a shipped robot (its name) or of an IRREGULAR geometry."""
    robot, overrides = IRREGULAR.get(geometry, (geometry, {}))
    return load_config(robot, {"driver": "mock", **overrides})


def build(monkeypatch, selected, factory):
    """``factory()`` built with HOLONOMIC_HOT_PATH=selected."""
    monkeypatch.setenv(hot_path.ENV, selected)
    return factory()


def both(monkeypatch, factory):
    return build(monkeypatch, "pure", factory), build(monkeypatch, "compiled", factory)


def same_bits(a, b):
    """Bitwise equality of float arrays (NaN equal to NaN, +0 != -0)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a.shape == b.shape and a.view(np.int64).tolist() == b.view(np.int64).tolist()


def close(a, b, rel=REL_ULPS):
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = max(np.max(np.abs(a), initial=0.0), 1e-300)
    return a.shape == b.shape and bool(np.all(np.abs(a - b) <= rel * scale))


# -- selection ------------------------------------------------------------------

def test_the_env_var_selects_the_path(monkeypatch):
    monkeypatch.setenv(hot_path.ENV, "pure")
    assert hot_path.module() is None and hot_path.name() == "pure"
    monkeypatch.setenv(hot_path.ENV, "compiled")
    assert hot_path.module() is COMPILED and hot_path.name() == "compiled"
    monkeypatch.setenv(hot_path.ENV, "auto")
    assert hot_path.module() is COMPILED       # built by make setup: auto takes it
    monkeypatch.setenv(hot_path.ENV, "fast")
    with pytest.raises(ValueError, match="HOLONOMIC_HOT_PATH='fast': must be one of auto, "
                                         "compiled, pure"):
        hot_path.module()


# A process in which the compiled module cannot be imported (as after a
# failed build): sys.modules[name] = None makes `import name` raise.
_WITHOUT_MODULE = """
import sys
sys.modules["holonomic_core._hot_path"] = None
import numpy as np
from holonomic_core.config import load_config
from holonomic_core.limits import TwistLimiter, saturate_joint_rates
cfg = load_config("xr4000", {"driver": "mock"})
kin = type(cfg.model.kinematics).from_params(cfg.values)
limiter = TwistLimiter((1.0, 1.0, 1.0), (1.0, 1.0, 1.0), (1.0, 1.0, 1.0))
print(kin.inverse(np.zeros(8), limiter.limit(np.array([2.0, 0.0, 0.0]), np.zeros(3), 0.1))[1])
"""


def _run_without_module(selected):
    env = dict(os.environ, **{hot_path.ENV: selected})
    return subprocess.run([sys.executable, "-c", _WITHOUT_MODULE], env=env, capture_output=True,
                          text=True, timeout=60)


def test_a_missing_compiled_module_runs_the_pure_path_with_one_warning_line():
    proc = _run_without_module("auto")
    assert proc.returncode == 0, proc.stderr
    # the limiter ramps x to 1 m/s^2 * 0.1 s = 0.1 m/s; the wheel of a caster
    # steered at phi = 0 rolls at vx / r = 0.1 / r rad/s (the XR4000's r)
    cfg = load_config("xr4000", {"driver": "mock"})
    r = cfg.model.kinematics.casters[0].wheel_radius
    assert float(proc.stdout) == pytest.approx(0.1 / r, rel=1e-12)
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and "compiled hot path is not built" in lines[0]
    assert "pure-Python cycle" in lines[0]


def test_a_missing_compiled_module_is_an_error_when_compiled_is_required():
    proc = _run_without_module("compiled")
    assert proc.returncode != 0
    assert "HOLONOMIC_HOT_PATH=compiled but holonomic_core._hot_path is not built" in proc.stderr


# -- limits ---------------------------------------------------------------------

def _limiter():
    return TwistLimiter((1.0, 0.5, 2.0), (2.0, 1.0, 4.0), (4.0, 2.0, 8.0))


def test_twist_limits_are_bitwise_those_of_the_pure_path(monkeypatch):
    pure, compiled = both(monkeypatch, _limiter)
    rng = np.random.default_rng(1)
    cases = [(rng.uniform(-3, 3, 3), rng.uniform(-1.2, 1.2, 3), rng.choice([0.001, 0.005, 0.1]))
             for _ in range(3000)]
    # the odd ones: no change, a reversal, zero, exactly at the limit, NaN and
    # infinite components (NaN passes through: the controller validates the
    # command before the limiter), a zero dt
    z = np.zeros(3)
    cases += [(z, z, 0.005), (np.array([1.0, 0.5, 2.0]), z, 0.005),
              (np.array([-1.0, 0.2, 0.0]), np.array([1.0, -0.2, 0.0]), 0.005),
              (np.array([0.3, 0.2, 0.1]), np.array([0.3, 0.2, 0.1]), 0.005),
              (np.array([math.nan, 0.1, 0.0]), z, 0.005),
              (np.array([math.inf, 0.1, 0.0]), z, 0.005),
              (np.array([-math.inf, 0.0, 0.0]), np.array([0.5, 0.0, 0.0]), 0.005),
              (np.array([0.5, 0.1, 0.0]), z, 0.0), (np.array([-0.0, 0.0, -0.0]), z, 0.005)]
    for target, previous, dt in cases:
        with np.errstate(invalid="ignore"):     # inf x 0 -> NaN, in both paths
            want = pure.limit(target, previous, dt)
        got = compiled.limit(target, previous, dt)
        assert same_bits(want, got), (target, previous, dt, want, got)
        assert got is not target and got is not previous


@pytest.mark.parametrize("jerk", [(5.0, 4.0, 40.0), (math.inf, 3.0, math.inf)],
                         ids=["every axis", "one axis"])
def test_speed_norm_and_jerk_limits_are_bitwise_those_of_the_pure_path(monkeypatch, jerk):
    pure, compiled = both(monkeypatch, lambda: TwistLimiter(
        (1.0, 0.5, 2.0), (2.0, 1.0, 4.0), (4.0, 2.0, 8.0), max_speed=0.8, max_jerk=jerk))
    rng = np.random.default_rng(3)
    cases = [(rng.uniform(-3, 3, 3), rng.uniform(-1.2, 1.2, 3), rng.choice([0.001, 0.005, 0.1]),
              rng.uniform(-10, 10, 3)) for _ in range(3000)]
    z = np.zeros(3)
    # at rest, arriving, a zero dt, an acceleration beyond the limits (clamped),
    # NaN passing through, a far target with a tiny jerk step (the continuous bound)
    cases += [(z, z, 0.005, z), (np.array([0.3, 0.2, 0.1]), np.array([0.3, 0.2, 0.1]), 0.005, z),
              (np.array([0.5, 0.1, 0.0]), z, 0.0, z), (z, np.array([0.5, 0.0, 0.0]), 0.005,
                                                       np.array([-50.0, 0.0, 0.0])),
              (np.array([math.nan, 0.1, 0.0]), z, 0.005, z),
              (np.array([0.8, 0.0, 0.0]), z, 1e-7, z)]
    # ramps: each step's output and acceleration feed the next
    for target, previous, dt, acc in list(cases[:50]):
        for _ in range(40):
            nxt = pure.limit(target, previous, dt, acc)
            cases.append((target, previous, dt, acc))
            previous, acc = nxt, (nxt - previous) / dt
    for target, previous, dt, acc in cases:
        with np.errstate(invalid="ignore"):
            want = pure.limit(target, previous, dt, acc)
        got = compiled.limit(target, previous, dt, acc)
        assert same_bits(want, got), (target, previous, dt, acc, want, got)


def test_joint_rate_saturation_is_bitwise_that_of_the_pure_path():
    rng = np.random.default_rng(2)
    limits = np.array([20.0, 20.0, 4.0, 6.0])
    cases = [rng.uniform(-40, 40, 4) for _ in range(2000)]
    cases += [np.zeros(4), limits.copy(), -limits, np.array([math.nan, 0, 0, 0]),
              np.array([0, math.inf, 0, 0]), np.array([1e308, 1e308, 1e308, 1e308])]
    for rates in cases:
        want, want_scale = saturate_joint_rates_pure(rates, limits)
        got, got_scale = COMPILED.saturate_joint_rates(rates, limits)
        assert same_bits(want, got) and same_bits(want_scale, got_scale), rates
        # within the limits both hand the caller's array back, unscaled
        assert (got is rates) == (want is rates)


# -- kinematics -----------------------------------------------------------------

def _kinematics(robot):
    cfg = robot_config(robot)
    return lambda: type(cfg.model.kinematics).from_params(cfg.values)


def _configurations(n, rng, count=1500):
    qs = [rng.uniform(-7, 7, n) for _ in range(count)]
    # singular-looking ones: every steering angle / the turret at 0, +-pi/2,
    # pi (a caster's wheel axis along the base's x or y), and huge angles
    qs += [np.full(n, a) for a in (0.0, math.pi / 2, -math.pi / 2, math.pi, 1e6)]
    return qs


@pytest.mark.parametrize("robot", GEOMETRIES)
def test_inverse_kinematics_are_bitwise_those_of_the_pure_path(monkeypatch, robot):
    pure, compiled = both(monkeypatch, _kinematics(robot))
    rng = np.random.default_rng(3)
    n = len(pure.joint_names)
    twists = [rng.uniform(-1, 1, 3) for _ in range(50)] + [
        np.zeros(3), np.array([math.nan, 0.0, 0.0]), np.array([0.0, 0.0, math.inf])]
    for k, q in enumerate(_configurations(n, rng)):
        twist = twists[k % len(twists)]
        assert same_bits(pure.inverse(q, twist), compiled.inverse(q, twist)), (q, twist)
    # plain lists work the same (the Python API takes sequences)
    assert same_bits(pure.inverse([0.1] * n, [0.3, 0.0, 0.2]),
                     compiled.inverse([0.1] * n, [0.3, 0.0, 0.2]))


@pytest.mark.parametrize("robot", GEOMETRIES)
def test_the_slip_min_fit_matches_the_pure_path(monkeypatch, robot):
    pure, compiled = both(monkeypatch, _kinematics(robot))
    rng = np.random.default_rng(4)
    n = len(pure.joint_names)
    for q in _configurations(n, rng):
        for rates in (rng.uniform(-10, 10, n), np.zeros(n)):
            want_twist, want_res = pure.estimate(q, rates, "slip_min")
            got_twist, got_res = compiled.estimate(q, rates, "slip_min")
            assert same_bits(want_twist, got_twist), (q, rates)
            assert close(want_res, got_res), (q, rates, want_res - got_res)
    # a non-finite joint rate: NaN out of both, never a number
    rates = np.zeros(n)
    rates[1] = math.nan
    assert np.isnan(compiled.estimate(np.zeros(n), rates)[0]).all()
    assert same_bits(pure.estimate(np.zeros(n), rates)[0], compiled.estimate(np.zeros(n), rates)[0])


def test_the_compiled_fit_serves_the_estimators_it_implements():
    # DDROT: exact for every estimator; PCV: slip_min only (robust and pinv
    # stay in Python, whatever the selection)
    hamr, xr = _kinematics("hamr")(), _kinematics("xr4000")()
    assert all(hamr.hot_path_geometry(e)[0] == hot_path.KIND_DDROT
               for e in ("slip_min", "pinv", "robust"))
    assert xr.hot_path_geometry("slip_min")[0] == hot_path.KIND_PCV
    assert xr.hot_path_geometry("robust") is None and xr.hot_path_geometry("pinv") is None


# -- odometry -------------------------------------------------------------------

def _readings(n, rng, count=600, dt=0.005):
    """A smooth encoder walk with the odd readings odometry must survive."""
    qs = np.cumsum(rng.uniform(-0.02, 0.02, (count, n)), axis=0)
    qs[200:260] += np.linspace(0, 3.0, 60)[:, None]        # a fast turn: dtheta > 1e-6
    stamps = np.arange(count) * dt
    stamps[300] = stamps[299]                              # a repeated stamp
    stamps[400:] -= 0.5                                    # the clock jumps back
    qs[450, 0] = math.nan                                  # a non-finite reading
    return qs, stamps


def _odometry_states(odo, qs, stamps):
    out = []
    for k, (q, stamp) in enumerate(zip(qs, stamps)):
        if k == 500:
            odo.rebase()
        odo.update(q, float(stamp))
        out.append((odo.pose.copy(), odo.rate_twist.copy(), odo.twist.copy(),
                    odo.pose_covariance, odo.twist_covariance, odo.residual.copy(),
                    odo.slip, odo.distance))
    return out


@pytest.mark.parametrize("window", [0.0, 0.03])
@pytest.mark.parametrize("robot", GEOMETRIES)
def test_odometry_matches_the_pure_path(monkeypatch, robot, window):
    cfg = robot_config(robot)
    c = cfg.controller
    # the model (its kinematics) is built under the same selection as the odometry
    pure, compiled = both(monkeypatch, lambda: Odometry(
        robot_config(robot).model, c.estimator, c.noise, window))
    rng = np.random.default_rng(5)
    qs, stamps = _readings(len(cfg.model.joint_names), rng)
    for k, (want, got) in enumerate(zip(_odometry_states(pure, qs, stamps),
                                        _odometry_states(compiled, qs, stamps))):
        pose, rate_twist, twist, pcov, tcov, residual, slip, distance = zip(want, got)
        assert same_bits(*pose), (k, pose)
        assert same_bits(*rate_twist), (k, rate_twist)
        if window == 0.0:
            assert same_bits(*twist), (k, twist)
            assert close(*tcov), (k, tcov)
        else:
            assert close(*twist, rel=2e-14), (k, twist)
            assert close(*tcov, rel=2e-13), (k, tcov)
        for a, b in (pcov, residual, slip, distance):
            assert close(a, b), (k, a, b)


@pytest.mark.parametrize("robot", ROBOTS)
def test_objects_built_with_compiled_selected_dispatch_to_it(monkeypatch, robot):
    # the compiled module checks its arguments' lengths itself (the pure
    # path would raise IndexError): its message shows the call went there
    compiled = build(monkeypatch, "compiled", _kinematics(robot))
    with pytest.raises(ValueError, match=r"^positions: 1 values, need \d+$"):
        compiled.inverse([0.0], [0.0, 0.0, 0.0])
    limiter = build(monkeypatch, "compiled", _limiter)
    with pytest.raises(ValueError, match=r"^target: 2 values, need 3$"):
        limiter.limit(np.zeros(2), np.zeros(3), 0.01)


# -- PCV dynamics (torque mode) ------------------------------------------------------

@pytest.mark.parametrize("robot", ["xr4000", "comr3"])
def test_the_pcv_dynamics_terms_are_bitwise_those_of_the_pure_path(monkeypatch, robot):
    """Lambda and mu of PcvDynamics.terms (torque mode's eq. 4 and bias, once a
    cycle): random configurations and twists, every caster where sin or cos
    vanishes and at 1e6 rad, no twist, rest, lists, and NaN and inf inputs,
    which propagate alike. The pure path against the numpy reference:
    pcv_base/test/test_dynamics_reference.py."""
    from pcv_base.dynamics import PcvDynamics
    from holonomic_core.model import load_model
    model = load_model(robot)
    pure, compiled = both(monkeypatch, lambda: PcvDynamics.from_model(model))
    n = len(model.joint_names)
    rng = np.random.default_rng(11)
    cases = [(rng.uniform(-7.0, 7.0, n), rng.normal(0.0, 1.5, 3)) for _ in range(300)]
    for phi in (0.0, math.pi / 2, -math.pi / 2, math.pi, 1e6):
        q = rng.uniform(-math.pi, math.pi, n)
        q[0::2] = phi
        cases += [(q, None), (q, np.zeros(3)), (q, np.array([0.4, -0.3, 2.0]))]
    q = rng.uniform(-3.0, 3.0, n)
    cases += [(list(q), (0.3, -0.2, 0.9)), (tuple(q), None),
              (q, np.array([math.nan, 0.0, 0.0])), (q, np.array([0.0, 0.0, math.inf]))]
    q_nan = q.copy()
    q_nan[2] = math.nan
    cases.append((q_nan, np.array([0.2, 0.1, 0.3])))
    for q, twist in cases:
        for a, b in zip(pure.terms(q, twist), compiled.terms(q, twist)):
            # a NaN's sign and payload depend on which operand the CPU
            # propagates (the compiler may swap a product's operands):
            # NaN where the pure path has NaN, every other entry bitwise
            nan = np.isnan(a)
            assert np.array_equal(nan, np.isnan(b)), (q, twist)
            assert same_bits(a[~nan], b[~nan]), (q, twist)
    # more positions than casters: both refuse (IndexError); fewer: both sum
    # the casters given
    for path in (pure, compiled):
        with pytest.raises(IndexError):
            path.terms(np.zeros(n + 2), None)
    fewer, twist = rng.uniform(-3.0, 3.0, n - 2), (0.2, 0.1, 0.3)
    for a, b in zip(pure.terms(fewer, twist), compiled.terms(fewer, twist)):
        assert same_bits(a, b)


# -- reading checks ---------------------------------------------------------------

def test_reading_checks_give_the_pure_path_verdicts(monkeypatch):
    from holonomic_core.driver import JointReading
    from holonomic_core.monitor import MonitorLimits, ReadingMonitor

    names = ("a", "b", "c")
    limits = MonitorLimits(3.0, 0.05, 0.3, 0.5)
    pure, compiled = both(monkeypatch, lambda: ReadingMonitor(
        names, np.array([10.0, 10.0, 2.0]), 0.005, limits))
    rng = np.random.default_rng(6)
    q = np.zeros(3)
    stream = []
    for k in range(3000):
        v = rng.uniform(-8, 8, 3)
        q = q + v * 0.005
        stamp = k * 0.005
        odd = k % 97
        # the odd ones: a velocity glitch over 3x the limit, a position jump,
        # NaN and inf readings, a frozen stamp, the clock going back
        if odd == 10:
            v = v.copy(); v[2] = 6.5
        elif odd == 20:
            q = q.copy(); q[1] += 0.5
        elif odd == 25:
            # backwards: a check without the absolute value passes this one
            q = q.copy(); q[0] -= 0.5
        elif odd == 35:
            v = v.copy(); v[1] = -6.5
        elif odd == 30:
            v = v.copy(); v[0] = math.nan
        elif odd == 40:
            q = q.copy(); q[2] = math.inf
        elif odd in (50, 51):
            stamp = (k - 1) * 0.005 if odd == 51 else stamp
        elif odd == 60:
            stamp -= 1.0
        stream.append((JointReading(stamp, q.copy(), v.copy(), np.full(3, math.nan)), stamp + 1e-4,
                       v + rng.uniform(-1, 1, 3) if k % 3 else None))
        if odd == 40:
            q[2] = 0.0
    verdicts = [(pure.check(*item), compiled.check(*item)) for item in stream]
    assert all(a == b for a, b in verdicts), next((a, b) for a, b in verdicts if a != b)
    # the stream did exercise every check
    found = " ".join(a for a, _ in verdicts if a)
    for words in ("over 3x its limit", "position jumped", "non-finite velocity",
                  "non-finite position"):
        assert words in found, words


# -- the whole cycle ----------------------------------------------------------------

def _controller(robot):
    from holonomic_core.controller import BaseController
    from holonomic_core.loop import ManualClock
    from holonomic_core.mock_driver import MockDriver

    cfg = robot_config(robot)
    clock = ManualClock()
    driver = MockDriver(cfg.model, cfg.values, cfg.controller.control_rate, clock=clock)
    driver.configure()
    ctrl = BaseController(cfg, driver, clock=clock)
    ctrl.request_enable(True)
    return ctrl, clock


@pytest.mark.parametrize("robot", GEOMETRIES)
def test_a_controller_on_either_path_commands_the_same_joints(monkeypatch, robot):
    (pure, pure_clock), (compiled, compiled_clock) = both(monkeypatch, lambda: _controller(robot))
    rng = np.random.default_rng(7)
    vmax = np.array(pure.config.controller.max_velocity)
    for k in range(1500):
        command = None
        if k % 50 == 0:
            # twice the speed limits (limited, saturated), a NaN (rejected:
            # stop), and from cycle 1200 on none (the command times out)
            command = rng.uniform(-2, 2, 3) * vmax if k % 350 else (math.nan, 0.0, 0.0)
        for ctrl, clock in ((pure, pure_clock), (compiled, compiled_clock)):
            if command is not None and k < 1200:
                ctrl.set_command(command)
            clock.now += ctrl.dt
            ctrl.step()
        assert same_bits(pure.joint_command, compiled.joint_command), k
        assert same_bits(pure.twist_command, compiled.twist_command), k
        assert same_bits(pure.odometry.pose, compiled.odometry.pose), k
        assert pure.saturation == compiled.saturation and pure.fault == compiled.fault, k
    assert pure.fault is None and pure.stale          # it ran, and timed out at the end
    assert np.abs(pure.odometry.pose[:2]).max() > 0.05
