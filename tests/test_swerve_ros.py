"""The simulated swerve base end to end through ROS (holonomic-bringup
swerve4): the same node and topics as the other families, the modules
turning before they drive, flipping instead of turning round, holding
their headings at rest, and the odometry against ground truth."""

import math
import signal
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import JointState

from holonomic_core.model import load_model
from holonomic_testing.ros_probe import Bringup, Probe, drive_script, wait_until

ROBOT = "swerve4"


@pytest.fixture(scope="module")
def swerve(ros, tmp_path_factory):
    """The simulated swerve4, armed, in its own namespace."""
    proc = Bringup([ROBOT, "--namespace", "swerve_test"],
                   tmp_path_factory.mktemp(ROBOT) / "bringup.log")
    probe = Probe(ros, "swerve_test")
    try:
        probe.wait_ready()
        ok = probe.enable(True)
        assert ok.success, ok.message
        yield probe
    finally:
        probe.close()
        code = proc.stop(signal.SIGINT)
        assert code == 0, proc.log()


@pytest.fixture()
def joints(swerve, ros):
    """Every joint_states message from now on."""
    received = []
    sub = ros.create_subscription(JointState, "/swerve_test/joint_states", received.append, 50)
    yield received
    ros.destroy_subscription(sub)


def _steer(msg: JointState) -> np.ndarray:
    return np.array(msg.position)[0::2]


TWISTS = {
    "strafe": (0.0, 0.5, 0.0),
    "rotation": (0.0, 0.0, 1.2),
    "translate_while_rotating": (0.3, 0.2, 0.6),
    "backward_diagonal": (-0.35, -0.35, 0.0),
}


@pytest.mark.parametrize("name", list(TWISTS))
def test_base_follows_the_commanded_twist_after_the_modules_turned(swerve, name):
    cmd = np.array(TWISTS[name])
    swerve.wait_at_rest()
    swerve.drive(cmd, 2.0)           # the modules turn, the base accelerates
    t0 = time.monotonic()
    swerve.drive(cmd, 1.0)
    achieved = np.mean([s.twist for s in swerve.truth_since(t0)], axis=0)
    v_cmd, w_cmd = np.linalg.norm(cmd[:2]), abs(cmd[2])
    assert np.linalg.norm(achieved[:2] - cmd[:2]) <= 0.05 * max(v_cmd, 0.1), achieved
    assert abs(achieved[2] - cmd[2]) <= 0.05 * max(w_cmd, 0.3), achieved


def test_a_reversal_flips_the_wheels_and_keeps_the_modules_headings(swerve, joints):
    # forward, then backward: each module's heading stays (within the
    # transients' few degrees), the wheels turn the other way
    swerve.wait_at_rest()
    swerve.drive((0.5, 0.0, 0.0), 2.0)
    before = joints[-1]
    swerve.drive((-0.5, 0.0, 0.0), 2.0)
    after = joints[-1]
    assert np.abs(_steer(after) - _steer(before)) == pytest.approx([0.0] * 4,
                                                                 abs=math.radians(3))
    # a module at 0 rad rolls forward first, one at pi backwards; both at
    # 0.5 / 0.075 = 6.67 rad/s, and the reversal swaps the sign
    wheels_before = np.array(before.velocity)[1::2]
    wheels_after = np.array(after.velocity)[1::2]
    assert np.abs(wheels_before) == pytest.approx([0.5 / 0.075] * 4, rel=0.05)
    assert wheels_after == pytest.approx(-wheels_before, rel=0.05)


def test_at_a_zero_command_the_modules_hold_their_headings(swerve, joints):
    # strafe turns the modules to +-90 deg; at rest they stay there
    swerve.drive((0.0, 0.4, 0.0), 2.0)
    swerve.wait_at_rest()
    held = _steer(joints[-1])
    assert np.abs(np.abs(held) % math.pi - math.pi / 2) == pytest.approx([0.0] * 4, abs=0.05)
    count = len(joints)
    time.sleep(1.0)
    assert len(joints) > count + 10
    assert np.abs(_steer(joints[-1]) - held) == pytest.approx([0.0] * 4, abs=1e-3)


def test_odometry_tracks_ground_truth_on_a_teleop_like_drive(swerve):
    # forward, strafe, translate while turning, spin, back diagonally: every
    # change of direction reorients the modules; the wheels wait for them
    # (swerve.drive_alignment), so little slips while they turn (with the
    # wheels driving on at the cosine of the error alone the heading drifts
    # about 2.4 deg on this script)
    script = [((0.6, 0.0, 0.0), 2.0), ((0.0, 0.5, 0.0), 2.0), ((0.3, 0.3, 0.8), 3.0),
              ((0.0, 0.0, -1.5), 1.5), ((-0.4, 0.2, 0.0), 2.5)]
    distance, error, heading = drive_script(swerve, script)
    print(f"teleop-like drive: {distance:.2f} m, odometry error {1000 * error:.1f} mm, "
          f"heading {math.degrees(heading):.2f} deg")
    assert distance > 3.5                 # the script drove (less while the modules turn)
    assert error <= 0.01 * distance, (error, distance)
    assert heading < math.radians(2.0), math.degrees(heading)


def test_joint_states_and_per_module_slip_in_diagnostics(swerve, joints):
    model = load_model(ROBOT)
    swerve.drive((0.2, 0.1, 0.3), 1.5)
    wait_until(lambda: joints and swerve.diagnostics, 10.0, "joint_states and diagnostics")
    assert tuple(joints[-1].name) == model.joint_names
    odo = next(s for s in swerve.diagnostics.status if s.name.endswith("odometry"))
    keys = {kv.key: kv.value for kv in odo.values}
    for name in model.kinematics.module_names:
        value = float(keys[f"slip_residual_{name}_m_s"])
        assert 0.0 <= value < 0.05
    assert keys["estimator"] == "slip_min"
    assert odo.level == DiagnosticStatus.OK
