"""Batch-run YAML: defaults, paths, and one clear error per problem."""

from pathlib import Path

import pytest
from conftest import ROOT

from partcal import ConfigError
from partcal.study.config import load_config

DATA = ROOT / "data" / "sk120"
BASE = f"""name: demo
robot: motoman_sk120
data:
  identification: {DATA / 'identification.csv'}
  tests:
    rectangle: {DATA / 'test_rectangle.csv'}
models:
  - name: FDP(CI)
    degree: 1
    solver: {{method: pso, particles: 30, iterations: 50}}
  - name: SDP octree
    degree: 2
    solver: {{method: lstsq}}
    partition: {{method: octree, max_depth: [1, 2]}}
    blend: {{method: hard}}
"""


def write(tmp_path, text):
    path = tmp_path / "configs" / "run.yaml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(text)
    return path


def test_defaults_and_paths(tmp_path):
    cfg = load_config(write(tmp_path, BASE))
    assert cfg.seed == 0 and cfg.n_jobs == 1 and cfg.cv_folds == 5 and cfg.dask_address is None
    assert cfg.output == tmp_path / "reports" / "demo"               # reports/<name> beside configs/
    assert cfg.models[0].swarm == {"particles": 30, "iterations": 50}
    part = cfg.models[1].partition
    assert part.method == "octree" and part.sizes == (1, 2) and part.blend == "hard"
    assert cfg.models[1].slug == "sdp-octree"
    relative = write(tmp_path, BASE.replace(str(DATA / "identification.csv"), "../data.csv")
                     .replace("name: demo", "name: demo\noutput: ../out/here"))
    (tmp_path / "data.csv").write_text("x")
    cfg = load_config(relative)
    assert cfg.identification == tmp_path / "data.csv" and cfg.output == tmp_path / "out" / "here"


@pytest.mark.parametrize("old, new, message", [
    ("    degree: 2\n", "    degree: 0\n", r"models\[1\]\.degree \(line {line}\): must be an int in \[1, 8\]; got 0"),
    ("max_depth: [1, 2]", "max_depth: [1, 9]", r"models\[1\]\.partition\.max_depth \(line {line}\): must be an int in \[0, 8\]"),
    ("    degree: 1\n", "    degre: 1\n", r"models\[0\]\.degre \(line {line}\): unknown key; did you mean 'degree'\?"),
    ("particles: 30", "particles: many", r"models\[0\]\.solver\.particles \(line {line}\): must be an integer; got 'many'"),
    ("particles: 30", "particles: 1", r"models\[0\]\.solver \(line {line}\): The 'particles' parameter of SwarmConfig must be an int in \[2, 100000\]"),
    ("method: lstsq}", "method: lstsq, particles: 10}", r"models\[1\]\.solver\.particles \(line {line}\): applies to method: pso only"),
    ("name: SDP octree", "name: FDP(CI)", r"models\[1\]\.name \(line {line}\): duplicate model name 'FDP\(CI\)'"),
    ("robot: motoman_sk120", "robot: motoman_sk12", r"robot \(line {line}\): robot 'motoman_sk12': no such file, and not a built-in robot"),
    ("test_rectangle.csv", "missing.csv", r"data\.tests\.rectangle \(line {line}\): no such file: .*missing\.csv"),
    ("name: demo\n", "name: demo\nseed: -3\n", r"seed \(line {line}\): must be an int in \[0, 4294967295\]; got -3"),
    ("    rectangle:", "    cv:", r"data\.tests\.cv \(line {line}\): a test set may not be called 'cv' \(reserved: "),
])
def test_errors_name_path_and_line(tmp_path, old, new, message):
    text = BASE.replace(old, new, 1)
    pos = BASE.index(old)       # the edited line: where the replacement starts, plus lines it adds before
    line = BASE[:pos].count("\n") + 1 + new.rstrip("\n").count("\n")
    with pytest.raises(ConfigError, match=message.format(line=line)):
        load_config(write(tmp_path, text))


def test_broken_yaml_names_its_line(tmp_path):
    text = BASE.replace("  tests:\n", "  tests: [\n")
    with pytest.raises(ConfigError, match=r"run\.yaml \(line \d+\): not valid YAML"):
        load_config(write(tmp_path, text))


