"""The command line: exit codes and messages."""

import csv
import json
import re
import shutil

import numpy as np
import pytest
from conftest import ROOT, SHARED, partcal_cli

import partcal
from partcal import read_measurements
from partcal.metrics import rms_per_axis

DATA = ROOT / "data" / "sk120"


run = partcal_cli


def test_version():
    res = run("--version")
    assert res.returncode == 0 and res.stdout.strip() == f"partcal {partcal.__version__}"


def test_simulate_prints_what_it_wrote(tmp_path):
    cfg = tmp_path / "configs"
    cfg.mkdir()
    shutil.copy(ROOT / "configs" / "sk120_virtual.yaml", cfg / "sk120_virtual.yaml")
    res = run("simulate", str(cfg / "sk120_virtual.yaml"))
    assert res.returncode == 0, res.stderr
    out = tmp_path / "data" / "sk120"
    assert sorted(p.name for p in out.iterdir()) == [
        "identification.csv", "test_rectangle.csv", "test_spiral_xy.csv", "test_spiral_yz.csv"]
    rows = {line.split()[0]: line.split() for line in res.stdout.splitlines()[2:6]}
    for name in ("identification", "test_rectangle", "test_spiral_xy", "test_spiral_yz"):
        m = read_measurements(out / f"{name}.csv")
        assert int(rows[name][1]) == len(m)
        np.testing.assert_allclose([float(v) for v in rows[name][2:5]], rms_per_axis(m.errors_mm), atol=0.006)


def test_simulate_checks_the_folder_first_and_replaces_files_as_a_set(tmp_path):
    cfg = tmp_path / "configs"
    cfg.mkdir()
    text = (ROOT / "configs" / "sk120_virtual.yaml").read_text()
    (cfg / "v.yaml").write_text(text.replace("output: ../data/sk120", "output: ../blocked/out"))
    (tmp_path / "blocked").write_text("a file where a folder must be")
    res = run("simulate", str(cfg / "v.yaml"))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert "blocked/out: cannot write here" in res.stderr and "Virtual" not in res.stdout    # refused before simulating
    (cfg / "v.yaml").write_text(text.replace("output: ../data/sk120", "output: ../out"))
    out = tmp_path / "out"
    out.mkdir()
    for name in ("identification", "test_rectangle", "test_spiral_xy", "test_spiral_yz"):
        (out / f"{name}.csv").write_text("old\n")
    (out / "test_spiral_xy.csv").unlink()
    (out / "test_spiral_xy.csv").mkdir()          # one target cannot be replaced: none may be
    res = run("simulate", str(cfg / "v.yaml"))
    assert res.returncode == 2, res.stderr
    assert all((out / f"{n}.csv").read_text() == "old\n" for n in ("identification", "test_rectangle", "test_spiral_yz"))
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []


def test_bad_input_exits_2_with_one_line(tmp_path):
    res = run("simulate", str(tmp_path / "missing.yaml"))
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and "missing.yaml: no such file" in res.stderr
    assert "Traceback" not in res.stderr


@pytest.fixture(scope="module")
def joint_model(tmp_path_factory):
    from partcal import ErrorModel, load_robot
    from partcal.study.persist import save_model

    m = read_measurements(DATA / "identification.csv")
    path = tmp_path_factory.mktemp("model") / "sdp-ai.json"
    save_model(ErrorModel(inputs="joint", degree=2, solver="lstsq").fit(m.q_deg, m.errors_mm), path,
               robot=load_robot("motoman_sk120"))
    return path


def test_compensate_marks_unconverged_targets_and_exits_3(joint_model, tmp_path):
    m = read_measurements(DATA / "test_rectangle.csv")
    targets = tmp_path / "targets.csv"
    rows = [m.nominal_mm[0], [9000.0, 0.0, 0.0], m.nominal_mm[1]]        # the middle one is 9 m away
    targets.write_text("x,y,z\n" + "\n".join(",".join(f"{v:.6f}" for v in p) for p in rows) + "\n")
    out = tmp_path / "cmd.csv"
    res = run("compensate", str(joint_model), str(targets), "-o", str(out))
    assert res.returncode == 3, res.stderr
    assert res.stderr.count("\n") == 1
    assert "1 of 3 targets did not converge or are unreachable (first: data row 2 of" in res.stderr
    with open(out) as handle:
        flags = [r["converged"] for r in csv.DictReader(handle)]
    assert flags == ["true", "false", "true"]
    targets.write_text("x,y,z\n" + "\n".join(",".join(f"{v:.6f}" for v in p) for p in m.nominal_mm[:3]) + "\n")
    res = run("compensate", str(joint_model), str(targets), "-o", str(out))
    assert res.returncode == 0 and res.stderr == "", res.stderr
    with open(out) as handle:
        assert [r["converged"] for r in csv.DictReader(handle)] == ["true"] * 3


@pytest.mark.parametrize("model, reasons", [("joint", ["", "out of reach", "joint limit"]),
                                            ("cartesian", ["", "out of reach", ""])])
def test_compensate_writes_each_targets_miss_and_why_it_missed(joint_model, cartesian_model, tmp_path, model,
                                                               reasons):
    m = read_measurements(DATA / "test_rectangle.csv")
    targets = tmp_path / "targets.csv"
    rows = [m.nominal_mm[0], [9000.0, 0.0, 0.0], [912.609, 0.0, 122.994]]  # 9 m away; the home seed folds the SK120
    targets.write_text("x,y,z\n" + "\n".join(",".join(f"{v:.6f}" for v in p) for p in rows) + "\n")
    out = tmp_path / "cmd.csv"
    res = run("compensate", str(joint_model if model == "joint" else cartesian_model), str(targets), "-o", str(out))
    assert res.returncode == 3, res.stderr
    assert "first: data row 2 of" in res.stderr and "0.0] mm: out of reach, predicted miss" in res.stderr
    with open(out) as handle:
        written = list(csv.DictReader(handle))
    assert list(written[0])[-3:] == ["miss_mm", "converged", "reason"]
    assert [r["reason"] for r in written] == reasons
    assert [r["converged"] for r in written] == ["true" if not r else "false" for r in reasons]
    assert float(written[0]["miss_mm"]) <= 1e-4
    if model == "joint":
        assert float(written[1]["miss_mm"]) > 1000 and float(written[2]["miss_mm"]) <= 1e-4   # solved, not takeable


