"""Joint position ranges: the keys, the guard's stopping arithmetic, the URDF,
and the unwind planner's geometry (ROS-free, no simulator)."""

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from holonomic_core.config import load_config, load_model
from holonomic_core.description import generate_urdf
from holonomic_core.joint_range import JointRangeGuard
from holonomic_core.unwind import (follower_joints, loop_segments, loop_turn, plan_unwind,
                                   wrap_angle)

TURRET_RANGE = {"joints.turret_joint.min_position": -1.0,
                "joints.turret_joint.max_position": 1.0}
CASTERS = ("front_left", "rear_left", "rear_right", "front_right")


def xr4000_ranged(turns=1.5):
    over = {}
    for c in CASTERS:
        over[f"joints.{c}_steer_joint.min_position"] = -turns * 2 * math.pi
        over[f"joints.{c}_steer_joint.max_position"] = turns * 2 * math.pi
    return load_model("xr4000", over)


def guard(**kw):
    # one continuous joint (NaN), one ranged to [-1, 1]
    return JointRangeGuard(("wheel", "turret"), [math.nan, -1.0], [math.nan, 1.0],
                           (2.0, 2.0, 10.0), 0.01, **kw)


def test_joints_are_continuous_unless_a_range_is_set():
    model = load_model("hamr")
    assert not any(lim.ranged for lim in model.joint_limits)
    assert JointRangeGuard.from_model(model, (1, 1, 1), 0.01) is None
    ranged = load_model("hamr", TURRET_RANGE)
    turret = ranged.joint_limits[ranged.joint_names.index("turret_joint")]
    assert (turret.min_position, turret.max_position) == (-1.0, 1.0) and turret.ranged


def test_guard_slows_a_joint_to_stop_at_its_range_end():
    g = guard()
    # turret at 0.9 rad, 2 rad/s towards +1, twist (0, 0, 2): the limiter stops
    # the base in T = 2 / 10 = 0.2 s, the joint travels 2 x 0.2 / 2 = 0.2 rad
    # then: K = 0.2 s^2 x s^2, plus 2 x 0.01 s per unit scale over the horizon;
    # 0.02 s + 0.2 s^2 = 0.1 -> s = (-0.02 + sqrt(0.0004 + 0.08)) / 0.4 = 0.6589
    s = g.scale(np.array([0.0, 0.9]), np.array([5.0, 2.0]), np.array([0.0, 0.0, 2.0]), 3.0)
    assert s == pytest.approx((-0.02 + math.sqrt(0.0004 + 0.08)) / 0.4)
    assert 0.02 * s + 0.2 * s * s == pytest.approx(0.1)
    assert g.limited(3.5, 2.0) == ("turret",) and g.limited(5.5, 2.0) == ()


def test_guard_accepts_motions_that_turn_the_joint_back():
    g = guard()
    twist = np.array([0.0, 0.0, -2.0])
    # at the end, or past it after an overshoot, moving back in: never slowed
    for q in (0.9, 1.0, 1.05):
        assert g.scale(np.array([0.0, q]), np.array([0.0, -2.0]), twist, 0.0) == 1.0
    # far from both ends: not slowed either
    assert g.scale(np.array([0.0, 0.0]), np.array([0.0, 0.5]), -twist / 4, 0.0) == 1.0
    assert g.limited(0.0, 2.0) == ()


def test_guard_stops_a_joint_at_or_past_its_end_moving_further():
    g = guard()
    for q in (1.0, 1.02, -1.0):
        rate = 1.0 if q > 0 else -1.0
        assert g.scale(np.array([0.0, q]), np.array([0.0, rate]),
                       np.array([0.0, 0.0, rate]), 0.0) == 0.0


def test_guard_uses_a_joints_own_deceleration_limit_when_tighter():
    # a = 5 rad/s^2: 2^2 / (2 x 5) = 0.4 rad to stop, more than the limiter's 0.2
    # at 0.7 rad (0.3 left), 2 rad/s: the limiter's 0.02 + 0.2 = 0.22 rad fits ...
    at, rate, twist = np.array([0.0, 0.7]), np.array([0.0, 2.0]), np.array([0.0, 0.0, 2.0])
    assert guard().scale(at, rate, twist, 0.0) == 1.0
    # ... the joint's own 0.02 s + 0.4 s^2 = 0.3 -> s = (-0.02 + sqrt(0.0004 + 0.48)) / 0.8
    g = guard(joint_deceleration=[math.inf, 5.0])
    assert g.scale(at, rate, twist, 0.0) == pytest.approx((-0.02 + math.sqrt(0.0004 + 0.48)) / 0.8)


def test_urdf_carries_the_range_as_a_revolute_joint():
    for model, joint in ((load_model("hamr", TURRET_RANGE), "turret_joint"),
                         (xr4000_ranged(), "rear_left_steer_joint")):
        joints = {j.get("name"): j for j in ET.fromstring(generate_urdf(model)).iter("joint")}
        limits = model.joint_limits[model.joint_names.index(joint)]
        assert joints[joint].get("type") == "revolute"
        limit = joints[joint].find("limit")
        assert float(limit.get("lower")) == pytest.approx(limits.min_position)
        assert float(limit.get("upper")) == pytest.approx(limits.max_position)
        wheels = [j for name, j in joints.items() if name.endswith("wheel_joint")]
        assert wheels and all(j.get("type") == "continuous" for j in wheels)
    plain = {j.get("name"): j for j in ET.fromstring(generate_urdf(load_model("hamr"))).iter("joint")}
    assert plain["turret_joint"].get("type") == "continuous"