def test_shipped_configs_load():
    for name in ("paper_sk120.yaml", "partitioned_sk120.yaml"):
        cfg = load_config(ROOT / "configs" / name)
        assert cfg.output == ROOT / "reports" / cfg.name and cfg.virtual_robot is not None
    assert Path(ROOT / "configs" / "paper_sk120.yaml").exists()


KINDS = BASE.replace("models:\n", """models:
  - {name: DH + GP, kind: kinematic, rcond: 1.0e-8, residual: {kind: gaussian_process, inputs: joint,
                                                                partition: {method: kmeans, n_regions: [2, 4]}}}
  - {name: GP(AI), kind: gaussian_process, inputs: joint, kernel: matern, nu: 1.5, restarts: 0}
""")


def test_model_kinds(tmp_path):
    cfg = load_config(write(tmp_path, KINDS))
    hybrid, gp, series = cfg.models[0], cfg.models[1], cfg.models[2]
    assert (hybrid.kind, hybrid.inputs, hybrid.kinematic.rcond, hybrid.kinematic.robot) == (
        "kinematic", "joint", 1e-8, "motoman_sk120")
    assert hybrid.residual.kind == "gaussian_process" and hybrid.residual.name == "DH + GP residual"
    assert hybrid.sizes == (2, 4) and series.kind == "series" and series.sizes == ()
    assert (gp.gp.kernel, gp.gp.nu, gp.gp.restarts) == ("matern", 1.5, 0)
    model = hybrid.build(0, 4)
    assert model.residual.partition.n_regions == 4 and model.robot.name == "motoman_sk120"
    import yaml
    resolved = yaml.safe_load(yaml.safe_dump(cfg.resolved()))
    assert resolved["models"][0]["residual"]["partition"]["sizes"] == [2, 4]


@pytest.mark.parametrize("old, new, message", [
    ("kind: gaussian_process, inputs: joint, kernel", "kind: gaussian_process, degree: 2, kernel",
     r"models\[1\]\.degree \(line {line}\): applies to kind: series only; this entry is kind: gaussian_process"),
    ("kind: kinematic, rcond", "kind: kinematic, inputs: joint, rcond",
     r"models\[0\]\.inputs \(line {line}\): applies to kind: series or gaussian_process only; this entry is "
     r"kind: kinematic"),
    ("residual: {kind: gaussian_process", "residual: {name: x, kind: gaussian_process",
     r"models\[0\]\.residual\.name \(line {line}\): a residual model takes its name from its entry"),
    ("residual: {kind: gaussian_process", "residual: {kind: kinematic",
     r"models\[0\]\.residual\.kind \(line {line}\): a residual must be 'series' or 'gaussian_process'"),
    ("kind: gaussian_process, inputs: joint, kernel", "kind: gp, inputs: joint, kernel",
     r"models\[1\]\.kind \(line {line}\): must be one of 'series', 'gaussian_process', 'kinematic'; got 'gp'"),
    ("nu: 1.5", "nu: 2", r"models\[1\]\.nu \(line {line}\): must be 0\.5, 1\.5 or 2\.5; got 2\.0"),
    ("kernel: matern, nu: 1.5", "kernel: rbf, nu: 1.5", r"models\[1\]\.nu \(line {line}\): applies to kernel: "
                                                        r"matern only"),
    ("rcond: 1.0e-8", "rcond: 0", r"models\[0\]\.rcond \(line {line}\): must be a number in \(0, 1\]; got 0"),
    ("robot: motoman_sk120\n", "", r"models\[0\]\.kind \(line {line}\): kind: kinematic needs the run's robot"),
])
def test_model_kind_errors_name_path_and_line(tmp_path, old, new, message):
    text = KINDS.replace(old, new, 1)
    line = text[:text.index(new or "data:")].count("\n") + 1 if new else \
        text[:text.index("kind: kinematic")].count("\n") + 1
    with pytest.raises(ConfigError, match=message.format(line=line)):
        load_config(write(tmp_path, text))


def test_calibration_config_loads():
    cfg = load_config(ROOT / "configs" / "calibration_sk120.yaml")
    assert {m.kind for m in cfg.models} == {"series", "kinematic", "gaussian_process"}
    paper = load_config(ROOT / "configs" / "paper_sk120.yaml")
    assert [m.name for m in paper.models] == ["FDP(CI)", "FDP(AI)", "SDP(CI)", "SDP(AI)"]      # the paper's four
