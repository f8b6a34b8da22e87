"""``partcal run`` on measurement types (partcal/study/measurement_run.py): a virtual UR10 touching a step block,
visiting fixed points and measured by a ballbar, identified without a tracker and scored against tracker
points of the same virtual robot; refusals; a type added by a test module runs through the command."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import small_contact_cell

from partcal.cli import main
from partcal.data.measurements import read_measurements
from partcal.data.simulate import load_study, simulate, write_study
from partcal.calibration.measurement import MeasurementType, Residuals
from partcal.calibration.registry import add_measurement_type, MEASUREMENT_TYPES
from partcal.robot.frames import kabsch
from partcal.study.config import load_config
from partcal.study.persist import load_model

@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """The shipped virtual cell, smaller: its data sets written into a folder of their own."""
    folder = tmp_path_factory.mktemp("cell")
    small_contact_cell(folder, touches=100, side=80, visits=50, poses=30)
    study = load_study(folder / "virtual.yaml")
    write_study(study, simulate(study))
    return folder, study


def _config(folder: Path, identification: str, cell: str | None = "cell.yaml", models: str = "", name="r"):
    text = f"""name: {name}
robot: universal_robots_ur10
data:
  identification: data/{identification}
{f'  cell: data/{cell}' if cell else ''}
  tests:
    test: data/test.csv
models:
  - name: complete
    kind: kinematic
    parametrization: complete
{models}output: out_{name}
"""
    path = folder / f"{name}.yaml"
    path.write_text(text)
    return path


def test_a_run_on_touches_identifies_the_robot_and_scores_tracker_points_after_a_rigid_fit(cell, capsys):
    folder, study = cell
    path = _config(folder, "touches.csv", name="touches")
    assert main(["run", "-q", str(path)]) == 0
    printed = capsys.readouterr().out
    assert "rigid" in printed
    metrics = json.loads((folder / "out_touches" / "metrics.json").read_text())
    assert metrics["seed"] == 0 and metrics["cv"]["folds"] == 5          # the config's seed, cv_folds: auto
    entry = metrics["models"]["complete"]
    assert 0.005 < entry["cv_rms_by_type"]["plane"] < 0.02          # the touches' 0.01 mm noise, held out
    # the score printed is the model's, after a rigid fit, against the test set: computed here independently
    model, _ = load_model(folder / "out_touches" / "models" / "complete.json")
    test = read_measurements(folder / "data" / "test.csv")
    predicted = test.nominal_mm + model.predict(test.q_deg)
    rot, t = kabsch(predicted, test.measured_mm)
    expected = np.sqrt(np.mean(np.sum((predicted @ rot.T + t - test.measured_mm) ** 2, axis=1)))
    assert entry["tests"]["test"]["rms_3d"] == pytest.approx(expected, rel=1e-9)
    rot0, t0 = kabsch(test.nominal_mm, test.measured_mm)
    before = np.sqrt(np.mean(np.sum((test.nominal_mm @ rot0.T + t0 - test.measured_mm) ** 2, axis=1)))
    assert expected < 0.1 < before                                   # calibrated from touches alone
    assert f"\nuncompensated {' ' * 2}" in printed and f"{before:.4f} (rigid)" in printed
    html = (folder / "out_touches" / "index.html").read_text()
    assert "What these data cannot identify" in html and "plane top" in html


def test_check_names_the_scale_when_every_plane_is_unknown(cell, capsys):
    folder, _ = cell
    (folder / "data" / "loose.yaml").write_text("planes: {top: {}, step: {}, side: {}}\n")
    path = _config(folder, "touches.csv", cell="loose.yaml", name="loose")
    assert main(["run", "--check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "scale: nothing here measures a length" in out
    tied = _config(folder, "touches.csv", name="tied")
    assert main(["run", "--check", str(tied)]) == 0
    assert "scale:" not in capsys.readouterr().out


@pytest.mark.parametrize("data", ["nests.csv", "ballbar.csv"])
def test_fixed_points_and_distances_run_too(cell, data, capsys):
    folder, _ = cell
    path = _config(folder, data, name=data.split(".")[0])
    path.write_text(path.read_text().replace("    test: data/test.csv\n",
                                             f"    test: data/test.csv\n    again: data/{data}\n"))
    assert main(["run", "-q", str(path)]) == 0
    metrics = json.loads((folder / f"out_{data.split('.')[0]}" / "metrics.json").read_text())
    entry = metrics["models"]["complete"]
    measurement = "fixed" if data == "nests.csv" else "distance"
    assert entry["cv_rms_by_type"][measurement] < 0.03
    assert entry["tests"]["test"]["rms_3d"] < 0.15
    # the identification file as a test set: its residuals are the fit's, printed with their type's name
    again = entry["tests"]["again"]["rms_by_type"][measurement]
    assert again == pytest.approx(entry["fit_rms_by_type"][measurement], rel=1e-9)
    assert f"{measurement} {again:.4f}" in capsys.readouterr().out


def test_a_model_of_an_error_field_is_refused_naming_it(cell, capsys):
    folder, _ = cell
    path = _config(folder, "touches.csv", name="field", models="  - name: FDP(CI)\n    inputs: cartesian\n"
                                                              "    basis: polynomial\n    degree: 1\n"
                                                              "    solver: {method: lstsq}\n")
    assert main(["run", str(path)]) == 2
    err = capsys.readouterr().err
    assert "FDP(CI)" in err and "error field" in err and "plane" in err


class Height(MeasurementType):
    """A toy type of this test module: the tool tip's height read by a height gauge, ``height_mm``."""

    name = "height_toy"
    default_noise = 0.01

    def residuals(self, positions, rotations, u):
        grad = np.tile([0.0, 0.0, 1.0], (self.index.size, 1))
        return Residuals(positions[self.index, 2] - self.rows.number("height_mm", self.index), self.index.copy(),
                         grad, np.zeros((self.index.size, 0)))