def test_compensate_tolerances_are_options(joint_model, tmp_path):
    m = read_measurements(DATA / "test_rectangle.csv")
    targets = tmp_path / "targets.csv"
    targets.write_text("x,y,z\n" + "\n".join(",".join(f"{v:.6f}" for v in p) for p in m.nominal_mm[:5]) + "\n")
    misses = {}
    for tol in ("1e-4", "0.05"):
        out = tmp_path / f"cmd{tol}.csv"
        res = run("compensate", str(joint_model), str(targets), "-o", str(out), "--tol-mm", tol)
        assert res.returncode == 0, res.stderr
        with open(out) as handle:
            misses[tol] = np.array([float(r["miss_mm"]) for r in csv.DictReader(handle)])
        assert misses[tol].max() <= float(tol)
    assert misses["0.05"].max() > 1e-4            # the looser tolerance stops the solve earlier
    res = run("compensate", str(joint_model), str(targets), "-o", str(tmp_path / "x.csv"), "--tol-mm", "0")
    assert res.returncode == 2 and "argument --tol-mm: expected a positive number; got '0'" in res.stderr
    assert not (tmp_path / "x.csv").exists()


def test_output_naming_a_folder_is_refused(joint_model, tmp_path):
    m = read_measurements(DATA / "identification.csv")
    points = tmp_path / "q.csv"
    points.write_text("q1,q2,q3,q4,q5,q6\n" + ",".join(f"{v:.6f}" for v in m.q_deg[0]) + "\n")
    folder = tmp_path / "a_folder"
    folder.mkdir()
    res = run("predict", str(joint_model), str(points), "-o", str(folder))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert f"{folder}: is a folder; give the name of a file to write" in res.stderr


def test_equations_command_prints_what_predicts(joint_model):
    from partcal import load_predictor

    res = run("equations", str(joint_model))
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert [line.split(" = ")[0] for line in lines] == ["dx", "dy", "dz"]
    m = read_measurements(DATA / "test_rectangle.csv")
    env = {f"q{i + 1}": m.q_deg[:, i] for i in range(6)}
    values = np.column_stack([eval(line.split("=", 1)[1].replace("^", "**"), {}, env) for line in lines])  # noqa: S307
    np.testing.assert_allclose(values, load_predictor(joint_model).predict(joints=m.q_deg), rtol=0, atol=1e-6)


def foreign(path, header, rows):
    """A file the way a tracker exports it: semicolons and decimal commas."""
    path.write_text(";".join(header) + "\n" + "\n".join(";".join(repr(float(v)).replace(".", ",") for v in r)
                                                        for r in rows) + "\n")
    return path


FORMAT = """delimiter: ";"
decimal: ","
columns: {q1: a1, q2: a2, q3: a3, q4: a4, q5: a5, q6: a6, x_meas: mx, y_meas: my, z_meas: mz,
          x_nom: nx, y_nom: ny, z_nom: nz}
joint_unit: rad
length_unit: m
"""


def test_import_converts_a_foreign_file_to_the_contract(tmp_path):
    from partcal import read_measurements

    m = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
    header = ["stamp", "a1", "a2", "a3", "a4", "a5", "a6", "nx", "ny", "nz", "mx", "my", "mz"]
    rows = np.column_stack([np.arange(len(m)), np.radians(m.q_deg), m.nominal_mm / 1000, m.measured_mm / 1000])
    src = foreign(tmp_path / "export.csv", header, rows)
    (tmp_path / "fmt.yaml").write_text(FORMAT)
    res = run("import", str(src), "--format", str(tmp_path / "fmt.yaml"), "-o", str(tmp_path / "out.csv"),
              "--rows", "2-85", "--every", "3")
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("wrote 28 poses to")
    back = read_measurements(tmp_path / "out.csv")
    np.testing.assert_allclose(back.q_deg, m.q_deg[1::3], atol=1e-6)
    np.testing.assert_allclose(back.nominal_mm, m.nominal_mm[1::3], atol=1e-6)
    np.testing.assert_allclose(back.measured_mm, m.measured_mm[1::3], atol=1e-6)


