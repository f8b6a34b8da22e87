"""Batch runs: outputs, consistency of metrics, reproducibility, Dask, compensation."""

import csv
import json
import subprocess
import sys
import warnings

import numpy as np
import pytest
from conftest import ROOT

from partcal import load_predictor, read_measurements
from partcal.metrics import summary
from partcal.study.config import load_config
from partcal.study.outputs import write_run
from partcal.study.registry import run

DATA = ROOT / "data" / "sk120"
CONFIG = f"""name: small
robot: motoman_sk120
seed: 3
n_jobs: @N_JOBS@
cv_folds: 3
@EXTRA@
data:
  identification: {DATA / 'identification.csv'}
  tests:
    rectangle: {DATA / 'test_rectangle.csv'}
    spiral_yz: {DATA / 'test_spiral_yz.csv'}
verify:
  virtual_robot: {ROOT / 'configs' / 'sk120_virtual.yaml'}
models:
  - {{name: FDP(CI), degree: 1, solver: {{method: pso, particles: 30, iterations: 300}}}}
  - {{name: SDP(AI), inputs: joint, degree: 2, solver: {{method: lstsq}}}}
  - name: FDP(CI) k-means
    degree: 1
    solver: {{method: lstsq}}
    partition: {{method: kmeans, n_regions: [2, 3]}}
"""


def config(tmp_path, n_jobs=1, extra="", name="run.yaml"):
    path = tmp_path / "configs" / name
    path.parent.mkdir(exist_ok=True)
    path.write_text(CONFIG.replace("@N_JOBS@", str(n_jobs)).replace("@EXTRA@", extra))
    return load_config(path)


def without_timings(doc):
    doc = json.loads(json.dumps(doc))
    for entry in doc["models"].values():
        entry.pop("fit_seconds")
    return doc


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("run")
    result = run(config(tmp))
    return result, write_run(result)


def test_outputs_follow_the_contract(small_run):
    result, out = small_run
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["name"] == "small" and doc["seed"] == 3 and doc["partcal_version"]
    assert doc["datasets"] == {"identification": {"n": 85}, "rectangle": {"n": 200}, "spiral_yz": {"n": 200}}
    assert set(doc["models"]) == {"FDP(CI)", "SDP(AI)", "FDP(CI) k-means"}
    best_cv = min(doc["models"].values(), key=lambda m: m["cv"]["rms_3d"])
    assert doc["models"][doc["best"]] is not None and doc["models"][doc["best"]]["cv"] == best_cv["cv"]
    for slug in ("fdp-ci", "sdp-ai", "fdp-ci-k-means"):
        assert (out / "models" / f"{slug}.json").is_file()
        for ds in ("identification", "rectangle", "spiral_yz"):
            assert (out / "predictions" / slug / f"{ds}.csv").is_file()
    assert (out / "config.resolved.yaml").is_file()
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".small.")]    # no temporaries left


def test_metrics_equal_those_recomputed_from_predictions_and_model_files(small_run):
    _, out = small_run
    doc = json.loads((out / "metrics.json").read_text())
    for name, entry in doc["models"].items():
        predictor = load_predictor(out / entry["file"])
        slug = entry["file"].split("/")[1][:-5]
        for ds in ("identification", "rectangle", "spiral_yz"):
            with open(out / "predictions" / slug / f"{ds}.csv") as handle:
                rows = list(csv.DictReader(handle))
            meas = np.array([[float(r[f"d{a}_meas"]) for a in "xyz"] for r in rows])
            pred = np.array([[float(r[f"d{a}_pred"]) for a in "xyz"] for r in rows])
            from_csv = np.sqrt(np.mean((meas - pred) ** 2, axis=0))
            np.testing.assert_allclose(from_csv, entry[ds]["rms"], rtol=1e-12)
            m = read_measurements(DATA / {"identification": "identification.csv", "rectangle": "test_rectangle.csv",
                                          "spiral_yz": "test_spiral_yz.csv"}[ds])
            X = {"positions": m.nominal_mm} if predictor.inputs == "cartesian" else {"joints": m.q_deg}
            from_model = summary(m.errors_mm - predictor.predict(**X))
            np.testing.assert_allclose(from_model["rms"], entry[ds]["rms"], rtol=1e-12)
            assert from_model["max_3d"] == pytest.approx(entry[ds]["max_3d"], rel=1e-12)


