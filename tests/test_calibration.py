"""Kinematic, hybrid and GP entries in a batch run: model files, predictor, compensation, report."""

import json

import html5lib
import numpy as np
import pytest
from conftest import ROOT, moved_positions

from partcal import load_predictor, load_robot, read_measurements
from partcal.metrics import summary
from partcal.calibration.parameters import robot_with
from partcal.report import render_report
from partcal.study.config import load_config
from partcal.study.outputs import write_run
from partcal.study.runner import run

DATA = ROOT / "data" / "sk120"
CONFIG = f"""name: kinds
robot: motoman_sk120
seed: 1
cv_folds: 5       # inner folds of 54 poses hold one 40-pose GP region, not two: granularity 2 is left out
data:
  identification: {DATA / 'identification.csv'}
  tests:
    rectangle: {DATA / 'test_rectangle.csv'}
verify:
  virtual_robot: {ROOT / 'configs' / 'sk120_virtual.yaml'}
models:
  - {{name: SDP(AI), inputs: joint, degree: 2, solver: {{method: lstsq}}}}
  - {{name: DH, kind: kinematic}}
  - {{name: DH + SDP(CI), kind: kinematic, residual: {{degree: 2, solver: {{method: lstsq}}}}}}
  - {{name: GP(AI), kind: gaussian_process, inputs: joint, restarts: 0}}
  - {{name: GP(CI), kind: gaussian_process, restarts: 0}}
  - {{name: GP(AI) k-means, kind: gaussian_process, inputs: joint, restarts: 0,
      partition: {{method: kmeans, n_regions: [1, 2]}}}}
  - name: DH + GP(AI) k-means
    kind: kinematic
    residual: {{kind: gaussian_process, inputs: joint, restarts: 0, partition: {{method: kmeans, n_regions: 2, min_samples: 20}}}}
"""
KINDS = {"SDP(AI)": "series", "DH": "kinematic", "DH + SDP(CI)": "kinematic + series",
         "GP(AI)": "gaussian_process", "GP(CI)": "gaussian_process", "GP(AI) k-means": "gaussian_process",
         "DH + GP(AI) k-means": "kinematic + gaussian_process"}


@pytest.fixture(scope="module")
def model_kinds_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("kinds")
    (tmp / "configs").mkdir()
    (tmp / "configs" / "run.yaml").write_text(CONFIG)
    result = run(load_config(tmp / "configs" / "run.yaml"))
    return result, write_run(result, render_report)


def independent_rank(q_deg) -> int:
    """How many of the SK120's 41 parameters positions at ``q_deg`` determine, worked out without partcal's
    identification: central differences of forward kinematics for each DH field of each row, the tool and the
    base pose (translation, small rotations), unit-norm columns, and the singular values above 1e-6 of the
    largest (measured: 19 values above 7e-3, the rest below 3e-10, the differencing noise)."""
    from partcal import load_robot

    robot = load_robot("motoman_sk120")
    rows = robot.alpha_deg.size
    jac = np.array([((moved_positions(robot, q_deg, k, 1e-4) - moved_positions(robot, q_deg, k, -1e-4)) / 2e-4).ravel()
                    for k in range(4 * rows + 9)]).T
    s = np.linalg.svd(jac / np.linalg.norm(jac, axis=0), compute_uv=False)
    return int(np.sum(s > 1e-6 * s[0]))


