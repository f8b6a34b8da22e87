"""Joint errors against values put by hand: the joints and harmonics a config may name, which frames may carry a
lumped mass, the parameters of a robot without any, and a compliant last joint whose only lever is the payload's
(the survivors of mutation testing on ``partcal/calibration/joint_errors.py`` and ``chain.py``)."""

import numpy as np
import pytest

from partcal import load_robot
from partcal.calibration.chain import model_positions
from partcal.calibration.joint_errors import (GRAVITY_M_S2, MAX_HARMONICS, JointErrors, compliance_problem,
                                              harmonics_problem)
from partcal.calibration.parameters import nominal_values, parameter_names


@pytest.fixture(scope="module")
def sk120():
    return load_robot("motoman_sk120")


@pytest.mark.parametrize("value, ok", [([1, 6], True), ([0], False), ([7], False), ([2, 2], False), ([True], False),
                                       ([2.0], False), (3, False)])
def test_compliant_joints_are_distinct_joint_numbers_from_one(value, ok):
    assert compliance_problem(value, 6) == (None if ok else "a list of distinct joint numbers in [1, 6]")


@pytest.mark.parametrize("value, ok", [(0, True), (MAX_HARMONICS, True), (MAX_HARMONICS + 1, False), (-1, False),
                                       ([0, 8, 1, 0, 0, 2], True), ([0, 9, 1, 0, 0, 2], False), ([1] * 5, False),
                                       ([1] * 7, False),
                                       (True, False), (1.0, False)])
def test_harmonics_are_ints_up_to_eight_for_every_joint_or_each(value, ok):
    assert MAX_HARMONICS == 8
    assert harmonics_problem(value, 6) == (None if ok else "an int in [0, 8] or a list of 6 such ints")


def test_without_joint_errors_asked_for_a_robot_has_none(sk120):
    errors = JointErrors.for_robot(sk120)
    assert errors.harmonics == (0,) * 6 and errors.empty and errors.size == 0 and errors.names() == []


@pytest.mark.parametrize("origin, moves", [([0, 0, 0, 1.0, 2.0, 3.0], False), ([0, 0, 5.0, 0, 0, 0], True),
                                           ([0, -2.0, 0, 0, 0, 0], True)])
def test_a_further_origin_moves_a_frame_only_by_its_shift(sk120, origin, moves):
    """SK120's row 7 (q5) has a = d = 0: its frame 7 repeats frame 6 unless the row's further origin shifts it
    (a turn alone leaves it in place). Every other row of the arm has a or d; the other origins are zero."""
    origins = np.zeros((8, 6))
    origins[6] = origin
    errors = JointErrors.for_robot(sk120.replace(origins=origins), [3])
    assert errors.frames == ((2, 3, 4, 5, 6, 7, 8) if moves else (2, 3, 4, 5, 6, 8),)


def test_a_row_moves_its_frame_by_an_offset_of_either_sign(sk120):
    """Row 6 (q4) has a = 0 and d = 1300 mm: d = -1300 mm moves frame 6 as far; a = d = 0 would not move it. Row 5
    has d = 0 and a = 250 mm: a = -250 mm moves frame 5."""
    for d, frames in ((-1300.0, (2, 3, 4, 5, 6, 8)), (0.0, (2, 3, 4, 5, 8))):
        robot = sk120.replace(d_mm=np.where(np.arange(8) == 5, d, sk120.d_mm))
        assert JointErrors.for_robot(robot, [3]).frames == (frames,)
    robot = sk120.replace(a_mm=np.where(np.arange(8) == 4, -250.0, sk120.a_mm))
    assert JointErrors.for_robot(robot, [3]).frames == ((2, 3, 4, 5, 6, 8),)


def test_a_compliant_last_joint_with_no_frame_beyond_it_bends_by_the_payload_alone(sk120):
    """Without the flange's d, no frame after joint 6's row moves: its one parameter is the compliance, and a
    payload at the tool point turns joint 6 by compliance x g x payload x the tool's lever about the joint's
    axis, ``(z_y r_x - z_x r_y) / 1000`` m (the lever of the module's doc), computed here from the forward
    kinematics."""
    robot = sk120.replace(d_mm=np.where(np.arange(8) == 7, 0.0, sk120.d_mm), tool_mm=np.array([205.32, 40.0, 112.65]))
    errors = JointErrors.for_robot(robot, [6])
    assert errors.frames == ((),) and [n for n, _ in parameter_names(robot, errors)][-1:] == ["compliance[6]"]
    assert errors.size == 1
    q = np.random.default_rng(3).uniform(-90, 90, (5, 6))
    payload = np.array([0.0, 10.0, 50.0, 120.0, 80.0])
    values = nominal_values(robot, errors)
    values[-1] = 1e-3                                          # deg/(N m)
    frames = robot.forward(q)
    axis = frames[:, :3, 2]                                    # the flange's z is joint 6's (its row's alpha is 0)
    arm = frames[:, :3, :3] @ robot.tool_mm                    # tool point minus the joint's origin
    lever = (axis[:, 1] * arm[:, 0] - axis[:, 0] * arm[:, 1]) / 1000.0
    bent = q.copy()
    bent[:, 5] += 1e-3 * GRAVITY_M_S2 * payload * lever
    expected = robot.positions(bent)
    assert np.abs(bent - q).max() > 0.05                      # the payload turns the joint measurably
    np.testing.assert_allclose(model_positions(robot, errors, q, values, payload), expected, atol=1e-9)