def test_same_config_same_metrics_for_any_n_jobs(small_run, tmp_path):
    from partcal.study.outputs import metrics_document

    result, _ = small_run
    two = run(config(tmp_path, n_jobs=2))
    assert json.dumps(without_timings(metrics_document(two))) == json.dumps(without_timings(metrics_document(result)))


def test_dask_cluster_gives_the_same_metrics(small_run, tmp_path):
    distributed = pytest.importorskip("distributed")
    from partcal.study.outputs import metrics_document

    result, _ = small_run
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp", host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        dask_run = run(config(tmp_path, extra=f"dask: {{address: '{cluster.scheduler_address}'}}"))
    assert json.dumps(without_timings(metrics_document(dask_run))) == json.dumps(without_timings(metrics_document(result)))


def test_compensation_on_the_virtual_robot_matches_the_prediction(small_run):
    result, _ = small_run
    for r in result.models:
        for ds, c in r.compensation.items():
            assert c["converged"] == c["n"]
            assert c["after"]["rms_3d"] < 0.5 * c["before"]["rms_3d"]
            assert c["after"]["rms_3d"] == pytest.approx(c["predicted_residual"]["rms_3d"], rel=0.15), (r.spec.name, ds)


def cli(*args):
    return subprocess.run([sys.executable, "-m", "partcal", *args], capture_output=True, text=True)


def test_cli_run_prints_table_2_and_bad_input_keeps_earlier_outputs(tmp_path):
    cfg = config(tmp_path)
    res = cli("run", str(cfg.source), "-q")
    assert res.returncode == 0, res.stderr
    assert "uncompensated" in res.stdout and "FDP(CI) k-means" in res.stdout
    metrics = (cfg.output / "metrics.json").read_bytes()
    text = cfg.source.read_text()
    cases = {
        "broken YAML": text.replace("models:", "models: [", 1),
        "unknown key": text.replace("seed: 3", "sed: 3"),
        "missing file": text.replace("test_spiral_yz.csv", "nope.csv"),
        "wrong type": text.replace("cv_folds: 3", "cv_folds: three"),
    }
    nan_csv = tmp_path / "nan.csv"
    original = (DATA / "test_rectangle.csv").read_text().splitlines()
    lines = list(original)
    lines[5] = ",".join(["nan"] + lines[5].split(",")[1:])
    nan_csv.write_text("\n".join(lines) + "\n")
    cases["NaN in a CSV"] = text.replace(str(DATA / "test_rectangle.csv"), str(nan_csv))
    few = tmp_path / "five_joints.csv"
    five = ["q1,q2,q3,q4,q5,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas"]
    five += [",".join(r.split(",")[:5] + r.split(",")[6:12]) for r in original[3:10]]
    few.write_text("\n".join(five) + "\n")
    cases["fewer joints in a test set"] = text.replace(str(DATA / "test_rectangle.csv"), str(few))
    expected = {"broken YAML": "not valid YAML", "unknown key": "did you mean 'seed'",
                "missing file": "no such file", "wrong type": "cv_folds (line 5): must be an integer",
                "NaN in a CSV": "nan.csv:6: column 'q1': expected a finite number, got 'nan'",
                "fewer joints in a test set": "has 5 joint columns (q1..q5) but the identification set"}
    for label, bad in cases.items():
        cfg.source.write_text(bad)
        res = cli("run", str(cfg.source), "-q")
        assert res.returncode == 2, (label, res.stderr)
        assert res.stderr.count("\n") == 1 and "Traceback" not in res.stderr, (label, res.stderr)
        assert expected[label] in res.stderr, (label, res.stderr)
        assert (cfg.output / "metrics.json").read_bytes() == metrics, label
    blocker = tmp_path / "not_a_folder"          # a file where a folder must be: unwritable even for root
    blocker.write_text("x")
    cfg.source.write_text(text.replace("name: small", f"name: small\noutput: {blocker / 'out'}"))
    res = cli("run", str(cfg.source), "-q")
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert f"{blocker / 'out'}: cannot write the output folder here" in res.stderr
    assert (cfg.output / "metrics.json").read_bytes() == metrics


