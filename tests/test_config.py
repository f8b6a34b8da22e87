"""Batch-run YAML: defaults, paths, and one clear error per problem."""

import numpy as np
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
    assert cfg.seed == 0 and cfg.n_jobs == 1 and cfg.cv_folds == "auto" and cfg.dask_address is None
    assert cfg.output == tmp_path / "reports" / "demo"               # reports/<name> beside configs/
    assert cfg.models[0].params["swarm"] == {"particles": 30, "iterations": 50}
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
    ("    rectangle:", "    validation:", r"data\.tests\.validation \(line {line}\): a test set may not be called 'validation'"),
    ("    rectangle:", "    ../up:", r"data\.tests\.\.\./up \(line {line}\): the test-set name '\.\./up' must be a name of at most 100 letters"),
    ("    rectangle:", "    'a b':", r"the test-set name 'a b' must be a name of at most 100 letters, digits"),
    ("name: demo\n", "name: ../demo\n", r"name \(line {line}\): must be a name of at most 100 letters, digits, '_', '\.' and '-' .*; got '\.\./demo'"),
    ("name: demo\n", "name: a/b\n", r"name \(line {line}\): must be a name of at most 100 letters.*got 'a/b'"),
    ("max_depth: [1, 2]", "max_depth: []", r"models\[1\]\.partition\.max_depth \(line {line}\): must be an int or a non-empty list of ints; got an empty list"),
    ("{method: hard}", "{method: gaussian, width: .nan}", r"models\[1\]\.blend\.width \(line {line}\): must be a real number in \[0\.6, 10\.0\]; got nan"),
    ("    degree: 2\n    solver: {method: lstsq}\n", "    degree: 2\n    inputs: joint\n    solver: {method: lstsq}\n", r"models\[1\]\.partition\.method \(line {line}\): octree splits the Cartesian workspace; for joint inputs use method: kmeans"),
    ("name: demo\n", "name: demo\nrank_by: best\n", r"rank_by \(line {line}\): must be one of 'cv', 'validation'; got 'best'"),
    ("name: demo\n", "name: demo\nverify: {}\n", r"verify \(line {line}\): missing required key 'virtual_robot'"),
])
def test_errors_name_path_and_line(tmp_path, old, new, message):
    text = BASE.replace(old, new, 1)
    pos = BASE.index(old)       # the edited line: where the replacement starts, plus lines it adds before
    line = BASE[:pos].count("\n") + 1 + new.rstrip("\n").count("\n")
    if "octree splits" in message:      # the partition key, two lines below the replaced block
        line += 1
    with pytest.raises(ConfigError, match=message.format(line=line)):
        load_config(write(tmp_path, text))


def test_broken_yaml_names_its_line(tmp_path):
    text = BASE.replace("  tests:\n", "  tests: [\n")
    with pytest.raises(ConfigError, match=r"run\.yaml \(line \d+\): not valid YAML"):
        load_config(write(tmp_path, text))


def test_shipped_configs_load():
    paper = load_config(ROOT / "configs" / "paper_sk120.yaml")
    assert [m.name for m in paper.models] == ["FDP(CI)", "FDP(AI)", "SDP(CI)", "SDP(AI)"]     # Table 2's four
    assert [(m.inputs, m.params["degree"]) for m in paper.models] == [("cartesian", 1), ("joint", 1), ("cartesian", 2),
                                                            ("joint", 2)]
    assert all(m.params["swarm"] == {"particles": 100, "iterations": 200, "c1": 2.05, "c2": 2.05, "patience": None}
               for m in paper.models)                                       # the paper's swarm settings
    assert set(paper.tests) == {"rectangle", "spiral_xy", "spiral_yz"}
    for name in ("paper_sk120.yaml", "partitioned_sk120.yaml"):
        cfg = load_config(ROOT / "configs" / name)
        assert cfg.output == ROOT / "reports" / cfg.name and cfg.virtual_robot == ROOT / "configs" / "sk120_virtual.yaml"
        assert cfg.identification == ROOT / "data" / "sk120" / "identification.csv" and cfg.rank_by == "cv"