def test_import_registers_a_tracker_file(tmp_path):
    from scipy.spatial.transform import Rotation

    from partcal import load_robot, read_measurements

    robot = load_robot("motoman_sk120")
    rng = np.random.default_rng(5)
    q = rng.uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], (30, 6))
    tool = np.array([200.0, 10.0, 120.0])
    truth = robot.replace(tool_mm=tool).positions(q)                  # an error-free robot
    rot, t = Rotation.from_rotvec([0.5, 1.0, -2.0]).as_matrix(), np.array([4000.0, 500.0, -300.0])
    header = ["a1", "a2", "a3", "a4", "a5", "a6", "mx", "my", "mz"]
    src = foreign(tmp_path / "tracker.csv", header, np.column_stack([np.radians(q), (truth - t) @ rot / 1000]))
    (tmp_path / "fmt.yaml").write_text(FORMAT.replace(",\n          x_nom: nx, y_nom: ny, z_nom: nz", ""))
    args = ["import", str(src), "--format", str(tmp_path / "fmt.yaml"), "-o", str(tmp_path / "base.csv")]
    res = run(*args, "--robot", "motoman_sk120", "--frame", "tracker")
    assert res.returncode == 0, res.stderr
    assert "tracker registration: 30 poses, residual 3-D RMS 0.000 mm" in res.stdout
    assert "tool [200.000, 10.000, 120.000] mm (fitted)" in res.stdout
    back = read_measurements(tmp_path / "base.csv")
    np.testing.assert_allclose(back.measured_mm, truth, atol=2e-6)
    np.testing.assert_allclose(back.nominal_mm, truth, atol=2e-6)
    assert "tracker frame registered on this set" in (tmp_path / "base.csv").read_text()
    res = run(*args, "--robot", "motoman_sk120", "--frame", "tracker", "--tool-mm", "200", "10", "130")
    assert res.returncode == 0 and "(given)" in res.stdout and "residual 3-D RMS 0.000" not in res.stdout
    for extra, message in [((), "--frame tracker needs --robot"),
                           (("--robot", "motoman_sk120", "--rows", "1-3"), "tracker.csv: a tracker registration with "
                                                                             "the tool needs at least 4 poses"),
                           (("--robot", "motoman_sk120", "--rows", "1-40"), "tracker.csv: rows '1-40' asks for data "
                                                                              "row 40, but the file has 30 data rows")]:
        res = run(*args, "--frame", "tracker", *extra)
        assert res.returncode == 2 and res.stderr.count("\n") == 1 and message in res.stderr, res.stderr
    res = run("import", str(src), "--format", str(tmp_path / "fmt.yaml"))
    assert res.returncode == 2 and "import: give the CSV to write with -o OUT.csv" in res.stderr
    res = run("import", "-o", str(tmp_path / "x.csv"))
    assert res.returncode == 2 and "give either an input file or --config RUN.yaml" in res.stderr
    res = run("import", str(src), "-o", str(tmp_path / "x.csv"))             # forgot the format
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "tracker.csv:1: the header is one column containing ';'" in res.stderr


@pytest.fixture(scope="module")
def cartesian_model(tmp_path_factory):
    from partcal import ErrorModel, load_robot
    from partcal.study.persist import save_model

    m = read_measurements(DATA / "identification.csv")
    path = tmp_path_factory.mktemp("model") / "sdp-ci.json"
    save_model(ErrorModel(degree=2, solver="lstsq").fit(m.nominal_mm, m.errors_mm), path,
               robot=load_robot("motoman_sk120"))
    return path


def test_a_cartesian_target_beyond_the_arms_reach_is_not_converged(cartesian_model, tmp_path):
    # the fixed-point iteration converges on any target; the robot in the file says 10 m is out of reach
    m = read_measurements(DATA / "test_rectangle.csv")
    targets = tmp_path / "t.csv"
    targets.write_text("x,y,z\n" + ",".join(f"{v:.6f}" for v in m.nominal_mm[0]) + "\n10000,0,0\n")
    res = run("compensate", str(cartesian_model), str(targets), "-o", str(tmp_path / "c.csv"))
    assert res.returncode == 3 and "1 of 2 targets did not converge or are unreachable (first: data row 2" in res.stderr
    with open(tmp_path / "c.csv") as handle:
        assert [r["converged"] for r in csv.DictReader(handle)] == ["true", "false"]


@pytest.mark.parametrize("args, message", [
    (["equations", "MODEL", "--digits", "-1"], "partcal equations: argument --digits: expected a whole number >= 1; got '-1'"),
    (["import", "a.csv", "--tool-mm", "0", "0", "abc"], "partcal import: argument --tool-mm: invalid float value: 'abc'"),
    (["import", "a.csv", "--every", "0"], "partcal import: argument --every: expected a whole number >= 1; got '0'"),
    (["predict", "MODEL", "IN.csv", "-o", "newdir/"], "newdir/: is a folder; give the name of a file to write"),
    (["import", "a.csv", "-o", "b.csv", "--tool-mm", "1", "2", "3"], "import: --tool-mm is the target offset of a "
                                                                     "tracker registration; it needs --frame tracker"),
])
def test_command_line_mistakes_get_one_line(cartesian_model, tmp_path, args, message):
    points = tmp_path / "IN.csv"
    points.write_text("x,y,z\n1000,0,500\n")
    args = [str(cartesian_model) if a == "MODEL" else str(points) if a == "IN.csv" else a for a in args]
    res = run(*args, cwd=tmp_path)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and message in res.stderr, res.stderr
    assert not (tmp_path / "newdir").exists()


def test_validation_set_with_converted_data_runs_and_imports(tmp_path):
    """A held-out validation set in a run whose data are converted (a row subset) used to crash after fitting."""
    cfg = tmp_path / "configs" / "v.yaml"
    cfg.parent.mkdir()
    cfg.write_text(f"""name: v
data:
  identification: {{file: {DATA / 'identification.csv'}, rows: "1-80"}}
  validation: {DATA / 'test_rectangle.csv'}
  tests: {{spiral: {DATA / 'test_spiral_xy.csv'}}}
rank_by: validation
models:
  - {{name: FDP(CI), solver: {{method: lstsq}}}}
""")
    res = run("import", "--config", str(cfg), "-o", str(tmp_path / "conv"))
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in (tmp_path / "conv").iterdir()) == [".partcal-output", "identification.csv", "spiral.csv",
                                                                     "validation.csv"]
    assert len(read_measurements(tmp_path / "conv" / "identification.csv")) == 80
    res = run("run", str(cfg), "-q")
    assert res.returncode == 0, res.stderr
    out = tmp_path / "reports" / "v"
    assert (out / "data" / "validation.csv").is_file() and (out / "metrics.json").is_file()


