"""The command line: exit codes and messages."""

import shutil
import subprocess
import sys

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