def test_a_measurement_type_registered_here_runs_through_partcal_run(cell, capsys):
    folder, study = cell
    vr = study.robot
    rng = np.random.default_rng(0)
    q = read_measurements(folder / "data" / "test.csv").q_deg[:120]
    height = vr.true_positions(q)[:, 2] + rng.normal(0, 0.01, len(q))
    lines = ["q1,q2,q3,q4,q5,q6,measurement,height_mm"] + [
        ",".join(f"{v:.6f}" for v in row) + f",height_toy,{h:.6f}" for row, h in zip(q, height)]
    (folder / "data" / "heights.csv").write_text("\n".join(lines) + "\n")
    add_measurement_type(Height)
    try:
        path = _config(folder, "heights.csv", cell=None, name="heights")
        assert main(["run", "-q", str(path)]) == 0
        metrics = json.loads((folder / "out_heights" / "metrics.json").read_text())
        assert metrics["measurement_types"]["height_toy"] == "120 height_toy rows; noise 0.01 mm"
        assert 0.005 < metrics["models"]["complete"]["cv_rms_by_type"]["height_toy"] < 0.03
    finally:
        del MEASUREMENT_TYPES["height_toy"]


def test_touches_and_tracker_points_in_two_files_in_the_trackers_frame(cell):
    """Mixed data: 20 tracker points in the tracker's own frame (a point CSV) beside the touches; the tracker's
    pose is fitted with the robot, and the test set (the same tracker) is scored after a rigid fit."""
    folder, study = cell
    vr = study.robot
    test = read_measurements(folder / "data" / "test.csv")
    rng = np.random.default_rng(3)
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    for name, q in (("points", test.q_deg[:20]), ("tracked", test.q_deg[200:])):
        seen = (vr.true_positions(q) - [2500.0, 0.0, 0.0]) @ turn + rng.normal(0, 0.02, (len(q), 3))
        lines = ["q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas"] + [",".join(f"{v:.6f}" for v in [*a, *b])
                                                               for a, b in zip(q, seen)]
        (folder / "data" / f"{name}.csv").write_text("\n".join(lines) + "\n")
    path = folder / "mixed.yaml"
    path.write_text(_config(folder, "touches.csv", name="mixed").read_text()
                    .replace("identification: data/touches.csv",
                             "identification: [data/touches.csv, data/points.csv]\n  frame: tracker")
                    .replace("test: data/test.csv", "test: data/tracked.csv"))
    assert main(["run", "-q", str(path)]) == 0
    metrics = json.loads((folder / "out_mixed" / "metrics.json").read_text())
    entry = metrics["models"]["complete"]
    assert set(entry["cv_rms_by_type"]) == {"point", "plane"}
    assert entry["cv_rms_by_type"]["point"] < 0.05 and entry["cv_rms_by_type"]["plane"] < 0.02
    assert metrics["measurement_types"]["point"] == "20 tracker points in the tracker's frame; noise 0.02 mm"
    assert entry["tests"]["test"]["rigid_fit"] and entry["tests"]["test"]["rms_3d"] < 0.1


