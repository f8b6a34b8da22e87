"""The command line: exit codes and messages."""

import shutil
import subprocess
import sys

import numpy as np
from conftest import ROOT

import partcal


def run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "partcal", *args], capture_output=True, text=True, cwd=cwd)


def test_version():
    res = run("--version")
    assert res.returncode == 0 and res.stdout.strip() == f"partcal {partcal.__version__}"


def test_simulate_prints_table_and_writes_files(tmp_path):
    cfg = tmp_path / "configs"
    cfg.mkdir()
    shutil.copy(ROOT / "configs" / "sk120_virtual.yaml", cfg / "sk120_virtual.yaml")
    res = run("simulate", str(cfg / "sk120_virtual.yaml"))
    assert res.returncode == 0, res.stderr
    assert "identification" in res.stdout and "8.0 / 7.5 / 17.9" in res.stdout
    assert sorted(p.name for p in (tmp_path / "data" / "sk120").iterdir()) == [
        "identification.csv", "test_rectangle.csv", "test_spiral_xy.csv", "test_spiral_yz.csv"]


def test_bad_input_exits_2_with_one_line(tmp_path):
    res = run("simulate", str(tmp_path / "missing.yaml"))
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and "missing.yaml: no such file" in res.stderr
    assert "Traceback" not in res.stderr


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