def test_import_config_writes_the_registered_robot_so_the_converted_data_run_again(tmp_path):
    from scipy.spatial.transform import Rotation

    rot, t = Rotation.from_rotvec([0.3, -1.2, 0.8]).as_matrix(), np.array([2500.0, -900.0, 400.0])
    files = {}
    for name in ("identification", "test_rectangle"):        # the SK120's data as seen from a tracker
        m = read_measurements(DATA / f"{name}.csv")
        files[name] = tmp_path / f"{name}_tracker.csv"
        files[name].write_text("q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas\n" + "\n".join(
            ",".join(repr(float(v)) for v in np.r_[q, p]) for q, p in zip(m.q_deg, (m.measured_mm - t) @ rot)) + "\n")
    models = "models:\n  - {name: FDP(CI), degree: 1, solver: {method: lstsq}}\n"
    original = tmp_path / "tracked.yaml"
    original.write_text(f"name: tracked\nrobot: motoman_sk120\ncv_folds: 3\ndata:\n  frame: tracker\n"
                        f"  identification: {files['identification']}\n"
                        f"  tests: {{rectangle: {files['test_rectangle']}}}\n{models}output: {tmp_path / 'a'}\n")
    res = run("import", "--config", str(original), "-o", str(tmp_path / "conv"))
    assert res.returncode == 0, res.stderr
    robot_file = tmp_path / "conv" / "robot.yaml"
    assert f"robot (tool offset included): {robot_file}" in res.stdout
    assert sorted(p.name for p in (tmp_path / "conv").iterdir()) == [".partcal-output", "identification.csv",
                                                                     "rectangle.csv", "robot.yaml"]
    again = tmp_path / "again.yaml"
    for robot, code in (("motoman_sk120", 2), (robot_file, 0)):    # the built-in robot lacks the registered tool
        again.write_text(f"name: again\nrobot: {robot}\ncv_folds: 3\ndata:\n"
                         f"  identification: {tmp_path / 'conv' / 'identification.csv'}\n"
                         f"  tests: {{rectangle: {tmp_path / 'conv' / 'rectangle.csv'}}}\n{models}"
                         f"output: {tmp_path / 'b'}\n")
        res = run("run", "-q", str(again))
        assert res.returncode == code, res.stderr
    assert run("run", "-q", str(original)).returncode == 0
    before, after = (json.loads((tmp_path / o / "metrics.json").read_text())["uncompensated"] for o in "ab")
    for name in ("identification", "rectangle"):
        np.testing.assert_allclose([after[name][k] for k in ("rms_3d", "max_3d", "p95_3d")] + after[name]["rms"],
                                   [before[name][k] for k in ("rms_3d", "max_3d", "p95_3d")] + before[name]["rms"],
                                   atol=1e-5, err_msg=name)


def test_a_run_never_replaces_a_folder_holding_its_inputs_or_files_partcal_did_not_write(tmp_path):
    """``output: .`` beside the config used to delete the config and the data (the folder is replaced whole)."""
    home = tmp_path / "study"
    home.mkdir()
    shutil.copy(DATA / "identification.csv", home)
    config = home / "cfg.yaml"
    body = "name: s\ndata:\n  identification: identification.csv\nmodels:\n  - {name: A, solver: {method: lstsq}}\n"
    config.write_text(body + "output: .\n")
    for check in ([], ["--check"]):
        res = run("run", *check, str(config))
        assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
        assert f"{home}: holds {config}, an input of this run" in res.stderr
    assert sorted(p.name for p in home.iterdir()) == ["cfg.yaml", "identification.csv"]

    mine = tmp_path / "mine"
    (mine / "notes").mkdir(parents=True)
    (mine / "thesis.tex").write_text("chapter 1\n")
    config.write_text(body + f"output: {mine}\n")
    res = run("run", str(config))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert f"{mine}: exists and holds files partcal did not write (notes, thesis.tex)" in res.stderr
    assert (mine / "thesis.tex").read_text() == "chapter 1\n"

    (tmp_path / "file.txt").write_text("x\n")
    for where, message in ((tmp_path / "file.txt", "exists and is not a folder"),
                           (tmp_path / "file.txt" / "sub", "cannot write the output folder here (Not a directory)")):
        config.write_text(body + f"output: {where}\n")
        res = run("run", "--check", str(config))               # --check looks at the output folder too
        assert res.returncode == 2 and f"{where}: {message}" in res.stderr, res.stderr

    out = tmp_path / "out"
    config.write_text(body + f"output: {out}\n")
    for _ in range(2):                      # partcal's own output (marked) is replaced by the next run
        res = run("run", "-q", str(config))
        assert res.returncode == 0, res.stderr
    assert (out / ".partcal-output").is_file() and (out / "metrics.json").is_file()
    (out / ".partcal-output").unlink()      # a run of a version before the marker: still partcal's own
    assert run("run", "-q", str(config)).returncode == 0


def test_a_full_disk_gets_one_line_not_a_traceback(monkeypatch, capsys):
    """An OSError from the machine (here ENOSPC while writing) used to print a 23-line traceback."""
    import errno

    from partcal import cli

    def full(args):
        raise OSError(errno.ENOSPC, "No space left on device", "reports/x/.x.partial-1/metrics.json")

    monkeypatch.setattr(cli, "_cmd_run", full)
    assert cli.main(["run", "any.yaml"]) == 1
    err = capsys.readouterr().err
    assert err == ("partcal: error: reports/x/.x.partial-1/metrics.json: No space left on device; "
                   "nothing was replaced\n")


UR10_EXPORT = SHARED / "datasets" / "ipa_ur10" / "Series_B" / "measurements_joint_configurations.csv"
UR10_FORMAT = """delimiter: ";"
decimal: ","
columns: {q1: shoulder_pan_joint, q2: shoulder_lift_joint, q3: elbow_joint, q4: wrist_1_joint, q5: wrist_2_joint,
          q6: wrist_3_joint, x_meas: measurement_x, y_meas: measurement_y, z_meas: measurement_z}
joint_unit: rad
"""