def data_file(tmp_path, rows, name="few.csv"):
    """A measurement CSV of the given joint rows (six joints) of the SK120, measured = nominal + 1 mm."""
    from partcal import load_robot

    lines = ["q1,q2,q3,q4,q5,q6,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas"]
    nominal = load_robot("motoman_sk120").positions(np.array([q for q, _ in rows], dtype=float))
    lines += [",".join(str(v) for v in [*q, *p, *(p + 1)]) for (q, _), p in zip(rows, nominal)]
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("case, message", [
    ("one row", r"data\.identification \(line 4\): .*few\.csv holds 1 pose; a fit needs at least 2"),
    ("constant", r"data\.identification \(line 4\): .*few\.csv holds 1 pose; a fit needs at least 2"),   # 10 repeats
    ("too few for folds", r"models\[1\]\.degree \(line 12\): 'SDP octree' needs one region of 21 samples \(7 terms per output \(3 varying cartesian inputs\)\), but the smallest cross-validation training fold \(leave-one-pose-out over 20 poses\) holds 19 samples"),
])
def test_data_problems_are_found_before_any_fit(tmp_path, case, message):
    from partcal.study.prepare import check_run, load_datasets

    rng = np.random.default_rng(0)
    if case == "one row":
        rows = [((0, -120, -170, 0, 0, 0), (1000.0, 0.0, 500.0))]
    elif case == "constant":
        rows = [((0, -120, -170, 0, 0, 0), (1000.0, 0.0, 500.0))] * 10
    else:
        rows = [((rng.uniform(-30, 30), rng.uniform(-130, -110), -170, 0, 0, 0), None) for _ in range(20)]
    text = BASE.replace(str(DATA / "identification.csv"), str(data_file(tmp_path, rows)))
    text = text.replace("    degree: 2\n", "    degree: 2\n    inputs: cartesian\n") if case == "constant" else text
    cfg = load_config(write(tmp_path, text))
    data, _, _ = load_datasets(cfg)
    with pytest.raises(ConfigError, match=message):
        check_run(cfg, data)


def test_a_nan_width_used_to_pass(tmp_path):
    # range checks compared NaN with < and >, which are both False: NaN slipped through
    with pytest.raises(ConfigError, match=r"must be a real number in \[0\.6, 10\.0\]; got nan"):
        load_config(write(tmp_path, BASE.replace("{method: hard}", "{method: gaussian, width: .nan}")))


TRACKER = f"""name: real
robot: universal_robots_ur10
data:
  format:
    delimiter: ";"
    decimal: ","
    columns: {{q1: j1, x_meas: mx}}
    joint_unit: rad
    length_unit: m
  frame: tracker
  identification: {{file: {DATA / 'identification.csv'}, rows: "1-40", every: 2}}
  tests:
    same: {DATA / 'test_rectangle.csv'}
    moved: {{file: {DATA / 'test_spiral_xy.csv'}, registration: own}}
registration: {{tool_mm: [0, 0.5, 93], fit_tool: false}}
models:
  - {{name: FDP, solver: {{method: lstsq}}}}
"""


def test_format_frame_rows_and_registration(tmp_path):
    import yaml

    from partcal.data.formats import MeasurementFormat, RowSelection

    cfg = load_config(write(tmp_path, TRACKER))
    opts = cfg.data_options
    assert opts.format == MeasurementFormat(delimiter=";", decimal=",", columns={"q1": "j1", "x_meas": "mx"},
                                            joint_unit="rad", length_unit="m")
    assert opts.frame == "tracker" and opts.own_frame == ("moved",)
    assert opts.rows == {"identification": RowSelection(((1, 40),), 2)}
    assert opts.tool_mm == (0.0, 0.5, 93.0) and opts.fit_tool is False and opts.converted
    assert cfg.identification == DATA / "identification.csv" and cfg.tests["moved"] == DATA / "test_spiral_xy.csv"
    resolved = yaml.safe_load(yaml.safe_dump(cfg.resolved()))
    assert resolved["data_options"]["rows"] == {"identification": {"rows": "1-40", "every": 2}}
    assert resolved["data_options"]["registration"] == {"tool_mm": [0.0, 0.5, 93.0], "fit_tool": False}
    plain = load_config(write(tmp_path, BASE)).data_options
    assert plain.format is None and plain.frame == "base" and not plain.converted


