"""The tracker path's own parts against values put by hand or computed another way: the rows it makes of further
targets, the rows it refuses, the defaults of ``identify``, the pose a robust loss names among several targets, and
what the primary target alone identifies (the survivors of mutation testing on
``partcal/calibration/identification.py``)."""

import numpy as np
import pytest

from partcal import DataError, load_robot
from partcal.calibration.identification import Extra, extra_from, identify, point_rows
from partcal.calibration.joint_errors import JointErrors
from partcal.calibration.parameters import nominal_values, robot_with

TOOLS = {"B": np.array([100.0, 0.0, 90.0])}


@pytest.fixture(scope="module")
def ur10():
    return load_robot("universal_robots_ur10").replace(tool_mm=np.array([0.0, 0.0, 120.0]))


def test_point_rows_of_two_targets_are_numbered_by_pose_and_carry_their_payload(ur10):
    q = np.zeros((3, 6))
    measured = np.arange(9.0).reshape(3, 3)
    extra = Extra({"B": TOOLS["B"]}, {"B": measured + 100.0})
    rows, cell = point_rows(q, measured, extra, payload_kg=np.array([0.0, 5.0, 10.0]))
    assert rows.ids == ("1", "2", "3", "1@B", "2@B", "3@B") and rows.texts["target"] == ("",) * 3 + ("B",) * 3
    assert rows.payload_kg.tolist() == [0.0, 5.0, 10.0] * 2
    assert rows.numbers["x_meas"].tolist() == [0.0, 3.0, 6.0, 100.0, 103.0, 106.0]
    alone = point_rows(q, measured)[0]
    assert alone.payload_kg is None and alone.ids == ("1", "2", "3") and alone.texts == {}


@pytest.mark.parametrize("rows", [2, 4])
def test_measured_points_further_targets_and_orientations_of_another_length_than_the_poses_are_refused(ur10, rows):
    q = np.zeros((3, 6))
    with pytest.raises(DataError, match=rf"targets\['B'\] has {rows} rows but X has 3"):
        extra_from(ur10, q, {"B": (TOOLS["B"], np.zeros((rows, 3)))}, None)
    with pytest.raises(DataError, match=rf"orientation_deg has {rows} rows but X has 3"):
        extra_from(ur10, q, None, np.zeros((rows, 3)))
    with pytest.raises(DataError, match=rf"measured_mm has {rows} rows but q_deg has 3"):
        identify(ur10, q, np.zeros((rows, 3)))


def test_hundreds_of_poses_of_one_length_are_accepted(ur10):
    """Lengths compared as numbers: 300 poses (beyond the small ints CPython keeps one object of) pass."""
    q = np.random.default_rng(8).uniform(-170, 170, (300, 6))
    extra = extra_from(ur10, q, {"B": (TOOLS["B"], np.zeros((300, 3)))}, np.zeros((300, 3)))
    assert extra.measured_mm["B"].shape == (300, 3) and extra.rotations.shape == (300, 3, 3)
    assert identify(ur10, q, ur10.positions(q)).n_poses == 300


def _truth(ur10, seed=1):
    rng = np.random.default_rng(seed)
    values = nominal_values(ur10)
    values[:24] += rng.normal(0, 0.3, 24)
    return robot_with(ur10, values)


def test_identify_without_a_payload_reads_none_and_scales_a_robust_loss_at_three_deviations(ur10):
    """With a compliant joint and no payload given, nothing weighs on the tool: the compliance moves nothing and
    is unidentifiable. A robust loss's scale is three times the stated standard deviation unless told."""
    q = np.random.default_rng(3).uniform(-170, 170, (60, 6))
    measured = _truth(ur10).positions(q)
    table = identify(ur10, q, measured, errors=JointErrors.for_robot(ur10, [2]))
    assert table.status[table.names.index("compliance[2]")] == "unidentifiable"
    robust = identify(ur10, q, measured, std_mm=np.full((60, 3), 0.02), loss="huber")
    assert robust.robust["scale_mm"] == pytest.approx(3 * 0.02, rel=1e-12)


@pytest.mark.parametrize("primary, further", [(3.0, 1.0), (1.0, 3.0)])
def test_a_pose_with_two_far_targets_is_named_once_by_its_lower_weight(ur10, primary, further):
    """Pose 7's primary target and its target B pushed 3 and 1 mm off (or 1 and 3): both rows are down-weighted, and
    the pose is named once, with the weight (the lower) and residual of the farther."""
    q = np.random.default_rng(4).uniform(-170, 170, (40, 6))
    true = _truth(ur10)
    measured = true.positions(q)
    b = true.replace(tool_mm=true.tool_mm + TOOLS["B"] - ur10.tool_mm).positions(q)
    measured[7] += [primary, 0.0, 0.0]
    b[7] += [0.0, further, 0.0]
    rng = np.random.default_rng(5)
    measured += rng.normal(0, 0.01, measured.shape)
    b += rng.normal(0, 0.01, b.shape)
    extra = Extra({"B": TOOLS["B"]}, {"B": b})
    table = identify(ur10, q, measured, extra=extra, loss="cauchy", std_mm=np.full((40, 3), 0.01),
                     parametrization="complete")
    (named,) = [d for d in table.robust["downweighted"] if d["row"] == 7]
    assert named["residual_mm"] == pytest.approx(3.0, abs=0.05)
    weight = 1.0 / (1.0 + (named["residual_mm"] / table.robust["scale_mm"]) ** 2)
    assert named["weight"] == pytest.approx(weight, rel=0.05) and named["weight"] < 1.0 / (1.0 + (1.0 / 0.03) ** 2)
    assert table.rms_mm == table.target_rms_mm["A"] != table.target_rms_mm["B"]     # the table's RMS is the primary's


def test_what_the_primary_target_alone_identifies_is_a_fit_on_it_alone(ur10):
    """With or without joint errors, the tool or the base held: the count the table gives for the primary target is
    what identify identifies on the primary target's rows alone, with the same settings. (With the tool point on the
    flange, holding the tool identifies one parameter less: nothing else moves the point along the flange's y.)"""
    q = np.random.default_rng(6).uniform(-170, 170, (50, 6))
    payload = np.random.default_rng(7).uniform(0, 20, 50)
    flange = ur10.replace(tool_mm=np.zeros(3))
    compliant = JointErrors.for_robot(ur10, [2, 3], [1, 1, 1, 0, 0, 0])
    cases = ((ur10, compliant, False, True), (ur10, compliant, True, False), (ur10, None, False, True),
             (ur10, None, True, False), (flange, None, False, True))
    for robot, errors, tool, base in cases:
        true = _truth(robot)
        b = true.replace(tool_mm=true.tool_mm + TOOLS["B"]).positions(q)         # B beyond the tool point
        both = identify(robot, q, true.positions(q), extra=Extra({"B": robot.tool_mm + TOOLS["B"]}, {"B": b}),
                        errors=errors, tool=tool, base=base, payload_kg=payload)
        alone = identify(robot, q, true.positions(q), errors=errors, tool=tool, base=base, payload_kg=payload)
        assert both.primary_identifiable == alone.status.count("identified") < both.status.count("identified")
    measured = _truth(flange).positions(q)
    counts = [identify(flange, q, measured, tool=t).status.count("identified") for t in (True, False)]
    assert counts[0] == counts[1] + 1