def test_every_kind_is_ranked_and_its_model_file_predicts_the_metrics(model_kinds_run):
    result, out = model_kinds_run
    doc = json.loads((out / "metrics.json").read_text())
    assert {name: entry["kind"] for name, entry in doc["models"].items()} == KINDS
    cv = {name: entry["cv"] for name, entry in doc["models"].items()}
    lowest = min(cv, key=lambda n: cv[n]["rms_3d"])
    within = [n for n in cv if cv[n]["rms_3d"] <= cv[lowest]["rms_3d"] + cv[lowest]["standard_error"]
              and doc["models"][n]["kind"] == "kinematic"]
    assert doc["best"] == (min(within, key=lambda n: (doc["models"][n]["effective_parameters"], cv[n]["rms_3d"]))
                           if within else lowest)
    assert [n for n, e in doc["models"].items() if e["physical"]] == [n for n, k in KINDS.items() if k == "kinematic"]
    assert doc["best_reason"].startswith("physical model" if doc["models"][doc["best"]]["physical"] else "lowest")
    assert doc["models"]["DH + GP(AI) k-means"]["regions"] == 2
    assert "granularity" not in doc["models"]["GP(AI) k-means"] and not cv["GP(AI) k-means"]["nested"]
    assert doc["cv"]["left_out"] == ["'GP(AI) k-means': granularity 2 left out: its regions need 40 samples each, "
                                     "and the smallest inner training fold of nested cross-validation (5-fold over "
                                     "85 poses) holds 54"]
    test = read_measurements(DATA / "test_rectangle.csv")
    for name, entry in doc["models"].items():
        p = load_predictor(out / entry["file"])
        X = {"joints": test.q_deg} if p.inputs == "joint" else {"positions": test.nominal_mm}
        np.testing.assert_allclose(summary(test.errors_mm - p.predict(**X))["rms"], entry["rectangle"]["rms"],
                                   rtol=1e-12, err_msg=name)
    dh = doc["models"]["DH"]["kinematic"]
    assert dh["parameters"] == 41 and "base.rz" in dh["unidentifiable"]
    assert dh["identified"] == independent_rank(read_measurements(DATA / "identification.csv").q_deg)
    # the geometric model removes most of the error; on the test path it beats the paper's best polynomial
    assert doc["models"]["DH"]["rectangle"]["rms_3d"] < 0.5 * doc["models"]["SDP(AI)"]["rectangle"]["rms_3d"]


def test_compensation_works_for_every_kind_on_the_virtual_robot(model_kinds_run):
    result, _ = model_kinds_run
    for r in result.models:
        if r.spec.kind == "series":
            continue                      # test_registry checks those
        c = r.compensation["rectangle"]
        assert c["converged"] == c["n"], r.spec.name
        # GP(CI) cannot see q6, which turns the tool: it only halves the error; the others cut it tenfold
        assert c["after"]["rms_3d"] < (0.5 if r.spec.name == "GP(CI)" else 0.1) * c["before"]["rms_3d"], r.spec.name
        assert c["after"]["rms_3d"] == pytest.approx(c["predicted_residual"]["rms_3d"], rel=0.15, abs=0.01), \
            r.spec.name


def test_a_kinematic_model_file_compensates_through_the_identified_robot(model_kinds_run):
    """The commanded joints put the identified robot on the targets: FK(identified, q_cmd) = target."""
    _, out = model_kinds_run
    p = load_predictor(out / "models" / "dh.json")
    doc = json.loads((out / "models" / "dh.json").read_text())
    identified = robot_with(load_robot("motoman_sk120"), np.array(doc["model"]["identification"]["value"]))
    test = read_measurements(DATA / "test_rectangle.csv")
    comp = p.compensate_full(test.nominal_mm[::10], joints=test.q_deg[::10])
    np.testing.assert_allclose(identified.positions(comp.joints_deg), test.nominal_mm[::10], atol=1e-3)
    np.testing.assert_array_equal(comp.joints_deg[:, 3:5], 0.0)          # q4, q5 never moved: held


def test_report_shows_the_identified_dh_table(model_kinds_run):
    result, out = model_kinds_run
    text = (out / "index.html").read_text()
    tree = html5lib.parse(text, namespaceHTMLElements=False)
    tables = [t for t in tree.iter("table") if t.get("class") == "dh"]
    assert len(tables) == 2                 # DH rows, and tool and base: the hybrids share DH's identification
    assert "The same identified parameters as DH." in text
    model = json.loads((out / "models" / "dh.json").read_text())["model"]["identification"]
    cells = {td.get("data-name"): td for td in tables[0].iter("td") if td.get("data-name")} | \
            {td.get("data-name"): td for td in tables[1].iter("td") if td.get("data-name")}
    assert len(cells) == 41
    for name, value, se, status in zip(model["names"], model["value"], model["std_error"], model["status"]):
        digits = 4 if name.startswith(("theta", "alpha", "base.r")) else 3
        expected = f"{value:.{digits}f}" + (f" ± {se:.{digits}f}" if status == "identified" else "")
        assert cells[name].text == expected and cells[name].get("class") == status, name
    assert "Kinematic models (1)" in text and "Hybrid models (kinematic + residual) (2)" in text