@pytest.fixture
def ur10_export(tmp_path):
    """A copy of the UR10 tracker export (series B) and its format: the shared file is never an output."""
    if not UR10_EXPORT.is_file():
        pytest.skip("the IPA UR10 data set is not beside the repository")
    export = tmp_path / "EXPORT.csv"
    shutil.copy(UR10_EXPORT, export)
    (tmp_path / "F.yaml").write_text(UR10_FORMAT)
    return export, tmp_path / "F.yaml"


def test_import_registers_every_target_and_the_orientation(tmp_path):
    from scipy.spatial.transform import Rotation

    from partcal import load_robot

    robot = load_robot("universal_robots_ur10")
    q = np.random.default_rng(6).uniform(-170, 170, (25, 6))
    tools = {"A": [0.0, 0.0, 120.0], "B": [100.0, 0.0, 90.0]}
    rot, t = Rotation.from_rotvec([0.2, -0.4, 1.5]).as_matrix(), np.array([2500.0, 300.0, -200.0])
    seen = {k: (robot.replace(tool_mm=np.array(v)).positions(q) - t) @ rot for k, v in tools.items()}
    turns = Rotation.from_matrix(rot.T @ robot.forward(q)[:, :3, :3]).as_euler("XYZ", degrees=True)
    header = "q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas,x_meas@B,y_meas@B,z_meas@B,rx_meas,ry_meas,rz_meas"
    rows = np.column_stack([q, seen["A"], seen["B"], turns])
    (tmp_path / "t.csv").write_text(header + "\n" + "\n".join(",".join(f"{v:.9f}" for v in r) for r in rows) + "\n")
    res = run("import", str(tmp_path / "t.csv"), "-o", str(tmp_path / "base.csv"), "--robot", "universal_robots_ur10",
              "--frame", "tracker")
    assert res.returncode == 0, res.stderr
    assert "per target RMS A 0.000, B 0.000 mm; orientation RMS 0.0000 deg" in res.stdout
    back = read_measurements(tmp_path / "base.csv")
    np.testing.assert_allclose(back.measured_of("B") - back.nominal_of("B"), 0, atol=1e-5)
    np.testing.assert_allclose(back.orientation_errors_deg, 0, atol=1e-6)
    written = re.search(r"tool@B \[([^\]]*)\] mm", (tmp_path / "base.csv").read_text())
    np.testing.assert_allclose([float(v) for v in written.group(1).split(",")], tools["B"], atol=2e-6)
    (tmp_path / "bad.csv").write_text(header.replace(",z_meas@B", "") + "\n" + "1," * 13 + "1\n")
    res = run("import", str(tmp_path / "bad.csv"), "-o", str(tmp_path / "x.csv"), "--robot", "universal_robots_ur10",
              "--frame", "tracker")
    assert res.returncode == 2 and res.stderr.strip() == (f"partcal: error: {tmp_path / 'bad.csv'}:1: column "
                                                          "'z_meas@B' is missing (target B needs all of x_meas@B, "
                                                          "y_meas@B, z_meas@B)")


def test_import_never_writes_over_its_own_input_or_format(ur10_export):
    export, fmt = ur10_export
    before = export.read_bytes()
    common = ["--robot", "universal_robots_ur10", "--frame", "tracker", "--rows", "1-200"]
    for target, what in ((export, "input file"), (fmt, "format file")):
        kept = target.read_bytes()
        res = run("import", str(export), "--format", str(fmt), *common, "-o", str(target))
        assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
        assert f"import: -o {target} is the {what} ({target})" in res.stderr
        assert target.read_bytes() == kept
    (export.parent / "link.csv").symlink_to(export)            # the same file by another name
    res = run("import", str(export), "--format", str(fmt), *common, "-o", str(export.parent / "link.csv"))
    assert res.returncode == 2 and "is the input file" in res.stderr, res.stderr
    assert export.read_bytes() == before
    res = run("import", str(export), "--format", str(fmt), *common, "-o", str(export.parent / "new.csv"))
    assert res.returncode == 0, res.stderr
    assert len(read_measurements(export.parent / "new.csv")) == 200


@pytest.mark.parametrize("command, target, what", [
    ("predict", "MODEL", "model file"), ("predict", "IN", "input file"), ("predict", "FMT", "format file"),
    ("compensate", "MODEL", "model file"), ("compensate", "IN", "targets file"), ("compensate", "FMT", "format file"),
])
def test_predict_and_compensate_never_write_over_an_input(cartesian_model, tmp_path, command, target, what):
    model = tmp_path / "m.json"
    shutil.copy(cartesian_model, model)
    points = tmp_path / "rect.csv"
    points.write_text("x,y,z\n1000,0,500\n")
    fmt = tmp_path / "fmt.yaml"
    fmt.write_text("delimiter: ','\n")
    paths = {"MODEL": model, "IN": points, "FMT": fmt}
    kept = paths[target].read_bytes()
    res = run(command, str(model), str(points), "--format", str(fmt), "-o", str(paths[target]))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert f"{command}: -o {paths[target]} is the {what}" in res.stderr
    assert paths[target].read_bytes() == kept


def test_import_config_never_writes_over_its_config(tmp_path):
    config = tmp_path / "c.yaml"
    config.write_text(f"name: c\ndata:\n  identification: {DATA / 'identification.csv'}\n"
                      "models:\n  - {name: A, solver: {method: lstsq}}\n")
    kept = config.read_bytes()
    res = run("import", "--config", str(config), "-o", str(config))
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and f"-o {config} is the run config" in res.stderr
    assert config.read_bytes() == kept


