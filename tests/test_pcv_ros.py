"""The simulated powered-caster vehicles end to end through ROS: the same
base controller node and topics as the HAMR, the kinematics chosen by the
robot config (holonomic-bringup xr4000 / comr3)."""

import signal
import time

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import JointState

from holonomic_core.model import load_model
from holonomic_testing.ros_probe import Bringup, Probe, drive_script, wait_until


@pytest.fixture(scope="module", params=["xr4000", "comr3"])
def pcv(request, ros, tmp_path_factory):
    """One simulated PCV per robot config, armed, in its own namespace."""
    robot = request.param
    proc = Bringup([robot, "--namespace", f"{robot}_test"],
                   tmp_path_factory.mktemp(robot) / "bringup.log")
    probe = Probe(ros, f"{robot}_test")
    probe.robot = robot
    try:
        probe.wait_ready()
        ok = probe.enable(True)
        assert ok.success, ok.message
        yield probe
    finally:
        probe.close()
        code = proc.stop(signal.SIGINT)
        assert code == 0, proc.log()


TWISTS = {
    "strafe": (0.0, 0.5, 0.0),
    "rotation": (0.0, 0.0, 1.2),
    "translate_while_rotating": (0.3, 0.2, 0.6),
    "backward_diagonal": (-0.35, -0.35, 0.0),
}


@pytest.mark.parametrize("name", list(TWISTS))
def test_base_follows_the_commanded_twist_after_the_casters_turned(pcv, name):
    cmd = np.array(TWISTS[name])
    pcv.wait_at_rest()
    pcv.drive(cmd, 2.0)           # the casters swing round, the base accelerates
    t0 = time.monotonic()
    pcv.drive(cmd, 1.0)
    achieved = np.mean([s.twist for s in pcv.truth_since(t0)], axis=0)
    v_cmd, w_cmd = np.linalg.norm(cmd[:2]), abs(cmd[2])
    assert np.linalg.norm(achieved[:2] - cmd[:2]) <= 0.05 * max(v_cmd, 0.1), achieved
    assert abs(achieved[2] - cmd[2]) <= 0.05 * max(w_cmd, 0.3), achieved


def test_odometry_tracks_ground_truth(pcv):
    script = [((0.6, 0.0, 0.0), 2.0), ((0.0, 0.5, 0.0), 2.0), ((0.3, 0.3, 0.8), 3.0),
              ((0.0, 0.0, -1.5), 1.5), ((-0.4, 0.2, 0.0), 2.5)]
    distance, error, heading = drive_script(pcv, script)
    assert distance > 4.0
    assert error <= 0.02 * distance, (error, distance)
    assert heading < 0.05



def test_joint_states_and_per_caster_slip_in_diagnostics(pcv, ros):
    model = load_model(pcv.robot)
    joints = []
    sub = ros.create_subscription(JointState, f"/{pcv.robot}_test/joint_states",
                                  joints.append, 10)
    try:
        pcv.drive((0.2, 0.1, 0.3), 0.5)
        wait_until(lambda: joints and pcv.diagnostics, 10.0, "joint_states and diagnostics")
        assert tuple(joints[-1].name) == model.joint_names
        odo = next(s for s in pcv.diagnostics.status if s.name.endswith("odometry"))
        keys = {kv.key: kv.value for kv in odo.values}
        for name in model.kinematics.caster_names:
            value = float(keys[f"slip_residual_{name}_m_s"])
            assert 0.0 <= value < 0.05
        assert keys["estimator"] == "slip_min"
        assert odo.level == DiagnosticStatus.OK      # no caster slipping
    finally:
        ros.destroy_subscription(sub)
