"""The checks of the one road (partcal/calibration/checks.py and the types' own), each on data ``partcal simulate``
makes of a virtual UR10 (DH errors and tilts) and through ``partcal run`` as a probe user runs it: a wrong input is
refused with one line naming file, line, column or key, or the run says the result is not calibrated and why;
never a silent exit 0 with a wrong model."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import small_contact_cell

from partcal.cli import main

@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """The shipped virtual cell, smaller (touches, nests on a 1000 mm bar, a 30-pose ballbar, 400 test points)."""
    folder = tmp_path_factory.mktemp("checks")
    small_contact_cell(folder, touches=60, side=40, visits=20, poses=30)
    assert main(["simulate", str(folder / "virtual.yaml")]) == 0
    return folder


def _run(folder: Path, name: str, identification: str, *, cell: str = "data/cell.yaml", extra: str = "",
         models: str = "  - {name: DH, kind: kinematic}\n") -> Path:
    path = folder / f"{name}.yaml"
    path.write_text(f"name: {name}\nrobot: universal_robots_ur10\nseed: 0\ncv_folds: 2\n{extra}data:\n"
                    f"  identification: {identification}\n  cell: {cell}\n  tests: {{test: data/test.csv}}\n"
                    f"models:\n{models}output: out_{name}\n")
    return path


def _metrics(folder: Path, name: str) -> dict:
    return json.loads((folder / f"out_{name}" / "metrics.json").read_text())


def _cell_with(folder: Path, name: str, old: str, new: str) -> str:
    text = (folder / "data" / "cell.yaml").read_text()
    assert old in text
    (folder / "data" / name).write_text(text.replace(old, new))
    return f"data/{name}"


def _edited_rows(folder: Path, source: str, target: str, edit) -> str:
    """``source`` with its data lines passed through ``edit(lines) -> lines`` (header and comments kept)."""
    lines = (folder / "data" / source).read_text().splitlines()
    first = next(i for i, x in enumerate(lines) if not x.startswith("#")) + 1
    (folder / "data" / target).write_text("\n".join(lines[:first] + edit(lines[first:])) + "\n")
    return f"data/{target}"


def test_a_bar_in_metres_is_refused_naming_the_key_and_the_unit(cell, capsys):
    cell_file = _cell_with(cell, "bar_metres.yaml", "distance_mm: 1000.0", "distance_mm: 1.0")
    assert main(["run", "--check", str(_run(cell, "metres", "data/nests.csv", cell=cell_file))]) == 2
    err = capsys.readouterr().err
    assert re.search(r"nests\.csv:\d+: points\.nest_b\.distance_mm: 1 mm, but the nominal robot's visits of 'nest_b' "
                     r"and 'nest_a' say about 100\d\.\d mm: expected the length in mm \(metres\? 1 metres is 1000 mm\)",
                     err), err


@pytest.mark.parametrize("old, new, key", [("distance_mm: 1000.0", "distance_mm: 1010.0", "points.nest_b.distance_mm"),
                                           ("spacing_mm: -200.0", "spacing_mm: -210.0", "planes.step.spacing_mm")])
def test_a_known_length_10_mm_off_is_said_and_the_fit_not_called_calibrated(cell, capsys, old, new, key):
    """10 mm off: the fit meets it by bending the robot (its own residuals stay small), so the run says so, names the
    key, calls the model not calibrated and, on the test points, worse than none."""
    data = "data/nests.csv" if "points" in key else "data/touches.csv"
    name = key.split(".")[1] + "_off"
    cell_file = _cell_with(cell, f"{name}.yaml", old, new)
    assert main(["run", "-q", str(_run(cell, name, data, cell=cell_file))]) == 0
    out = capsys.readouterr().out
    assert f"note: not calibrated: {key} is {float(new.split()[1]):g} mm, but the nominal robot's" in out
    entry = _metrics(cell, name)["models"]["DH"]
    assert entry["kinematic"]["calibrated"] is False
    assert "note: worse than none on test set 'test'" in out
    assert entry["tests"]["test"]["rms_3d"] > _metrics(cell, name)["uncompensated"]["test"]["rms_3d"]


def test_the_same_cell_with_its_true_lengths_is_calibrated(cell, capsys):
    assert main(["run", "-q", str(_run(cell, "true_lengths", "data/nests.csv"))]) == 0
    out = capsys.readouterr().out
    entry = _metrics(cell, "true_lengths")["models"]["DH"]
    assert entry["kinematic"]["calibrated"] is True and "not calibrated" not in out and "worse than none" not in out
    assert entry["tests"]["test"]["rms_3d"] < 0.5 * _metrics(cell, "true_lengths")["uncompensated"]["test"]["rms_3d"]


def test_joints_in_degrees_read_as_radians_are_refused_naming_row_and_column(cell, capsys):
    fmt = "  format: {joint_unit: rad}\n"
    path = _run(cell, "radians", "data/ballbar.csv")
    path.write_text(path.read_text().replace("data:\n", "data:\n" + fmt).replace("  tests: {test: data/test.csv}\n",
                                                                                 ""))
    assert main(["run", "--check", str(path)]) == 2
    err = capsys.readouterr().err
    assert re.search(r"ballbar\.csv:\d+: column 'q\d': -?[\d.]+ degrees lies outside joint \d's limits \[-360, 360\] "
                     r"of universal_robots_ur10 \(\d+ rows beyond a limit\); every joint divided by 57\.3 lies within "
                     r"them: degrees read as radians", err), err


def test_one_joint_of_a_million_degrees_is_refused(cell, capsys):
    rows = _edited_rows(cell, "touches.csv", "q4.csv",
                        lambda lines: [",".join(c if k != 3 else "1e6" for k, c in enumerate(x.split(",")))
                                       if i == 7 else x for i, x in enumerate(lines)])
    assert main(["run", "--check", str(_run(cell, "q4", rows))]) == 2
    assert re.search(r"q4\.csv:\d+: column 'q4': 1e\+06 degrees lies outside joint 4's limits",
                     capsys.readouterr().err)


def test_one_distance_10_mm_off_is_named_and_a_robust_loss_keeps_the_fit_within_10_percent(cell, capsys):
    """Among the 435 pair distances one is 10 mm off: least squares leaves a fit many times the noise and names
    that row; the Cauchy loss stays within 10 % of the clean fit on the test points and names it down-weighted."""
    def bad(lines):
        cells = lines[100].split(",")
        cells[8] = f"{float(cells[8]) + 10.0:.6f}"           # distance_mm of a distance row
        return lines[:100] + [",".join(cells)] + lines[101:]
    header = [x for x in (cell / "data" / "ballbar.csv").read_text().splitlines() if not x.startswith("#")][0]
    assert header.split(",")[8] == "distance_mm"
    rows = _edited_rows(cell, "ballbar.csv", "bar_bad.csv", bad)
    complete = "  - {name: complete, kind: kinematic, parametrization: complete}\n"
    assert main(["run", "-q", str(_run(cell, "bar_clean", "data/ballbar.csv", models=complete))]) == 0
    assert main(["run", "-q", str(_run(cell, "bar_ls", rows, models=complete))]) == 0
    plain = capsys.readouterr().out
    robust = complete.replace("}", ", loss: cauchy}")
    assert main(["run", "-q", str(_run(cell, "bar_robust", rows, models=robust))]) == 0
    out = capsys.readouterr().out
    text = (cell / "data" / "bar_bad.csv").read_text().splitlines()
    bad_line = next(i for i, x in enumerate(text, 1) if not x.startswith("#")) + 101     # its header's line + 101
    assert f"bar_bad.csv:{bad_line} (9." in plain and "note: not calibrated: the distance rows' fit leaves" in plain
    assert re.search(rf"bar_bad\.csv:{bad_line}: down-weighted by the cauchy loss \(residual (10|9\.\d+) mm", out), out
    assert "not calibrated" not in out          # judged on the rows the loss keeps
    clean = _metrics(cell, "bar_clean")["models"]["complete"]["tests"]["test"]["rms_3d"]
    bent = _metrics(cell, "bar_ls")["models"]["complete"]["tests"]["test"]["rms_3d"]
    kept = _metrics(cell, "bar_robust")["models"]["complete"]["tests"]["test"]["rms_3d"]
    assert bent > 1.5 * clean and kept < 1.1 * clean


def test_a_model_from_five_touches_is_refused_before_it_is_fitted(cell, capsys):
    """Five touches of one plane: every fold's training rows (and the whole file) leave no residual for the
    parameters they identify; the config is refused naming cv_folds (the old code wrote a model worse than none)."""
    rows = _edited_rows(cell, "touches.csv", "five.csv", lambda lines: [x for x in lines if x.endswith(",top")][:5])
    path = _run(cell, "five", rows)
    path.write_text(path.read_text().replace("cv_folds: 2\n", ""))
    assert main(["run", "--check", str(path)]) == 2
    assert re.search(r"five\.yaml: cv_folds: cross-validation fold 1 of 5: its training rows give \d+ residuals for the "
                     r"\d+ parameters they identify for model 'DH': no residual is left", capsys.readouterr().err)


def test_leave_one_out_on_twelve_touches_is_refused_when_the_config_is_read(cell, capsys):
    def twelve(lines):
        return [x for x in lines if x.endswith(",top")][:4] + [x for x in lines if x.endswith(",step")][:4] + \
            [x for x in lines if x.endswith(",side")][:4]
    rows = _edited_rows(cell, "touches.csv", "twelve.csv", twelve)
    path = _run(cell, "twelve", rows)
    path.write_text(path.read_text().replace("cv_folds: 2", "cv_folds: leave_one_out"))
    assert main(["run", "--check", str(path)]) == 2
    assert "cv_folds (line 4): cross-validation fold 1 of 12" in capsys.readouterr().err


def test_rows_plan_wrote_are_refused_until_measured(cell, capsys):
    plan_cell = _cell_with(cell, "plan_cell.yaml", "side: {}", "side: {normal: [1.0, 0.0, 0.02], offset_mm: 600.0}")
    out = cell / "data" / "planned.csv"
    assert main(["plan", "universal_robots_ur10", "-q", "--measurement", "plane", "-n", "30", "-o", str(out),
                 "--cell", str(cell / plan_cell), "--pool", "300"]) == 0
    assert main(["run", "--check", str(_run(cell, "planned", "data/planned.csv", cell=plan_cell))]) == 2
    assert re.search(r"planned\.csv:\d+: column 'planned': a row partcal plan planned, not yet measured",
                     capsys.readouterr().err)


def test_a_semicolon_file_is_named_as_such_not_the_cell(cell, capsys):
    text = (cell / "data" / "touches.csv").read_text().replace(",", ";")
    (cell / "data" / "semi.csv").write_text(text)
    assert main(["run", "--check", str(_run(cell, "semi", "data/semi.csv"))]) == 2
    err = capsys.readouterr().err
    assert "semi.csv:3: the header is one column containing ';', but the delimiter is ','" in err
    assert "data.cell" not in err


def test_a_list_where_a_number_is_expected_is_shown(cell, capsys):
    path = _run(cell, "listed", "data/touches.csv")
    path.write_text(path.read_text().replace("seed: 0", "seed: [1, 2]"))
    assert main(["run", "--check", str(path)]) == 2
    assert "seed (line 3): must be an integer; got a list [1, 2]" in capsys.readouterr().err


def test_a_plane_given_approximately_is_held_where_the_touches_put_it_not_at_the_guess(cell):
    """Touches of the top plane with the tool vertical, turned about its axis (flush), alone: they cannot identify
    the plane's tilts against the robot's. Given approximately (its normal 0.5 degree off, offset 1 mm), the fit
    holds that part where the nominal robot's touches put it, as if unknown: the same robot either way (the old
    code held it at the guess and bent the robot to meet it)."""
    from partcal.calibration.stacked import identify_measurements
    from partcal.data.measurement_rows import read_cell, read_measurement_rows
    from partcal.robot.description import load_robot
    robot = load_robot("universal_robots_ur10")
    rows = read_measurement_rows(cell / "data" / "flush.csv", robot)
    top = np.array([r == "top" for r in rows.texts["feature"]])
    rows = rows.take(np.flatnonzero(top))
    given = read_cell(cell / "data" / "cell.yaml")
    assert "normal" in given["planes"]["top"]
    unknown = {**given, "planes": {**given["planes"], "top": {}}}
    a = identify_measurements(robot, rows, given)[0]
    b = identify_measurements(robot, rows, unknown)[0]
    assert a.names[:33] == b.names[:33] and a.status[:33] == b.status[:33]       # the robot's parameters
    np.testing.assert_allclose(a.value[:33], b.value[:33], atol=1e-6)


def test_a_robust_fits_noise_ratio_leaves_out_only_the_rows_weighed_below_a_tenth(cell):
    """Ballbar distances with one 10 mm off (the Cauchy loss weighs it ~1e-5) and one 0.06 mm off (weighed about
    1 / (1 + (0.06 / 0.03)^2) = 0.2: named as down-weighted, but kept): the noise ratio is the RMS of every row but
    the first over the stated noise, worked out from the fit's RMS of all rows and the residual of the row left
    out (one residual a row)."""
    from partcal.calibration.stacked import identify_measurements
    from partcal.data.measurement_rows import read_cell, read_measurement_rows
    from partcal.robot.description import load_robot

    def bad(lines):
        out = list(lines)
        for k, off in ((100, 10.0), (200, 0.06)):
            cells = out[k].split(",")
            cells[8] = f"{float(cells[8]) + off:.6f}"       # distance_mm
            out[k] = ",".join(cells)
        return out
    robot = load_robot("universal_robots_ur10")
    rows = read_measurement_rows(cell / _edited_rows(cell, "ballbar.csv", "bar_two.csv", bad), robot)
    given = read_cell(cell / "data" / "cell.yaml")
    table = identify_measurements(robot, rows, given, parametrization="complete", loss="cauchy")[0]
    sigma = given["noise"]["distance"]
    assert sigma == 0.01 and table.misfit is not None and table.robust is not None
    weights = {d["row"]: d["weight"] for d in table.robust["downweighted"]}
    far = [d for d in table.robust["downweighted"] if d["weight"] < 0.1]
    assert len(far) == 1 and weights[far[0]["row"]] < 1e-3
    assert any(0.1 < w < 0.5 for w in weights.values())            # a row down-weighted but kept
    n = rows.types.count("distance")
    kept_squares = n * table.target_rms_mm["distance"] ** 2 - far[0]["residual_mm"] ** 2
    expected = np.sqrt(kept_squares / (n - 1)) / sigma
    assert table.misfit["noise_ratio"]["distance"] == pytest.approx(expected, rel=1e-9)