@pytest.mark.parametrize("old, new, message", [
    ("robot: universal_robots_ur10\n", "", r"data\.frame \(line {line}\): tracker needs a robot model"),
    ("  frame: tracker\n", "  frame: laser\n", r"data\.frame \(line {line}\): must be one of 'base', 'tracker'; got 'laser'"),
    ('    delimiter: ";"\n', '    delimiter: ","\n', r"data\.format\.decimal \(line 6\): must be different from the "
                                                  r"delimiter ','"),
    ("    columns: {{q1: j1, x_meas: mx}}\n", "    columns: {{q1: j1, xmeas: mx}}\n",
     r"data\.format\.columns\.xmeas \(line {line}\): must be a contract column .*did you mean 'x_meas'\?"),
    ('rows: "1-40"', 'rows: "40-1"', r"data\.identification\.rows \(line {line}\): must be data rows such as '1-600'"),
    ("every: 2}}", "every: 0}}", r"data\.identification\.every \(line {line}\): must be an int >= 1; got 0"),
    ("  identification: {{file:", "  identification: {{fil:", r"data\.identification \(line {line}\): missing "
                                                            r"required key 'file'"),
    ("registration: own}}", "registration: mine}}",
     r"data\.tests\.moved\.registration \(line {line}\): must be one of 'shared', 'own'; got 'mine'"),
    ("tool_mm: [0, 0.5, 93]", "tool_mm: [0, 93]", r"registration\.tool_mm \(line {line}\): must be a list of 3 numbers"),
    ("fit_tool: false", "fit_tool: no_way", r"registration\.fit_tool \(line {line}\): must be true or false"),
])
def test_data_and_registration_errors_name_path_and_line(tmp_path, old, new, message):
    text = TRACKER.replace(old.format(), new.format(), 1)
    assert text != TRACKER
    line = TRACKER[:TRACKER.index(old.format())].count("\n") + 1
    if not new:
        line = TRACKER[:TRACKER.index("  frame: tracker")].count("\n")       # one line was removed above it
    with pytest.raises(ConfigError, match=message.format(line=line)):
        load_config(write(tmp_path, text))


KINDS = BASE.replace("models:\n", """models:
  - {name: DH + GP, kind: kinematic, rcond: 1.0e-8, residual: {kind: gaussian_process, inputs: joint,
                                                                region_overlap: 1.25, hyper_samples: 300,
                                                                partition: {method: kmeans, n_regions: [2, 4]}}}
  - {name: GP(AI), kind: gaussian_process, inputs: joint, kernel: matern, nu: 1.5, restarts: 0}
""")


