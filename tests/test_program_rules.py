"""Rules of compensated programs that a vendor's manual or the robot's file states: which ConfJ/ConfL setting
governs which RAPID move, and that a target whose joints break the robot's limits is never taken as reachable."""

import warnings

import numpy as np
import pytest

from partcal import ErrorModel, load_robot
from partcal.data.programs import read_program
from partcal.robot.rotations import rotation_vectors_from_matrices
from partcal.study.persist import model_to_dict
from partcal.study.predictor import Predictor
from partcal.study.programs import compensate_program

SK120 = load_robot("motoman_sk120")

MODULE = """MODULE Rules
  CONST robtarget pJ:=[[1201.645,85.084,1050.031],[0.212583,-0.556195,0.152896,-0.788719],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget pL:=[[1057.669,-344.24,898.42],[-0.388956,-0.519826,-0.170439,-0.741245],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    ConfJ \\{j};
    ConfL \\{l};
    TriggJ pJ, v1000, trigg1, z50, tool0;
    TriggL pL, v1000, trigg1, z50, tool0;
  ENDPROC
ENDMODULE
"""


@pytest.mark.parametrize("joint, linear", [("Off", "On"), ("On", "Off")])
def test_rapid_triggj_follows_confj_and_triggl_confl(tmp_path, joint, linear):
    """The RAPID reference: ConfJ governs MoveJ and TriggJ, ConfL the linear and circular moves (TriggL among them);
    a move whose monitoring is off has its target's configuration dropped (the controller does not check it)."""
    path = tmp_path / "rules.mod"
    path.write_text(MODULE.format(j=joint, l=linear))
    targets = {t.name: t.configuration for t in read_program(path).targets}
    assert targets["pJ"] == (None if joint == "Off" else (0, 0, 0, 0))
    assert targets["pL"] == (None if linear == "Off" else (-1, -1, -1, 0))


def _flange_script(robot, q_deg, path):
    """A URScript program moving linearly to the flange pose (metres, rotation vector) the robot has at ``q_deg``."""
    tool = np.eye(4)
    tool[:3, 3] = robot.tool_mm
    pose = robot.forward(np.asarray(q_deg, dtype=float)[None])[0] @ np.linalg.inv(tool)
    numbers = [*(pose[:3, 3] / 1000.0), *rotation_vectors_from_matrices(pose[None, :3, :3])[0]]
    path.write_text("def prog():\n  movel(p[" + ", ".join(f"{v:.9f}" for v in numbers) + "], a=1.2, v=0.25)\nend\n")
    return path


def _zero_predictor(robot):
    rng = np.random.default_rng(0)
    X = rng.uniform(-1000, 1000, (40, 3))
    model = ErrorModel(inputs="cartesian", degree=1, solver="lstsq").fit(X, np.zeros((40, 3)))
    return Predictor(model, model_to_dict(model, name="zero", robot=robot), robot)


@pytest.mark.parametrize("q2_minus_q3, reachable", [(125.0, False), (115.0, True)])
def test_a_target_whose_joints_break_the_parallelograms_constraint_is_unreachable(tmp_path, q2_minus_q3, reachable):
    """The SK120's file keeps q2 - q3 within 10 to 120 degrees (the parallelogram), a constraint that no single
    joint's range states. A pose the arm reaches only at q2 - q3 = 125 degrees (each joint within its own range) is
    reported unreachable and nothing is written, even though the pose solve reaches it exactly; at 115 degrees it
    is compensated."""
    q = np.array([20.0, -100.0, -100.0 - q2_minus_q3, 10.0, 40.0, 30.0])
    low, high = SK120.limits_deg[:, 0], SK120.limits_deg[:, 1]
    assert np.all((q >= low) & (q <= high))
    path = _flange_script(SK120, q, tmp_path / "target.script")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = compensate_program(_zero_predictor(SK120), read_program(path))
    if reachable:
        assert result.failures == [] and result.output == path.read_bytes()
    else:
        assert [why for _, why in result.failures] == [
            "is outside the joint limits: it breaks a coupled constraint between the joints (the arm reaches the pose "
            "only there)"]
        assert result.output is None