def test_compensation_far_from_the_data_warns_once(small_run, tmp_path):
    from partcal.metrics import ExtrapolationWarning

    _, out = small_run
    m = read_measurements(DATA / "identification.csv")
    far = m.nominal_mm[:6] + [0.0, 0.0, 1500.0] * (np.arange(6) % 2)[:, None]      # every other one 1.5 m up
    p = load_predictor(out / "models" / "fdp-ci-k-means.json")
    with pytest.warns(ExtrapolationWarning, match="3 of 6 points lie more than 50 input units outside"):
        p.compensate(far)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        p.compensate(m.nominal_mm[:6])          # at the samples: commanded points move by the errors only
    targets = tmp_path / "far.csv"
    targets.write_text("x,y,z\n" + "\n".join(",".join(f"{v:.6f}" for v in row) for row in far) + "\n")
    for model in ("fdp-ci.json", "fdp-ci-k-means.json"):
        res = cli("compensate", str(out / "models" / model), str(targets), "-o", str(tmp_path / "cmd.csv"))
        assert res.returncode == 0, res.stderr
        warned = [line for line in res.stderr.splitlines() if "outside the data" in line]
        assert warned == ["partcal: warning: 3 of 6 points lie more than 50 mm outside the data the model "
                          "was fitted on"], res.stderr


def test_cli_predict_and_compensate(small_run, tmp_path):
    _, out = small_run
    m = read_measurements(DATA / "test_rectangle.csv")
    pts = tmp_path / "points.csv"
    pts.write_text("x,y,z\n" + "\n".join(",".join(f"{v:.6f}" for v in p) for p in m.nominal_mm[:20]) + "\n")
    res = cli("predict", str(out / "models" / "fdp-ci.json"), str(pts), "-o", str(tmp_path / "pred.csv"))
    assert res.returncode == 0, res.stderr
    with open(tmp_path / "pred.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert list(rows[0]) == ["x", "y", "z", "dx", "dy", "dz"]
    expected = load_predictor(out / "models" / "fdp-ci.json").predict(positions=m.nominal_mm[:20])
    np.testing.assert_allclose([[float(r[k]) for k in ("dx", "dy", "dz")] for r in rows], expected, atol=1e-6)
    res = cli("compensate", str(out / "models" / "fdp-ci.json"), str(pts), "-o", str(tmp_path / "cmd.csv"))
    assert res.returncode == 0, res.stderr
    with open(tmp_path / "cmd.csv") as handle:
        rows = list(csv.DictReader(handle))
    cmd = np.array([[float(r[k]) for k in ("x_cmd", "y_cmd", "z_cmd")] for r in rows])
    p = load_predictor(out / "models" / "fdp-ci.json")
    np.testing.assert_allclose(cmd + p.predict(positions=cmd), m.nominal_mm[:20], atol=1e-3)
    seeds = tmp_path / "seeded.csv"
    seeds.write_text("x,y,z,q1,q2,q3,q4,q5,q6\n" + "\n".join(
        ",".join(f"{v:.6f}" for v in np.r_[p_, q_]) for p_, q_ in zip(m.nominal_mm[:5], m.q_deg[:5])) + "\n")
    res = cli("compensate", str(out / "models" / "sdp-ai.json"), str(seeds), "-o", str(tmp_path / "q.csv"))
    assert res.returncode == 0, res.stderr
    header = (tmp_path / "q.csv").read_text().splitlines()[0].split(",")
    assert header[-9:] == ["x_cmd", "y_cmd", "z_cmd"] + [f"q{j}_cmd" for j in range(1, 7)]
    res = cli("predict", str(out / "models" / "sdp-ai.json"), str(pts), "-o", str(tmp_path / "x.csv"))
    assert res.returncode == 2 and "column 'q1' is missing (expected columns q1,q2,q3,q4,q5,q6)" in res.stderr
