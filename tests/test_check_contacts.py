"""``partcal check`` and ``partcal update`` with the rows of trackerless instruments (plane touches, ballbar
distances, fixed-point visits; partcal/study/check.py, partcal/study/update.py), on a model identified from touches of
a virtual UR10 (``partcal simulate`` then ``partcal run``): new rows of the same virtual robot hold, rows of the robot
with joint 2's zero moved by 0.05 degree say moved and name joint 2 with the truth's change, an update from the moved
robot's rows follows it (scored independently: the model's positions on 300 poses against the moved robot's true
ones after a rigid fit), and visits to a point the model does not know are refused naming it."""

import dataclasses
import json
import os

import numpy as np
import pytest
from conftest import small_contact_cell

from partcal.cli import main
from partcal.data.contact_sets import _dataset
from partcal.data.measurement_rows import write_measurement_rows
from partcal.data.simulate import load_study, simulate, write_study
from partcal.errors import DataError
from partcal.robot.frames import kabsch
from partcal.study.check import check_file
from partcal.study.predictor import load_predictor
from partcal.study.update import update_file

RUN = """name: r
robot: universal_robots_ur10
data:
  identification: data/touches.csv
  cell: data/cell.yaml
models:
  - name: complete
    kind: kinematic
    parametrization: complete
output: out
"""
PLANES = {"type": "plane", "counts": {"top": 30, "step": 30, "side": 20}, "noise": 0.01, "flush": False}
BALLBAR = {"type": "distance", "poses": 20, "pairs": "all", "noise": 0.01}


@pytest.fixture(scope="module")
def touched(tmp_path_factory):
    """A model of 280 touches of the virtual contact cell (its top, step and side planes; 0.01 mm)."""
    folder = tmp_path_factory.mktemp("check_contacts")
    small_contact_cell(folder, touches=100, side=80, visits=20, poses=10)
    study = load_study(folder / "virtual.yaml")
    write_study(study, simulate(study))
    (folder / "r.yaml").write_text(RUN)
    cwd = os.getcwd()
    try:
        os.chdir(folder)
        assert main(["run", "-q", "r.yaml"]) == 0
    finally:
        os.chdir(cwd)
    return folder / "out" / "models" / "complete.json", study


def _moved(study, joint_moved_deg: float):
    vr = study.robot
    if not joint_moved_deg:
        return vr
    offset = vr.true.theta_offset_deg.copy()
    offset[1] += joint_moved_deg
    return dataclasses.replace(vr, true=vr.true.replace(theta_offset_deg=offset))


def _rows(study, path, spec, seed, joint_moved_deg=0.0):
    """Rows of ``spec``'s type of the virtual robot (joint 2's zero moved by ``joint_moved_deg``), written to ``path``."""
    rows = _dataset(_moved(study, joint_moved_deg), study, path.stem, spec, np.random.default_rng(seed))
    write_measurement_rows(rows, path)
    return path


def _rigid_mm(study, model_file, joint_moved_deg) -> float:
    """The model's tool positions on 300 poses against the true ones of the robot (joint 2 moved by
    ``joint_moved_deg``) after a rigid fit (touches fix no frame), RMS mm."""
    q = study.robot.nominal.home_deg + np.random.default_rng(0).uniform(-60, 60, (300, 6))
    truth = _moved(study, joint_moved_deg).true_positions(q)
    fitted = study.robot.nominal.positions(q) + load_predictor(model_file).predict(joints=q)
    rotation, shift = kabsch(fitted, truth)
    return float(np.sqrt(np.mean(np.sum((fitted @ rotation.T + shift - truth) ** 2, axis=1))))


@pytest.mark.parametrize("spec", [PLANES, BALLBAR], ids=["touches", "distances"])
def test_check_contact_rows_holds_for_the_same_robot_and_names_a_moved_joint(touched, tmp_path, spec):
    model, study = touched
    same = check_file(model, _rows(study, tmp_path / "same.csv", spec, 7))
    assert same.holds and 0.7 < same.mean_z2 < 1.4, same.lines()
    moved = check_file(model, _rows(study, tmp_path / "moved.csv", spec, 7, joint_moved_deg=0.05))
    assert not moved.holds and moved.mean_z2 > 100
    first = moved.explanations[0]
    assert first.name == "joint 2's offset"
    assert first.change[0] == pytest.approx(0.05, abs=0.005)           # the truth: +0.05 degree
    said = "\n".join(moved.lines())
    assert said.startswith("moved:") and "moved.csv:" in said


@pytest.mark.parametrize("spec", [PLANES, BALLBAR], ids=["touches", "distances"])
def test_update_from_contact_rows_follows_a_moved_joint(touched, tmp_path, spec):
    """Before: 0.02 mm from the robot it was fitted to, 0.52 mm from the moved one; after an update from 80 touches
    (or the distances of 20 poses) of the moved robot: 0.012 (0.003) mm from it."""
    model, study = touched
    assert _rigid_mm(study, model, 0.0) < 0.05 and _rigid_mm(study, model, 0.05) > 0.3
    done = update_file(model, _rows(study, tmp_path / "new.csv", spec, 9, joint_moved_deg=0.05),
                       tmp_path / "updated.json")
    assert _rigid_mm(study, tmp_path / "updated.json", 0.05) < 0.05
    kind = spec["type"]
    assert 0.005 < done.rms_after[kind] < 0.02                          # the rows' 0.01 mm noise
    assert json.loads((tmp_path / "updated.json").read_text())["fit"]["update"]["rows"] > 0


def test_visits_to_a_point_the_model_does_not_know_are_refused_naming_it(touched, tmp_path):
    model, study = touched
    visits = {"type": "fixed", "counts": {"nest_a": 10, "sphere": 10}, "noise": 0.01}
    with pytest.raises(DataError, match=r"'point nest_a.x' is not in the model .*which identified plane side, plane "
                                        r"top: check reads rows of what the model identified") as refused:
        check_file(model, _rows(study, tmp_path / "visits.csv", visits, 3))
    assert "\n" not in str(refused.value)