def test_a_rerun_refuses_files_added_to_an_earlier_output_and_replaces_its_own(tmp_path):
    config = tmp_path / "configs" / "c.yaml"
    config.parent.mkdir()
    out = tmp_path / "out"
    config.write_text(f"name: c\ndata:\n  identification: {DATA / 'identification.csv'}\n"
                      f"models:\n  - {{name: A, solver: {{method: lstsq}}}}\noutput: {out}\n")
    assert run("run", "-q", str(config)).returncode == 0
    (out / "NOTES.txt").write_text("tracker moved on Tuesday\n")
    (out / "raw").mkdir()
    (out / "raw" / "export.csv").write_text("1,2,3\n")
    (out / "models" / "mine.json").write_text("{}\n")
    for check in ([], ["--check"]):
        res = run("run", "-q", *check, str(config))
        assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
        assert f"{out}: exists and holds files partcal did not write (NOTES.txt, models/mine.json, raw)" in res.stderr
    assert (out / "NOTES.txt").read_text() == "tracker moved on Tuesday\n"
    assert (out / "raw" / "export.csv").read_text() == "1,2,3\n" and (out / "models" / "mine.json").is_file()
    for added in (out / "NOTES.txt", out / "raw" / "export.csv", out / "models" / "mine.json"):
        added.unlink()
    (out / "raw").rmdir()
    (out / "metrics.json").write_text("{}\n")       # partcal's own files, even changed, are replaced by a rerun
    res = run("run", "-q", str(config))
    assert res.returncode == 0, res.stderr
    assert json.loads((out / "metrics.json").read_text())["name"] == "c"
    listed = (out / ".partcal-output").read_text().splitlines()[1:]
    assert sorted(listed) == sorted(f"- {p.relative_to(out)}" for p in out.rglob("*")
                                    if p.is_file() and p.name != ".partcal-output")


@pytest.fixture(scope="module")
def ur10_models(tmp_path_factory):
    """A Cartesian and a joint model of the UR10 (errors of a millimetre per metre), with the robot in the files."""
    from partcal import ErrorModel, load_robot
    from partcal.study.persist import save_model

    ur10 = load_robot("universal_robots_ur10")
    q = np.random.default_rng(0).uniform(ur10.limits_deg[:, 0], ur10.limits_deg[:, 1], (200, 6))
    p = ur10.positions(q)
    e = 1e-3 * p[:, [1, 2, 0]]
    tmp = tmp_path_factory.mktemp("ur10")
    save_model(ErrorModel(degree=1, solver="lstsq").fit(p, e), tmp / "ci.json", robot=ur10)
    save_model(ErrorModel(inputs="joint", degree=1, solver="lstsq").fit(q, e), tmp / "ai.json", robot=ur10)
    return tmp / "ci.json", tmp / "ai.json"