def test_model_kinds(tmp_path):
    cfg = load_config(write(tmp_path, KINDS))
    hybrid, gp, series = cfg.models[0], cfg.models[1], cfg.models[2]
    assert (hybrid.kind, hybrid.inputs, hybrid.params["rcond"], hybrid.params["robot"].name) == (
        "kinematic", "joint", 1e-8, "motoman_sk120")
    assert hybrid.params["robot"] is cfg.nominal_robot         # the robot is loaded once, by the config
    assert hybrid.residual.kind == "gaussian_process" and hybrid.residual.name == "DH + GP residual"
    assert hybrid.sizes == (2, 4) and series.kind == "series" and series.sizes == ()
    assert (gp.params["kernel"], gp.params["nu"], gp.params["restarts"]) == ("matern", 1.5, 0)
    model = hybrid.build(0, 4)
    assert model.residual.partition.n_regions == 4 and model.robot.name == "motoman_sk120"
    local = model.residual.local
    assert (local.region_overlap, local.hyper_samples, local.hyperparameters) == (1.25, 300, "shared")
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
     r"models\[0\]\.residual\.kind \(line {line}\): must be one of 'series', 'gaussian_process' \(a residual is fitted to what its entry leaves"),
    ("kind: gaussian_process, inputs: joint, kernel", "kind: gp, inputs: joint, kernel",
     r"models\[1\]\.kind \(line {line}\): must be one of 'series', 'gaussian_process', 'kinematic'; got 'gp'"),
    ("nu: 1.5", "nu: 2", r"models\[1\]\.nu \(line {line}\): must be one of 0\.5, 1\.5, 2\.5; got 2\.0"),
    ("kernel: matern, nu: 1.5", "kernel: rbf, nu: 1.5", r"models\[1\]\.nu \(line {line}\): applies to kernel: "
                                                        r"matern only"),
    ("rcond: 1.0e-8", "rcond: 0", r"models\[0\]\.rcond \(line {line}\): must be a real number in \(0\.0, 1\.0\]; got 0\.0"),
    ("region_overlap: 1.25", "region_overlap: 4", r"models\[0\]\.residual\.region_overlap \(line {line}\): must be "
                                                  r"a real number in \[1\.0, 3\.0\]; got 4\.0"),
    ("hyper_samples: 300", "hyper_samples: 10", r"models\[0\]\.residual\.hyper_samples \(line {line}\): must be an "
                                                r"int >= 20 or None; got 10"),
    ("restarts: 0", "restarts: 0, hyperparameters: per_region", r"models\[1\]\.hyperparameters \(line {line}\): "
                                                                r"applies to a partitioned GP only"),
    ("robot: motoman_sk120\n", "", r"models\[0\]\.kind \(line {line}\): kind: kinematic needs the run's robot"),
])
def test_model_kind_errors_name_path_and_line(tmp_path, old, new, message):
    text = KINDS.replace(old, new, 1)
    line = text[:text.index(new or "data:")].count("\n") + 1 if new else \
        text[:text.index("kind: kinematic")].count("\n") + 1
    with pytest.raises(ConfigError, match=message.format(line=line)):
        load_config(write(tmp_path, text))


def test_registration_keys_need_a_tracker_frame(tmp_path):
    text = TRACKER.replace("  frame: tracker\n", "")
    line = text[:text.index("    moved:")].count("\n") + 1
    with pytest.raises(ConfigError, match=rf"data\.tests\.moved\.registration \(line {line}\): applies to data\.frame: "
                                          "tracker only"):
        load_config(write(tmp_path, text))
    text = text.replace(", registration: own", "")
    line = text[:text.index("registration:")].count("\n") + 1
    with pytest.raises(ConfigError, match=rf"registration \(line {line}\): applies to data\.frame: tracker only"):
        load_config(write(tmp_path, text))

def test_calibration_config_loads():
    cfg = load_config(ROOT / "configs" / "calibration_sk120.yaml")
    assert {m.kind for m in cfg.models} == {"series", "kinematic", "gaussian_process"}
    paper = load_config(ROOT / "configs" / "paper_sk120.yaml")
    assert [m.name for m in paper.models] == ["FDP(CI)", "FDP(AI)", "SDP(CI)", "SDP(AI)"]      # the paper's four


def test_a_name_too_long_for_a_file_is_refused_before_fitting(tmp_path):
    with pytest.raises(ConfigError, match=r"data\.tests\.b{300} \(line \d+\): the test-set name 'b{300}' must be a name of at most 100"):
        load_config(write(tmp_path, BASE.replace("    rectangle:", "    " + "b" * 300 + ":")))