def test_a_list_of_point_files_is_refused(cell, capsys):
    folder, _ = cell
    path = folder / "points_list.yaml"
    path.write_text(_config(folder, "test.csv", cell=None, name="plist").read_text()
                    .replace("identification: data/test.csv", "identification: [data/test.csv, data/test.csv]"))
    assert main(["run", "--check", str(path)]) == 2
    assert "join them into one file" in capsys.readouterr().err


def test_features_beside_a_point_file_alone_are_refused(cell, capsys):
    folder, _ = cell
    path = _config(folder, "test.csv", name="points_features")
    assert main(["run", "--check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "data.cell (line 5)" in err and "no identification file here has a 'measurement' column" in err


def _edited(folder: Path, source: str, target: str, edit) -> str:
    """``source`` of the cell's data with its data lines passed through ``edit(lines)``, as ``target``."""
    lines = (folder / "data" / source).read_text().splitlines()
    (folder / "data" / target).write_text("\n".join(edit(lines)) + "\n")
    return target


def _refusal(folder, data, capsys, cell="cell.yaml"):
    path = _config(folder, data, cell=cell, name=data.split(".")[0])
    assert main(["run", "--check", str(path)]) == 2
    return capsys.readouterr().err


def test_bad_rows_are_refused_naming_file_line_and_column(cell, capsys):
    folder, _ = cell
    header = 3                  # two comment lines, then the header: data line k is line k + 3

    def relabel(lines):         # data row 5 names the wrong plane: 'side' instead of 'top'
        out = list(lines)
        assert out[header + 4].endswith(",top")
        out[header + 4] = out[header + 4][:-3] + "side"
        return out
    err = _refusal(folder, _edited(folder, "touches.csv", "relabelled.csv", relabel), capsys)
    assert f"relabelled.csv:{header + 5}: column 'feature'" in err and "from plane 'side'" in err

    def metres(lines):          # the first distance in metres
        out = list(lines)
        k = next(i for i, line in enumerate(out) if ",distance," in line)
        cells = out[k].split(",")
        cells[-2] = f"{float(cells[-2]) / 1000:.6f}"
        out[k] = ",".join(cells)
        return out
    err = _refusal(folder, _edited(folder, "ballbar.csv", "metres.csv", metres), capsys)
    assert "metres.csv:" in err and "column 'distance_mm'" in err and "metres" in err

    def one_orientation(lines):  # the first visit of nest_a three times: one orientation
        first = next(line for line in lines if line.endswith(",nest_a"))
        cells = first.split(",")
        return lines[:header] + [",".join([*cells[:7], str(k), cells[8]]) for k in (1, 2, 3)]
    err = _refusal(folder, _edited(folder, "nests.csv", "still.csv", one_orientation), capsys)
    assert "still.csv:4: column 'feature': fixed point 'nest_a' is reached from one orientation" in err


@pytest.mark.parametrize("key, text", [
    ("data.validation", "  validation: data/test.csv\n"),
    ("data.groups", "  groups: set\n"),
    ("verify", "verify: {virtual_robot: virtual.yaml}\n"),
    ("predict", "predict: pose\n"),
    ("spread", "spread: {coverage: 0.9}\n"),
])
def test_a_setting_a_measurement_run_does_not_use_is_refused_naming_its_key(cell, capsys, key, text):
    folder, _ = cell
    config = _config(folder, "nests.csv", name="unused").read_text()
    if key.startswith("data."):
        config = config.replace("  tests:\n", text + "  tests:\n")
    else:
        config = text + config
    path = folder / "unused.yaml"
    path.write_text(config)
    assert main(["run", "--check", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{key} (line " in err and "does not use it" in err


def test_a_point_test_set_takes_a_row_subset_and_a_measurements_file_does_not(cell, capsys):
    from partcal.study.measurement_run import prepare_measurement_run
    folder, _ = cell
    path = folder / "subset.yaml"
    path.write_text(_config(folder, "nests.csv", name="subset").read_text()
                    .replace("test: data/test.csv", "test: {file: data/test.csv, rows: 11-40}"))
    data = prepare_measurement_run(load_config(path))
    whole = read_measurements(folder / "data" / "test.csv")
    assert np.array_equal(data.tests["test"].q_deg, whole.q_deg[10:40])
    path.write_text(_config(folder, "nests.csv", name="subset").read_text()
                    .replace("identification: data/nests.csv", "identification: {file: data/nests.csv, rows: 1-50}"))
    assert main(["run", "--check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "data.identification (line" in err and "read whole" in err


@pytest.mark.parametrize("second", ["data/nests.csv", "data/again/nests.csv"])
def test_identification_files_of_one_name_are_refused(cell, capsys, second):
    folder, _ = cell
    (folder / "data" / "again").mkdir(exist_ok=True)
    shutil.copy(folder / "data" / "nests.csv", folder / "data" / "again" / "nests.csv")
    path = folder / "twice.yaml"
    path.write_text(_config(folder, "nests.csv", name="twice").read_text()
                    .replace("identification: data/nests.csv", f"identification: [data/nests.csv, {second}]"))
    assert main(["run", "--check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "data.identification (line" in err and "nests.csv" in err
    assert ("listed twice" in err) == (second == "data/nests.csv")


def _few_side(folder: Path, keep: int) -> str:
    """touches.csv with only the first ``keep`` touches of plane 'side'."""
    def edit(lines):
        side = [i for i, line in enumerate(lines) if line.endswith(",side")]
        return [line for i, line in enumerate(lines) if i not in side[keep:]]
    return _edited(folder, "touches.csv", f"side{keep}.csv", edit)


def test_held_out_touches_are_scored_however_few_of_a_plane_a_fold_holds(cell, capsys):
    """A plane of 8 touches: a fold holds out one or two of them (fewer than an identification needs of a
    plane) and the run scores them all with the planes the training rows fitted."""
    folder, _ = cell
    path = _config(folder, _few_side(folder, 8), name="side8")
    assert main(["run", "-q", str(path)]) == 0, capsys.readouterr().err
    metrics = json.loads((folder / "out_side8" / "metrics.json").read_text())
    assert "side 8" in metrics["measurement_types"]["plane"]
    assert 0.005 < metrics["models"]["complete"]["cv_rms_by_type"]["plane"] < 0.1      # 0.01 mm touches


def test_check_refuses_folds_that_leave_a_plane_too_few_touches(cell, capsys):
    folder, _ = cell
    path = _config(folder, _few_side(folder, 3), name="side3")        # any fold holding one leaves two
    assert main(["run", "--check", str(path)]) == 2
    err = capsys.readouterr().err
    assert "cv_folds: cross-validation fold" in err and "plane 'side' has" in err and "fewer folds" in err


def test_a_measurement_test_set_is_scored_with_what_the_identification_fitted(cell):
    """A test set of visits of nest_b alone (tied to nest_a, which it does not visit; an identification would
    refuse it) is scored with the points the identification fitted: the 3-D coincidence of the model's tips with
    nest_b, computed here from the model file."""
    folder, _ = cell
    others = (",nest_a", ",sphere", ",cone")
    nest_b = _edited(folder, "nests.csv", "nest_b.csv", lambda lines: [x for x in lines if not x.endswith(others)])
    path = _config(folder, "nests.csv", name="nestb")
    path.write_text(path.read_text().replace("    test: data/test.csv\n",
                                             f"    test: data/test.csv\n    b: data/{nest_b}\n"))
    assert main(["run", "-q", str(path)]) == 0
    metrics = json.loads((folder / "out_nestb" / "metrics.json").read_text())
    model, _ = load_model(folder / "out_nestb" / "models" / "complete.json")
    from partcal.data.measurement_rows import read_measurement_rows
    rows = read_measurement_rows(folder / "data" / nest_b, "universal_robots_ur10")
    table = model.identification_
    centre = np.array([table.value[list(table.names).index(f"point nest_b.{c}")] for c in "xyz"])
    tips = model.robot.positions(rows.q_deg) + model.predict(rows.q_deg)
    expected = np.sqrt(np.mean((tips - centre) ** 2))
    assert metrics["models"]["complete"]["tests"]["b"]["rms_by_type"]["fixed"] == pytest.approx(expected, rel=1e-6)


def test_a_test_set_of_planes_the_identification_never_saw_places_them_on_its_own_rows(cell):
    """Identified from nests alone, scored on touches: the planes are fitted on the touches with the robot held
    (and the metrics say so); left at their starting values they scored 5 mm for a 0.17 mm model."""
    folder, _ = cell
    path = folder / "unseen.yaml"
    path.write_text(_config(folder, "nests.csv", name="unseen").read_text()
                    .replace("test: data/test.csv", "touches: data/touches.csv"))
    assert main(["run", "-q", str(path)]) == 0
    entry = json.loads((folder / "out_unseen" / "metrics.json").read_text())["models"]["complete"]
    touches = entry["tests"]["touches"]
    assert touches["fitted_on_test"] == ["plane side", "plane top"]
    assert touches["rms_by_type"]["plane"] < 0.05


def test_a_model_from_measurement_types_that_fix_no_frame_says_so_when_loaded(cell, caplog):
    folder, _ = cell
    path = _config(folder, "touches.csv", name="frame")
    assert main(["run", "-q", str(path)]) == 0
    model_file = folder / "out_frame" / "models" / "complete.json"
    doc = json.loads(model_file.read_text())
    assert doc["model"]["frame_fixed"] is False
    with caplog.at_level("WARNING"):
        model, _ = load_model(model_file)
    assert "fix no frame" in caplog.text and str(model_file) in caplog.text
    assert any("fix no frame" in note for note in model.fit_notes())
    # a file of partcal 0.1 names the types it was fitted on `measures`: read the same
    from partcal.study.persist import checksum
    doc["model"]["measures"] = doc["model"].pop("measurement_types")
    doc["checksum"] = checksum(doc)
    old_file = folder / "old_frame.json"
    old_file.write_text(json.dumps(doc))
    old, _ = load_model(old_file)
    assert old.measurement_types_ == model.measurement_types_ == ("plane",)
    q = np.random.default_rng(0).uniform(-90, 90, (5, 6))
    np.testing.assert_array_equal(old.predict(q), model.predict(q))


def test_a_prior_on_a_measurement_run_chooses_its_strength_on_the_runs_folds(cell, capsys):
    """Three strengths: the run scores each on its folds and chooses by the one-standard-error rule (written out
    here from its table), here the middle one, neither the first nor the strongest; the model fitted on every row
    is then the fit at that strength, as KinematicModel gives it, and not the fit at either other."""
    from partcal.models.kinematic import KinematicModel

    from partcal.study.measurement_run import prepare_measurement_run
    folder, _ = cell
    strengths = [0.01, 0.1, 1.0]
    half = _edited(folder, "nests.csv", "nests_half.csv",       # every other visit, on 2 folds: a quicker run
                   lambda lines: lines[:3] + lines[3::2])
    path = _config(folder, half, name="prior", models=f"    prior: plausible\n    prior_strength: {strengths}\n")
    path.write_text(path.read_text().replace("robot:", "cv_folds: 2\nrobot:"))
    assert main(["run", "-q", str(path)]) == 0
    printed = capsys.readouterr().out
    out = folder / "out_prior"
    metrics = json.loads((out / "metrics.json").read_text())
    table = metrics["models"]["complete"]["prior_strength"]
    assert [row["prior_strength"] for row in table] == strengths
    assert set(table[0]) == {"prior_strength", "cv_weighted_rms_mm", "cv_se", "chosen"}
    scores, errors = [row["cv_weighted_rms_mm"] for row in table], [row["cv_se"] for row in table]
    best = int(np.argmin(scores))                 # the one-standard-error rule, written out
    chosen = max(row["prior_strength"] for row in table if row["cv_weighted_rms_mm"] <= scores[best] + errors[best])
    assert chosen == 0.1                          # neither the first in the list nor the strongest
    assert [row["chosen"] for row in table] == [row["prior_strength"] == chosen for row in table]
    note = next(n for n in metrics["models"]["complete"]["notes"] if n.startswith(f"prior strength {chosen:g} chosen"))
    assert "CV weighted RMS" in note and f"note: {note}" in printed
    html = (out / "index.html").read_text()
    assert "Prior strength chosen by cross-validation" in html and f"{scores[1]:.4f}" in html
    data = prepare_measurement_run(load_config(path))
    fitted, _ = load_model(out / "models" / "complete.json")

    def at(strength):
        return KinematicModel(robot=data.robot, parametrization="complete", prior="plausible",
                              prior_strength=strength).fit(data.rows.q_deg, None,
                                                           rows=data.rows, cell=data.cell).identification_
    np.testing.assert_allclose(fitted.identification_.value, at(chosen).value, rtol=0, atol=1e-9)
    for other in (strengths[0], strengths[-1]):
        assert np.max(np.abs(at(other).value[:33] - fitted.identification_.value[:33])) > 1e-3


def test_a_measurement_run_calls_best_the_entry_of_the_lowest_cv_score_and_a_model_file_serves_as_a_prior(cell, capsys):
    """Two entries, complete and DH rows: "best" is the one whose weighted CV residual is the lower (the table marks
    it). Then one of the model files (fitted on types: its planes' and points' unknowns follow the robot's) as a
    strong prior of another run: the row parameters come out at its values."""
    folder, _ = cell
    plain = _config(folder, "nests.csv", name="noprior", models="  - name: dh\n    kind: kinematic\n")
    plain.write_text(plain.read_text().replace("robot:", "cv_folds: 2\nrobot:"))
    assert main(["run", str(plain)]) == 0
    printed = capsys.readouterr().out
    metrics = json.loads((folder / "out_noprior" / "metrics.json").read_text())
    scores = {name: entry["cv_weighted_rms_mm"] for name, entry in metrics["models"].items()}
    assert set(scores) == {"complete", "dh"} and abs(scores["complete"] - scores["dh"]) > 1e-4
    lowest = min(scores, key=scores.get)
    assert metrics["best"] == lowest
    assert any(line.startswith(f"{lowest} *") for line in printed.splitlines())
    other = _config(folder, "nests.csv", name="fileprior",
                    models="    prior: out_noprior/models/complete.json\n    prior_strength: 10000\n")
    assert main(["run", "-q", str(other)]) == 0
    source, _ = load_model(folder / "out_noprior" / "models" / "complete.json")
    fitted, _ = load_model(folder / "out_fileprior" / "models" / "complete.json")
    rows = next(k for k, n in enumerate(source.identification_.names) if n.startswith("tool."))
    np.testing.assert_allclose(fitted.identification_.value[:rows], source.identification_.value[:rows], atol=1e-4)
    assert np.max(np.abs(source.identification_.correction[:rows])) > 1e-2      # and those are not nominal


def test_a_bad_prior_strength_on_a_measurement_run_is_refused_naming_file_line_and_field(cell, capsys):
    folder, _ = cell
    path = _config(folder, "nests.csv", name="badprior", models="    prior: plausible\n    prior_strength: -1\n")
    line = path.read_text().splitlines().index("    prior_strength: -1") + 1
    assert main(["run", "--check", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}: models[0].prior_strength (line {line}): must be a number >= 0, auto" in err and "got -1" in err
    path = _config(folder, "nests.csv", name="badprior", models="    prior_strength: 3\n")
    line = path.read_text().splitlines().index("    prior_strength: 3") + 1
    assert main(["run", "--check", str(path)]) == 2
    assert f"models[0].prior_strength (line {line}): applies with a prior only" in capsys.readouterr().err


def test_check_says_a_prior_holds_the_scale_unknown_planes_leave_free(cell, capsys):
    folder, _ = cell
    (folder / "data" / "loose.yaml").write_text("planes: {top: {}, step: {}, side: {}}\n")
    path = _config(folder, "touches.csv", cell="loose.yaml", name="loose_prior",
                   models="    prior: plausible\n")
    assert main(["run", "--check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "scale: nothing here measures a length" in out and "the prior holds it" in out
    held = next(line for line in out.splitlines() if line.startswith("complete: held nominal"))
    plain = _config(folder, "touches.csv", cell="loose.yaml", name="loose_plain")
    assert main(["run", "--check", str(plain)]) == 0
    out = capsys.readouterr().out
    assert "one length is held nominal" in out
    held_plain = next(line for line in out.splitlines() if line.startswith("complete: held nominal"))
    # the prior's rows make the length the scale would have held identifiable: fewer parameters held nominal
    assert len(held.split(":", 2)[2].split(",")) < len(held_plain.split(":", 2)[2].split(","))
    # but no cross-validation of such rows can choose a strength (held-out lengths fall as the robot shrinks)
    listed = _config(folder, "touches.csv", cell="loose.yaml", name="loose_list",
                     models="    prior: plausible\n    prior_strength: auto\n")
    line = listed.read_text().splitlines().index("    prior_strength: auto") + 1
    assert main(["run", "--check", str(listed)]) == 2
    err = capsys.readouterr().err
    assert f"{listed}: models[0].prior_strength (line {line}): a list of strengths cannot be chosen on these " in err


PROBE = {**{f"q{j}": f"Axis {j}" for j in range(1, 7)}, "measurement": "Type", "id": "Name", "distance_mm": "Length",
         "to": "Ref", "x_nom": "Xn", "y_nom": "Yn", "z_nom": "Zn", "x_meas": "X", "y_meas": "Y", "z_meas": "Z",
         "set": "Group"}
PROBE_KINDS = {"pose": "Pose", "distance": "Bar"}


def _probe_export(folder: Path, source: str, target: str) -> str:
    """The cell's ``source`` as a foreign export writes it: PROBE's column names, semicolons, decimal commas,
    joints in radians, lengths in metres and PROBE_KINDS' type values (converted here, not by partcal)."""
    lines = [x for x in (folder / "data" / source).read_text().splitlines() if x and not x.startswith("#")]
    header = lines[0].split(",")
    out = [";".join(PROBE[c] for c in header)]
    for line in lines[1:]:
        cells = []
        for column, cell in zip(header, line.split(",")):
            if cell and column.startswith("q"):
                cell = repr(float(cell) * np.pi / 180.0)
            elif cell and column in ("distance_mm", "x_nom", "y_nom", "z_nom", "x_meas", "y_meas", "z_meas"):
                cell = repr(float(cell) / 1000.0)
            cells.append(PROBE_KINDS.get(cell, cell) if column == "measurement" else cell.replace(".", ","))
        out.append(";".join(cells))
    (folder / "data" / target).write_text("\n".join(out) + "\n")
    return target


def test_a_run_reads_a_foreign_measurements_file_and_point_csv_through_one_format(cell):
    """``data.format`` maps the ballbar's types columns and type values and the tracker test set's columns: the
    run's figures are those of the same data in the contract."""
    folder, _ = cell
    contract = _config(folder, "ballbar.csv", name="bar_contract")
    foreign = _config(folder, _probe_export(folder, "ballbar.csv", "ballbar_probe.csv"), name="bar_probe")
    test = _probe_export(folder, "test.csv", "test_probe.csv")
    columns = ", ".join(f"{k}: '{v}'" for k, v in PROBE.items())
    measurements = ", ".join(f"{v}: {k}" for k, v in PROBE_KINDS.items())
    foreign.write_text(foreign.read_text().replace("data/test.csv", f"data/{test}").replace(
        "data:\n", f"data:\n  format: {{delimiter: ';', decimal: ',', joint_unit: rad, length_unit: m,\n"
                   f"           columns: {{{columns}}},\n           measurements: {{{measurements}}}}}\n"))
    assert main(["run", "-q", str(contract)]) == 0 and main(["run", "-q", str(foreign)]) == 0
    want, got = ((json.loads((folder / f"out_{n}" / "metrics.json").read_text())["models"]["complete"])
                 for n in ("bar_contract", "bar_probe"))
    assert got["fit_rms_by_type"]["distance"] == pytest.approx(want["fit_rms_by_type"]["distance"], rel=1e-6)
    assert got["cv_rms_by_type"]["distance"] == pytest.approx(want["cv_rms_by_type"]["distance"], rel=1e-6)
    assert got["tests"]["test"]["rms_3d"] == pytest.approx(want["tests"]["test"]["rms_3d"], rel=1e-6)
    assert want["tests"]["test"]["rms_3d"] < 0.15                      # a calibrated robot, not two failures


def test_a_ballbar_split_over_two_files_links_its_ids_across_them(cell, capsys):
    """The ballbar's poses in one file and its distances in another (their 'to' naming the poses' ids): the run
    links them and its figures are those of the one file; an id two other files both hold is refused."""
    folder, _ = cell
    lines = (folder / "data" / "ballbar.csv").read_text().splitlines()
    header, rows = lines[[i for i, x in enumerate(lines) if not x.startswith("#")][0]], \
        [x for x in lines if x and not x.startswith("#")][1:]
    (folder / "data" / "bar_poses.csv").write_text("\n".join([header, *(r for r in rows if ",pose," in r)]) + "\n")
    (folder / "data" / "bar_lengths.csv").write_text(
        "\n".join([header, *(r for r in rows if ",distance," in r)]) + "\n")
    whole = _config(folder, "ballbar.csv", name="bar_whole")
    split = _config(folder, "ballbar.csv", name="bar_split")
    split.write_text(split.read_text().replace("identification: data/ballbar.csv",
                                               "identification: [data/bar_poses.csv, data/bar_lengths.csv]"))
    assert main(["run", "-q", str(whole)]) == 0 and main(["run", "-q", str(split)]) == 0, capsys.readouterr().err
    want, got = (json.loads((folder / f"out_{n}" / "metrics.json").read_text())["models"]["complete"]
                 for n in ("bar_whole", "bar_split"))
    assert got["fit_rms_by_type"]["distance"] == pytest.approx(want["fit_rms_by_type"]["distance"], rel=1e-9)
    assert got["tests"]["test"]["rms_3d"] == pytest.approx(want["tests"]["test"]["rms_3d"], rel=1e-9)
    shutil.copy(folder / "data" / "bar_poses.csv", folder / "data" / "bar_poses2.csv")
    split.write_text(split.read_text().replace("[data/bar_poses.csv, data/bar_lengths.csv]",
                                               "[data/bar_poses.csv, data/bar_poses2.csv, data/bar_lengths.csv]"))
    capsys.readouterr()
    assert main(["run", "-q", str(split)]) == 2
    assert ("bar_lengths.csv:2: column 'to': 'p2' names no row of its file and a row of 2 others (bar_poses, "
            "bar_poses2)") in capsys.readouterr().err


def test_update_takes_a_model_identified_from_touches_and_new_tracker_points(cell, capsys):
    """``partcal update`` of a model identified from touches (its planes among its unknowns) with tracker points of
    the same robot: the prior is on the robot's parameters alone, the new model holds the robot's parameters, and
    on the points it leaves less than the touches' model did (its frame refitted), as printed."""
    folder, _ = cell
    path = _config(folder, "touches.csv", name="touches_for_update")
    assert main(["run", "-q", str(path)]) == 0
    model_path = folder / "out_touches_for_update" / "models" / "complete.json"
    capsys.readouterr()
    assert main(["update", str(model_path), str(folder / "data" / "test.csv"), "-o", str(folder / "new.json")]) == 0
    printed = capsys.readouterr().out
    import re
    before, after = (float(x) for x in re.search(r"3-D RMS on them ([\d.]+) mm with the prior model \(its frame "
                                                 r"refitted\) -> ([\d.]+) mm", printed).groups())
    new, _ = load_model(folder / "new.json")
    old, _ = load_model(model_path)
    assert new.identification_.names == old.identification_.names[:len(old.robot_parameter_names())]
    assert not any(n.startswith("plane ") for n in new.identification_.names)
    test = read_measurements(folder / "data" / "test.csv")
    left = np.sqrt(np.mean(np.sum((test.errors_mm - new.predict(test.q_deg)) ** 2, axis=1)))
    assert left == pytest.approx(after, abs=5e-4) and after < before