@pytest.mark.parametrize("kind", [0, 1])
def test_targets_the_ur10_cannot_reach_exit_3_for_every_model_kind(ur10_models, tmp_path, kind):
    from partcal import load_robot

    ur10 = load_robot("universal_robots_ur10")
    reachable = ur10.positions(np.array([[30.0, -60, 80, -90, -90, 0]]))[0]
    targets = tmp_path / "t.csv"
    targets.write_text("x,y,z\n0,0,0\n1480,0,0\n" + ",".join(f"{v:.6f}" for v in reachable) + "\n")
    res = run("compensate", str(ur10_models[kind]), str(targets), "-o", str(tmp_path / "c.csv"))
    assert res.returncode == 3 and res.stderr.count("\n") == 1, res.stderr
    assert "2 of 3 targets did not converge or are unreachable (first: data row 1 of" in res.stderr
    with open(tmp_path / "c.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["converged"] for r in rows] == ["false", "false", "true"]
    assert [r["reason"] for r in rows] == ["out of reach", "out of reach", ""]


@pytest.mark.parametrize("inputs", ["cartesian", "joint"])
def test_the_ur10_base_origin_is_reached_with_a_long_enough_tool(tmp_path, inputs):
    """The bare flange stays 72 mm from the base origin (exit 3 above); a 150 mm tool folds onto it."""
    from partcal import ErrorModel, load_robot
    from partcal.study.persist import save_model

    ur10 = load_robot("universal_robots_ur10").replace(tool_mm=np.array([0.0, 0.0, 150.0]))
    q = np.random.default_rng(0).uniform(ur10.limits_deg[:, 0], ur10.limits_deg[:, 1], (200, 6))
    p = ur10.positions(q)
    save_model(ErrorModel(inputs=inputs, degree=1, solver="lstsq").fit(q if inputs == "joint" else p,
                                                                        1e-3 * p[:, [1, 2, 0]]),
               tmp_path / "m.json", robot=ur10)
    (tmp_path / "t.csv").write_text("x,y,z\n0,0,0\n")
    res = run("compensate", str(tmp_path / "m.json"), str(tmp_path / "t.csv"), "-o", str(tmp_path / "c.csv"))
    assert res.returncode == 0, res.stderr
    with open(tmp_path / "c.csv") as handle:
        row = next(csv.DictReader(handle))
    assert row["converged"] == "true" and row["reason"] == "" and float(row["miss_mm"]) <= 1e-4


def test_absurd_inputs_are_refused_in_one_line_without_numpy_warnings(cartesian_model, joint_model, tmp_path):
    points = tmp_path / "p.csv"
    points.write_text("x,y,z\n1000,0,500\n1e200,0,0\n1e300,1e300,1e300\n")
    out = tmp_path / "o.csv"
    res = run("predict", str(cartesian_model), str(points), "-o", str(out))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert f"{points}: data row 2: the predicted error is not finite (2 of 3 rows); the input [1e+200, 0, 0]" \
        in res.stderr and res.stderr.endswith("nothing written\n")
    assert "Warning" not in res.stderr and not out.exists()
    from partcal import load_predictor

    size = np.linalg.norm(load_predictor(cartesian_model).predict(positions=[[60000.0, 0, 0]]))
    assert size > 4413.2                                                     # the SK120's reach (every link out)
    points.write_text("x,y,z\n1000,0,500\n60000,0,0\n")
    res = run("predict", str(cartesian_model), str(points), "-o", str(out))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert (f"data row 2: the predicted error is {size:.4g} mm, more than robot motoman_sk120's reach (4413 mm) "
            "(1 of 2 rows)") in res.stderr and not out.exists()
    points.write_text("x,y,z\n1000,0,500\n1e200,0,0\n1e300,1e300,1e300\n")
    res = run("compensate", str(cartesian_model), str(points), "-o", str(out))
    assert res.returncode == 3 and res.stderr.count("\n") == 1 and "Warning" not in res.stderr, res.stderr
    assert "2 of 3 targets did not converge or are unreachable (first: data row 2" in res.stderr
    joints = tmp_path / "q.csv"
    joints.write_text("q1,q2,q3,q4,q5,q6\n0,-120,-170,0,0,0\n1e200,-120,-170,0,0,0\n")
    res = run("predict", str(joint_model), str(joints), "-o", str(out))
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "Warning" not in res.stderr, res.stderr
    assert f"{joints}: data row 2: the predicted error is not finite (1 of 2 rows)" in res.stderr


def test_the_extrapolation_warning_names_the_farthest_point(cartesian_model, tmp_path):
    m = read_measurements(DATA / "identification.csv")
    points = tmp_path / "p.csv"
    rows = [m.nominal_mm[0], m.nominal_mm[1] + [0, 0, -300], m.nominal_mm[2] + [0, 0, -200]]
    points.write_text("x,y,z\n" + "\n".join(",".join(f"{v:.6f}" for v in r) for r in rows) + "\n")
    from partcal import load_predictor

    far = load_predictor(cartesian_model).distance_to_data(positions=np.array(rows))
    res = run("predict", str(cartesian_model), str(points), "-o", str(tmp_path / "o.csv"))
    assert res.returncode == 0, res.stderr
    assert res.stderr == (f"partcal: warning: 2 of 3 points lie more than 50 mm from the data the model was fitted on "
                          f"(the farthest, data row 2, {far[1]:.4g} mm)\n")


def test_compensate_reads_the_nominal_columns_of_a_measurement_csv(cartesian_model, tmp_path):
    from partcal import load_predictor

    res = run("compensate", str(cartesian_model), str(DATA / "identification.csv"), "-o", str(tmp_path / "c.csv"))
    assert res.returncode == 0, res.stderr
    with open(tmp_path / "c.csv") as handle:
        rows = list(csv.DictReader(handle))
    m = read_measurements(DATA / "identification.csv")
    assert list(rows[0])[:3] == ["x_nom", "y_nom", "z_nom"] and len(rows) == 85
    cmd = np.array([[float(r[k]) for k in ("x_cmd", "y_cmd", "z_cmd")] for r in rows])
    np.testing.assert_allclose(cmd + load_predictor(cartesian_model).predict(positions=cmd), m.nominal_mm, atol=2e-4)


def test_orientation_targets_with_a_position_model_are_refused_and_nothing_written(cartesian_model, tmp_path):
    targets = tmp_path / "t.csv"
    targets.write_text("x,y,z,rx,ry,rz\n1000,0,500,180,0,90\n")
    out = tmp_path / "c.csv"
    res = run("compensate", str(cartesian_model), str(targets), "-o", str(out))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert (f"compensate: {targets} has the orientation columns rx, ry, rz, but {cartesian_model} predicts position "
            "errors only (3 outputs): fit a pose model ('predict: pose' in the run config)") in res.stderr
    assert not out.exists()


def test_screenshot_without_a_browser_is_refused_before_fitting(tmp_path):
    import subprocess
    import sys

    config = tmp_path / "configs" / "c.yaml"
    config.parent.mkdir()
    config.write_text(f"name: c\ndata:\n  identification: {DATA / 'identification.csv'}\n"
                      "models:\n  - {name: A, solver: {method: lstsq}}\n")
    res = subprocess.run([sys.executable, "-m", "partcal", "run", "--screenshot", str(config)], capture_output=True,
                         text=True, env={"PATH": str(tmp_path)})           # no chromium on this PATH
    assert res.returncode == 2 and res.stderr == ("partcal: error: no chromium found: install the Debian package "
                                                  "'chromium' for screenshots\n"), res.stderr
    assert not (tmp_path / "reports").exists()


def test_a_run_warns_in_one_format_once_and_progress_has_its_own_lines(tmp_path, capsys):
    from partcal.cli import main

    config = tmp_path / "configs" / "c.yaml"
    config.parent.mkdir()
    config.write_text(f"name: c\ndata:\n  identification: {DATA / 'identification.csv'}\n  tests:\n"
                      f"    a: {DATA / 'test_rectangle.csv'}\n"
                      "models:\n  - {name: Oct, solver: {method: lstsq}, partition: {method: octree, max_depth: 2}}\n")
    assert main(["run", str(config)]) == 0
    err = capsys.readouterr().err.splitlines()
    warned = [line for line in err if "regions, but on the cross-validation folds" in line]
    assert len(warned) == 1 and warned[0].startswith("partcal: warning: Oct: fitted on all the identification data")
    progress = [line for line in err if line.startswith("partcal: [1/1] Oct: CV RMS")]
    assert len(progress) == 1 and ", cross-validated in " in progress[0]


def test_program_and_parametrization_choices_are_read_from_their_tables(monkeypatch, capsys):
    """--program takes the names of the dialect table and --parametrization 'auto' and the names of the
    parametrization table: a row added to a table is a choice, and a refusal lists the table."""
    from partcal.cli import build_parser
    from partcal.data import programs
    from partcal.calibration import parameters as identification

    monkeypatch.setitem(programs.DIALECTS, "toy", programs.DIALECTS["krl"])
    monkeypatch.setitem(identification.PARAMETRIZATIONS, "toy", identification.PARAMETRIZATIONS["dh"])
    parser = build_parser()
    for name in programs.DIALECTS:
        assert parser.parse_args(["compensate", "m.json", "p.src", "-o", "o", "--program", name]).program == name
    for name in ("auto", *identification.PARAMETRIZATIONS):
        assert parser.parse_args(["plan", "ur10", "--parametrization", name]).parametrization == name
    with pytest.raises(SystemExit) as stop:
        parser.parse_args(["compensate", "m.json", "p.src", "-o", "o", "--program", "vb6"])
    assert stop.value.code == 2
    assert capsys.readouterr().err == (
        "partcal: error: partcal compensate: argument --program: invalid choice: 'vb6' (choose from 'urscript', "
        "'krl', 'rapid', 'joints', 'toy') (see 'partcal compensate --help')\n")
    with pytest.raises(SystemExit):
        parser.parse_args(["plan", "ur10", "--parametrization", "mdh"])
    assert "(choose from 'auto', 'dh', 'complete', 'toy')" in capsys.readouterr().err


def test_predict_and_compensate_are_one_call_each_from_python(tmp_path):
    """partcal.study's predict_points and compensate_file write what the commands write, and say it in their
    Outcome; the predicted errors are the predictor's."""
    from partcal import load_predictor
    from partcal.study import compensate_file, predict_points

    model, data = ROOT / "tests" / "fixtures" / "v0.1_sdp-ci.json", DATA / "test_rectangle.csv"
    nominal = read_measurements(data).nominal_mm
    for command, call, columns in (("predict", predict_points, ["dx", "dy", "dz"]),
                                   ("compensate", compensate_file, ["x_cmd", "y_cmd", "z_cmd"])):
        res = run(command, str(model), str(data), "-o", str(tmp_path / f"{command}_cli.csv"))
        done = call(model, data, tmp_path / f"{command}_py.csv")
        assert res.returncode == 0 and res.stderr == "", res.stderr
        assert (tmp_path / f"{command}_py.csv").read_bytes() == (tmp_path / f"{command}_cli.csv").read_bytes()
        assert done.n == len(nominal) and done.failure == "" and done.warnings == ()
        assert res.stdout == "\n".join(done.lines).replace("_py.csv", "_cli.csv") + "\n"
        with open(tmp_path / f"{command}_py.csv") as handle:
            written = np.array([[float(r[c]) for c in columns] for r in csv.DictReader(handle)])
        if command == "predict":
            np.testing.assert_allclose(written, load_predictor(model).predict(positions=nominal), atol=5e-7)
        else:
            np.testing.assert_allclose(written + load_predictor(model).predict(positions=written), nominal,
                                       atol=1e-3)


def test_a_terminated_run_exits_143_and_leaves_no_half_written_output(tmp_path):
    """SIGTERM (a scheduler or a cell controller stopping a run) while a run works: exit 143, and no hidden
    temporary file or folder beside the outputs, wherever in the run the signal lands."""
    import signal
    import subprocess
    import sys
    import time

    cfg = tmp_path / "configs" / "t.yaml"
    cfg.parent.mkdir()
    cfg.write_text(f"""name: t
data:
  identification: {DATA / 'identification.csv'}
  tests: {{rectangle: {DATA / 'test_rectangle.csv'}}}
models:
  - {{name: GP(AI), kind: gaussian_process, inputs: joint}}
  - {{name: SDP(AI), inputs: joint, degree: 2}}
""")
    child = subprocess.Popen([sys.executable, "-m", "partcal", "run", str(cfg)], stderr=subprocess.PIPE, text=True)
    child.stderr.readline()                       # the run has started (its handler is set before any line)
    time.sleep(0.2)
    child.send_signal(signal.SIGTERM)
    assert child.wait(timeout=60) == 143
    hidden = [p for p in tmp_path.rglob(".*") if p.name != ".partcal-output"]
    assert hidden == []


def test_an_unknown_option_is_refused_by_the_parser_it_belongs_to_naming_partcal_once():
    res = run("-q", "run", "configs/paper_sk120.yaml")
    assert res.returncode == 2
    assert res.stderr == "partcal: error: unrecognized arguments: -q (see 'partcal --help')\n"
    res = run("equations", "model.json", "--bogus")
    assert res.returncode == 2
    assert res.stderr == ("partcal: error: partcal equations: unrecognized arguments: --bogus "
                          "(see 'partcal equations --help')\n")


def test_import_names_its_rows_option_when_the_rows_are_bad(tmp_path):
    res = run("import", str(DATA / "identification.csv"), "-o", str(tmp_path / "o.csv"), "--rows", "5-2")
    assert res.returncode == 2 and not (tmp_path / "o.csv").exists()
    assert res.stderr == ("partcal: error: import: --rows '5-2': expected data rows such as '1-600' or "
                          "'1-100, 201-300' (1-based, increasing, not overlapping)\n")


@pytest.mark.parametrize("command", ["run", "simulate"])
def test_a_csv_given_for_a_config_is_named_as_such(command):
    res = run(command, str(DATA / "identification.csv"))
    assert res.returncode == 2 and res.stderr.count("\n") == 1
    assert res.stderr.startswith(f"partcal: error: {DATA / 'identification.csv'}: top level (line ")
    assert res.stderr.rstrip().endswith("expected a mapping, got a text: is it a YAML config? (a CSV or another "
                                        "file given where a config is expected)")