def test_follower_joints_are_derived_from_the_kinematics():
    # a caster's steering tends to the direction of travel (sigma +1, offset 0,
    # decay length b = 0.02 m); the DDROT turret to minus it (sigma -1, b = 0.1641 m)
    casters, others = follower_joints(xr4000_ranged(), np.zeros(8))
    assert others == [] and [j.sigma for j in casters] == [1, 1, 1, 1]
    assert [j.length for j in casters] == pytest.approx([0.02] * 4, rel=1e-4)
    assert [j.offset for j in casters] == pytest.approx([0.0] * 4, abs=1e-6)
    turret, _ = follower_joints(load_model("hamr", TURRET_RANGE), np.array([0.0, 0.0, 0.3]))
    assert [(j.name, j.sigma) for j in turret] == [("turret_joint", -1)]
    assert turret[0].length == pytest.approx(0.1641, rel=1e-4)
    assert turret[0].direction(0.3) == pytest.approx(-0.3)


@pytest.mark.parametrize("sense", [1, -1])
@pytest.mark.parametrize("start,end", [(0.0, 0.0), (0.5, 2.5), (3.0, -2.0), (-1.0, 1.2)])
def test_each_loop_is_closed_smooth_and_turns_as_planned(sense, start, end):
    fillet, radius = 0.05, 0.2
    delta = math.asin(fillet / (radius - fillet))
    segs = loop_segments((1.0, -2.0), start, end, sense, 1, fillet, radius)
    assert segs[0].point(0.0) == pytest.approx((1.0, -2.0))
    assert segs[-1].point(segs[-1].length) == pytest.approx((1.0, -2.0))
    turned = 0.0
    for a, b in zip(segs, segs[1:]):
        # continuous in position and in direction
        assert a.point(a.length) == pytest.approx(b.point(0.0), abs=1e-9)
        assert wrap_angle(a.tangent(a.length) - b.tangent(0.0)) == pytest.approx(0.0, abs=1e-9)
    for seg in segs:
        turned += seg.tangent(seg.length) - seg.tangent(0.0)
        # never farther from the start than the big circle
        for s in np.linspace(0.0, seg.length, 20):
            assert math.dist(seg.point(s), (1.0, -2.0)) <= radius + 1e-9
    assert turned == pytest.approx(loop_turn(sense, start, end, delta) + sense * 2 * math.pi)
    assert wrap_angle(segs[0].tangent(0.0) - start) == pytest.approx(0.0, abs=1e-12)
    assert wrap_angle(segs[-1].tangent(0.0) - end) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("wound", [9.42, -9.42, 4.0, 0.5, -0.3])
def test_plan_brings_every_caster_to_the_middle(wound):
    model = xr4000_ranged()
    q = np.zeros(8)
    q[0::2] = wound
    plan = plan_unwind(model, q, (0.3, -0.2, 0.7))
    assert plan.expected == pytest.approx([0.0] * 4, abs=1e-9)
    assert plan.footprint == pytest.approx(0.2)     # 4 x max(1.5 x 0.02 m, 0.05 m)
    segs = plan.segments
    assert segs[0].point(0.0) == pytest.approx((0.3, -0.2))
    assert segs[-1].point(segs[-1].length) == pytest.approx((0.3, -0.2))


def test_nothing_to_unwind_near_the_middle_and_a_clear_refusal_without_ranges():
    assert plan_unwind(xr4000_ranged(), np.full(8, 0.01), (0, 0, 0)) is None
    with pytest.raises(ValueError, match="every joint is continuous"):
        plan_unwind(load_model("xr4000"), np.zeros(8), (0, 0, 0))


def test_casters_wound_by_different_turns_are_refused():
    q = np.zeros(8)
    q[0], q[2] = 2 * math.pi, -2 * math.pi
    # one translation turns every caster alike: -2 pi for the first is -4 pi,
    # past its range, for the second
    with pytest.raises(ValueError, match="past its range"):
        plan_unwind(xr4000_ranged(), q, (0, 0, 0))


def test_a_half_turn_range_wound_to_its_end_is_refused_with_the_reason():
    # at the end of a +-pi range the joint needs a turn of pi, less than one
    # loop turns (pi + 2 delta), and a figure of eight would pass its end
    q = np.zeros(8)
    q[0::2] = math.pi
    with pytest.raises(ValueError, match="past its range"):
        plan_unwind(xr4000_ranged(0.5), q, (0, 0, 0))


def test_config_from_a_params_file_with_a_turret_range(tmp_path):
    text = load_config("hamr").source
    yaml = open(text).read().replace("# min_position: -6.2832", "min_position: -6.2832") \
        .replace("# max_position: 6.2832", "max_position: 6.2832")
    path = tmp_path / "hamr_ranged.yaml"
    path.write_text(yaml)
    cfg = load_config(path)
    turret = cfg.model.joint_limits[cfg.model.joint_names.index("turret_joint")]
    assert (turret.min_position, turret.max_position) == (-6.2832, 6.2832)
    assert cfg.values["joints.turret_joint.min_position"] == -6.2832
    assert cfg.values["joints.left_wheel_joint.min_position"] is None
