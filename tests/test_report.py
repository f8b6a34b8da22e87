"""The HTML report, opened in headless Chromium as an engineer would open it."""

import html
import json
import re
import shutil

import html5lib
import numpy as np
import pytest
from conftest import ROOT

from partcal.report import render_report
from partcal.study.config import load_config
from partcal.study.outputs import write_run
from partcal.study.runner import run

DATA = ROOT / "data" / "sk120"
EVIL = 'FDP <script>alert("x")</script> & co'
CONFIG = f"""name: report_demo
robot: motoman_sk120
cv_folds: 3
data:
  identification: {DATA / 'identification.csv'}
  tests:
    rectangle: {DATA / 'test_rectangle.csv'}
verify:
  virtual_robot: {ROOT / 'configs' / 'sk120_virtual.yaml'}
models:
  - name: '{EVIL}'
    degree: 1
    solver: {{method: pso, particles: 20, iterations: 100}}
  - {{name: SDP(AI), inputs: joint, degree: 2, solver: {{method: lstsq}}}}
  - name: FDP(CI) octree
    degree: 1
    solver: {{method: pso, particles: 20, iterations: 100}}
    partition: {{method: octree, max_depth: 1, min_samples: 12}}
"""

needs_chromium = pytest.mark.skipif(shutil.which("chromium") is None, reason="Debian package chromium not installed")


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("report")
    (tmp / "configs").mkdir()
    (tmp / "configs" / "run.yaml").write_text(CONFIG)
    result = run(load_config(tmp / "configs" / "run.yaml"))
    out = write_run(result, render_report)
    return result, out


def test_report_is_valid_self_contained_html(report):
    _, out = report
    text = (out / "index.html").read_text()
    html5lib.HTMLParser(strict=True).parse(text)                  # raises on any parse error
    assert "&lt;script&gt;alert(" in text and '<script>alert("x")' not in text
    for needle in ("http://", "https://", "//cdn", "src=\"/"):
        assert needle not in text.replace("http://www.w3.org/2000/svg", "").replace(
            "http://www.w3.org/1999/xlink", "").replace("http://purl.org/dc", "").replace(
            "http://creativecommons.org", "").replace("https://matplotlib.org", ""), needle
    assert (out / "index.html").stat().st_size < 3 * 1024 * 1024


@needs_chromium
def test_report_in_headless_chromium(report, tmp_path):
    from partcal.report.browser import open_report

    _, out = report
    check = open_report(out / "index.html", tmp_path / "page.png")
    assert check.console_errors == [] and check.failed_requests == [] and check.dialogs == []
    assert all(url.startswith(("file://", "data:")) for url in check.requests), check.requests
    assert len(check.image_widths) >= 6 and min(check.image_widths) > 0      # every image decoded
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(check.cells) == {"uncompensated", *metrics["models"]}
    for model, entry in metrics["models"].items():
        cells = check.cells[model]
        for ds in ("identification", "rectangle"):
            for axis, value in zip("xyz", entry[ds]["rms"]):
                assert float(cells[f"{ds}.{axis}"]) == pytest.approx(value, rel=1e-12)
            assert float(cells[f"{ds}.3d"]) == pytest.approx(entry[ds]["rms_3d"], rel=1e-12)
            assert float(cells[f"{ds}.max"]) == pytest.approx(entry[ds]["max_3d"], rel=1e-12)
        assert float(cells["cv"]) == pytest.approx(entry["cv"]["rms_3d"], rel=1e-12)
    png = (tmp_path / "page.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 50_000


@pytest.mark.parametrize("failure, note", [
    ("no interpreter", "No picture: 3-D rendering could not start"),
    ("crash", "No picture: 3-D rendering failed (exit -11: Segmentation fault)"),
])
def test_report_survives_when_3d_rendering_is_impossible(report, tmp_path, monkeypatch, failure, note):
    import partcal.report.scene as scene

    result, _ = report
    if failure == "no interpreter":
        monkeypatch.setattr(scene.sys, "executable", str(tmp_path / "no-such-python"))
    else:                 # a child that dies as a broken OpenGL stack kills it
        crashing = tmp_path / "crashing-python"
        crashing.write_text("#!/bin/sh\necho 'Segmentation fault' >&2\nkill -SEGV $$\n")
        crashing.chmod(0o755)
        monkeypatch.setattr(scene.sys, "executable", str(crashing))
    text = render_report(result, tmp_path).read_text()
    assert note in text
    assert "The rest of the report is complete" in text and "id=\"compensation\"" in text
    html5lib.HTMLParser(strict=True).parse(text)


def test_report_shows_the_tracker_registration(tmp_path):
    import numpy as np

    from partcal import read_measurements

    for name in ("identification", "test_rectangle"):   # the virtual data, measured points only, turned 90 degrees
        m = read_measurements(DATA / f"{name}.csv")
        rows = [",".join(f"{v:.6f}" for v in (*q, -p[1], p[0], p[2])) for q, p in zip(m.q_deg, m.measured_mm)]
        (tmp_path / f"{name}.csv").write_text("q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas\n" + "\n".join(rows) + "\n")
    (tmp_path / "configs").mkdir()
    (tmp_path / "configs" / "run.yaml").write_text("""name: tracked
robot: motoman_sk120
cv_folds: 3
data:
  frame: tracker
  identification: ../identification.csv
  tests: {rectangle: ../test_rectangle.csv}
models:
  - {name: FDP(CI), degree: 1, solver: {method: lstsq}}
""")
    result = run(load_config(tmp_path / "configs" / "run.yaml"))
    text = (write_run(result, render_report) / "index.html").read_text()
    html5lib.HTMLParser(strict=True).parse(text)
    errors = result.datasets["identification"].errors_mm
    rms = float(np.sqrt(np.mean(np.sum(errors**2, axis=1))))
    assert 'id="registration-table"' in text and "identification, rectangle" in text
    assert f'data-value="{result.registrations["identification"].rms_3d}"' in text
    assert f">{rms:.3f}<" in text and "(fitted)" in text
    assert re.search(r"<td>-?[\d.]+ -?[\d.]+ -(89\.[5-9]|90\.[0-4])\d*</td>", text)   # tracker -> base: back by 90 deg


# --- a run of pose errors on a virtual UR10 with three targets, measured in a tracker's frame ----------------

POSE_MODELS = """models:
  - {name: DH, kind: kinematic}
  - {name: DH (all targets), kind: kinematic, all_targets: true, use_orientation: true}
  - {name: FDP(AI), inputs: joint, degree: 1, solver: {method: lstsq}}
"""


def _tracker_csv(m, path, rot, t):
    """A data set's joints, every target's measured position and the measured orientation (intrinsic XYZ, deg) as
    a tracker at ``p_base = rot @ p_tracker + t`` reads them: measured columns only."""
    import numpy as np

    from partcal.robot.kinematics import matrices_from_xyz_deg, xyz_deg_from_matrices

    def seen(p):
        return (p - t) @ rot

    blocks = [m.q_deg, seen(m.measured_mm), *(seen(p) for p in m.extra_measured_mm.values()),
              xyz_deg_from_matrices(rot.T @ matrices_from_xyz_deg(m.measured_orientation_deg))]
    header = [f"q{j + 1}" for j in range(m.n_joints)] + ["x_meas", "y_meas", "z_meas"] + [
        f"{c}_meas@{k}" for k in m.extra_measured_mm for c in "xyz"] + ["rx_meas", "ry_meas", "rz_meas"]
    rows = [",".join(f"{v:.6f}" for v in row) for row in np.hstack(blocks)]
    path.write_text(",".join(header) + "\n" + "\n".join(rows) + "\n")


@pytest.fixture(scope="module")
def pose_report(tmp_path_factory):
    """``predict: pose`` on the virtual UR10 of configs/ur10_targets_virtual.yaml (16 identification poses, 40
    test poses), its files turned into a tracker's frame: a registration on three targets and the orientation,
    a kinematic model on the primary target, one on every target and the orientation, and a polynomial."""
    import numpy as np
    import yaml
    from scipy.spatial.transform import Rotation

    from partcal import load_robot, read_measurements
    from partcal.data.simulate import load_study, simulate, write_study
    from partcal.robot.description import robot_to_dict

    tmp = tmp_path_factory.mktemp("pose")
    (tmp / "configs").mkdir()
    sim = (ROOT / "configs" / "ur10_targets_virtual.yaml").read_text()
    (tmp / "configs" / "sim.yaml").write_text(sim.replace("output: ../data/ur10_targets", "output: ../data")
                                              .replace("test: {sample: 400}", "test: {sample: 40}"))
    study = load_study(tmp / "configs" / "sim.yaml")
    write_study(study, simulate(study))
    ur10 = load_robot("universal_robots_ur10").replace(tool_mm=np.array([0.0, 0.0, 120.0]))
    (tmp / "robot.yaml").write_text(yaml.safe_dump(robot_to_dict(ur10)))
    rot, t = Rotation.from_rotvec([0.0, 0.0, np.pi / 2]).as_matrix(), np.array([2500.0, 100.0, -300.0])
    for name in ("identification", "test"):
        _tracker_csv(read_measurements(tmp / "data" / f"{name}.csv"), tmp / "data" / f"tracker_{name}.csv", rot, t)
    head = """robot: ../robot.yaml
cv_folds: 4
predict: pose
data: {frame: tracker, identification: ../data/tracker_identification.csv, tests: {test: ../data/tracker_test.csv}}
"""
    (tmp / "configs" / "pose.yaml").write_text("name: pose\n" + head + POSE_MODELS)
    (tmp / "configs" / "turn.yaml").write_text("name: turn\nrank_on: orientation\n" + head + POSE_MODELS)
    result = run(load_config(tmp / "configs" / "pose.yaml"))
    out = write_run(result, render_report)
    return result, out, tmp


def _cells(text: str, table_id: str) -> dict[str, dict[str, float]]:
    """``{row's data-model: {data-key: float(data-value)}}`` of one table of a report."""
    doc = html5lib.parse(text, namespaceHTMLElements=False)
    table = doc.find(f".//table[@id='{table_id}']")
    assert table is not None, table_id
    return {tr.get("data-model"): {td.get("data-key"): float(td.get("data-value")) for td in tr.iter("td")
                                   if td.get("data-value")}
            for tr in table.iter("tr") if tr.get("data-model")}


def _keyed(text: str, data_model: str | None = None) -> dict[str, float]:
    """Every ``data-key: data-value`` of the report (within the tables of one ``data-model`` if given)."""
    doc = html5lib.parse(text, namespaceHTMLElements=False)
    tables = [tb for tb in doc.iter("table") if data_model is None or tb.get("data-model") == data_model]
    return {td.get("data-key"): float(td.get("data-value")) for tb in tables for td in tb.iter("td")
            if td.get("data-value")}


def _orientation_left(measured_deg, predicted):
    """Per axis RMS, RMS angle, the same in degrees, and the largest angle of the turn from a predicted
    orientation error (rotation vectors, mrad) to the measured one (rotation vectors, degrees): written out."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    left = (Rotation.from_rotvec(measured_deg, degrees=True) * Rotation.from_rotvec(predicted / 1000.0).inv()
            ).as_rotvec() * 1000.0
    angle = np.linalg.norm(left, axis=1)
    rms = float(np.sqrt(np.mean(angle**2)))
    return [*np.sqrt(np.mean(left**2, axis=0)), rms, rms * 180.0 / np.pi / 1000.0, float(angle.max())]


def test_the_orientation_table_holds_the_orientation_each_model_leaves(pose_report):
    import numpy as np

    result, out, _ = pose_report
    text = (out / "index.html").read_text()
    html5lib.HTMLParser(strict=True).parse(text)
    cells = _cells(text, "orientation-table")
    assert list(cells) == ["uncompensated", "DH", "DH (all targets)", "FDP(AI)"]
    keys = ("rx", "ry", "rz", "angle", "angle_deg", "max_angle")
    for name, m in result.datasets.items():
        zero = np.zeros((len(m), 3))
        expected = {"uncompensated": _orientation_left(m.orientation_errors_deg, zero)}
        expected.update({r.spec.name: _orientation_left(m.orientation_errors_deg, r.predictions[name][:, 3:])
                         for r in result.models})
        for model, values in expected.items():
            got = [cells[model][f"{name}.{k}"] for k in keys]
            assert got == pytest.approx(values, rel=1e-9), (model, name)
    lowest = min(result.models, key=lambda r: r.metrics["test"]["orientation"]["rms_angle"]).spec.name
    table = text.split('id="orientation-table"')[1]
    row = re.search(r'<tr class="" data-model="%s">.*?</tr>' % re.escape(lowest), table, re.S).group(0)
    assert re.search(r'<td class="best" data-key="test\.angle"', row)
    ranked = re.search(r'<p id="ranked-part" data-rank-on="(\w+)" data-unit="(\w+)">', text)
    assert ranked.groups() == ("position", "mm") and "ranked on the position" in text


def test_the_orientation_plot_shows_each_data_set_uncompensated_and_left(pose_report):
    import base64

    import numpy as np

    result, out, _ = pose_report
    text = (out / "index.html").read_text()
    section = text.split('<h2 id="orientation">')[1].split("<h2")[0]
    for name, m in result.datasets.items():
        svg = base64.b64decode(re.search(rf'alt="orientation error along {name}" src="data:image/svg\+xml;base64,'
                                         r'([A-Za-z0-9+/=]+)"', section).group(1)).decode()
        rms = 1000 * np.radians(np.sqrt(np.mean(np.sum(m.orientation_errors_deg**2, axis=1))))
        assert f"uncompensated (RMS {rms:.3f} mrad)" in svg and "orientation error (mrad)" in svg
        assert "DH (all targets) (RMS" in svg            # the best model by CV, the shown global model


def test_a_position_run_has_no_orientation_or_per_target_section(report):
    _, out = report
    text = (out / "index.html").read_text()
    for needle in ('id="orientation"', 'id="orientation-table"', "ranked-part", 'id="registration-targets-table"',
                   'class="targets"', "orientation RMS angle"):
        assert needle not in text, needle
    assert re.search(r"chosen by the [^<]*: [\d.]+ mm</div>", text)


def test_a_run_ranked_on_the_orientation_says_so_and_gives_the_unit(pose_report, tmp_path):
    _, _, tmp = pose_report
    result = run(load_config(tmp / "configs" / "turn.yaml"))
    text = render_report(result, tmp_path).read_text()
    html5lib.HTMLParser(strict=True).parse(text)
    best = next(r for r in result.models if r.spec.name == result.best)
    assert re.search(r'<p id="ranked-part" data-rank-on="orientation" data-unit="mrad">', text)
    assert f": {best.cv_rms_3d:.3f} mrad</div>" in text and ">CV mrad</th>" in text
    assert "RMS angle of the orientation error left (mrad, not mm)" in text
    assert _cells(text, "comparison-table")[best.spec.name]["cv"] == pytest.approx(best.cv_rms_3d, rel=1e-12)


def test_the_registration_and_the_kinematic_fit_show_each_target_and_the_orientation(pose_report):
    import numpy as np
    from scipy.spatial.transform import Rotation

    result, out, _ = pose_report
    text = (out / "index.html").read_text()
    ident = result.datasets["identification"]
    assert ident.target_names == ("A", "B", "C")
    keyed = _keyed(text)
    # the registration: each target's registered measured - nominal, and the orientation's turn, on its poses
    for t in ident.target_names:
        e = ident.measured_of(t) - ident.nominal_of(t)
        assert keyed[f"registration.target.{t}.rms"] == pytest.approx(np.sqrt(np.mean(np.sum(e**2, axis=1))), rel=1e-9)
    angle = np.sqrt(np.mean(np.sum(ident.orientation_errors_deg**2, axis=1)))
    assert keyed["registration.orientation.rms_deg"] == pytest.approx(angle, rel=1e-9)
    assert re.search(r'<tr data-target="B"><td class="name">identification, test</td><td class="name">B</td>', text)
    # the fit on every target: each one's distance to the identified robot's, and the orientation left
    every = next(r for r in result.models if r.spec.name == "DH (all targets)")
    model = every.model
    fitted = _keyed(text, "DH (all targets)")
    values = dict(zip(model.identification_.names, model.identification_.value))
    predicted = model.predict(ident.q_deg)
    e = ident.errors_mm - predicted[:, :3]
    assert fitted["kinematic.target.A.rms"] == pytest.approx(np.sqrt(np.mean(np.sum(e**2, axis=1))), rel=1e-9)
    for t in ("B", "C"):
        tool = np.array([values[f"tool@{t}.{c}"] for c in "xyz"])
        e = ident.measured_of(t) - model.identified_robot_.replace(tool_mm=tool).positions(ident.q_deg)
        assert fitted[f"kinematic.target.{t}.rms"] == pytest.approx(np.sqrt(np.mean(np.sum(e**2, axis=1))), rel=1e-9)
    left = (Rotation.from_rotvec(ident.orientation_errors_deg, degrees=True) *
            Rotation.from_rotvec(predicted[:, 3:] / 1000.0).inv()).magnitude()
    assert fitted["kinematic.orientation.rms_deg"] == pytest.approx(np.degrees(np.sqrt(np.mean(left**2))), rel=1e-9)
    # identifiable from the primary alone against all the data: the numbers of metrics.json
    summary = json.loads((out / "metrics.json").read_text())["models"]["DH (all targets)"]["kinematic"]
    assert fitted["kinematic.identifiable.primary"] == summary["identifiable_from_primary"]
    assert fitted["kinematic.identifiable.all"] == summary["identified"]
    # with the registered targets (0.4 mm off the flange axis here) the primary's rank already reaches the
    # one-target table's 25 of 33; the further targets change which ones (and how well), not how many
    assert 0 < fitted["kinematic.identifiable.primary"] <= fitted["kinematic.identifiable.all_of_one"]
    # the further targets' offsets and the probe's turn are tabled apart, not among the joint errors
    assert re.search(r'<table class="dh added" data-model="DH \(all targets\)">.*data-name="tool@B.x".*'
                     r'data-name="probe.rz"', text, re.S)
    assert "joint-errors" not in text
    assert _keyed(text, "DH") == {}                       # the fit on the primary target alone has no such table


@needs_chromium
def test_the_pose_report_in_headless_chromium(pose_report, tmp_path):
    from partcal.report.browser import open_report

    _, out, _ = pose_report
    check = open_report(out / "index.html")
    assert check.console_errors == [] and check.failed_requests == [] and check.dialogs == []
    assert len(check.image_widths) >= 6 and min(check.image_widths) > 0      # the orientation plots decode too


def test_a_set_in_its_own_frame_scores_the_orientation_as_the_shared_frame_does(pose_report):
    """``registration: own`` keeps the identification's tool offsets and probe rotation: the same tracker file
    registered on itself leaves each model the orientation error the shared frame leaves it (refitted, the
    probe's turn absorbed part of the robot's turn, and DH (orientation) scored 0.39 mrad against 0.16)."""
    _, _, tmp = pose_report
    (tmp / "configs" / "own.yaml").write_text("""name: own
robot: ../robot.yaml
cv_folds: 4
predict: pose
data: {frame: tracker, identification: ../data/tracker_identification.csv,
       tests: {test: ../data/tracker_test.csv, own: {file: ../data/tracker_test.csv, registration: own}}}
""" + POSE_MODELS)
    result = run(load_config(tmp / "configs" / "own.yaml"))
    assert result.registrations["own"] is not result.registrations["identification"]
    np.testing.assert_array_equal(result.registrations["own"].probe_rotation,
                                  result.registrations["identification"].probe_rotation)
    for r in [*result.models, None]:          # measured: DH 0.867 / 0.866, DH (all targets) 0.151 / 0.153
        stats = result.uncompensated if r is None else r.metrics
        shared, own = stats["test"]["orientation"]["rms_angle"], stats["own"]["orientation"]["rms_angle"]
        # FDP(AI) leaves 2 mm: the rigid fit of its positions to the set turns its orientation too (1.40 / 1.58)
        assert own == pytest.approx(shared, rel=0.05 if r is None or r.spec.kind == "kinematic" else 0.2)
    # The residual histogram draws what the table scores: on the set in its own frame, after the rigid fit.
    import base64

    from partcal.report import error_figures

    figure = next(f for f in error_figures(result, result.models) if f["name"] == "own")
    svg = base64.b64decode(figure["hist_svg"]).decode()
    assert "after the rigid fit to its own frame" in svg
    for r in [None, *result.models]:
        label, stats = ("uncompensated", result.uncompensated) if r is None else (r.spec.name, r.metrics)
        assert f"{label} (RMS {stats['own']['rms_3d']:.2f} mm)" in svg


def test_scattered_poses_are_drawn_as_points_with_the_share_inside_each_models_interval():
    from partcal.report import figures

    rng = np.random.default_rng(0)
    measured = rng.normal(0, 1, size=(200, 3))
    predicted = np.zeros((200, 3))
    spread = np.full((200, 3), 0.5)
    inside = np.abs(measured[:, 0]) <= 1.959963984540054 * 0.5          # x: the legend's share
    svg = figures.errors_scattered("C", measured, {"GP": predicted}, {"GP": spread})
    assert f"GP ({100 * inside.mean():.0f}% within its 95% interval)" in svg
    assert "one point per pose" in svg and "<path" in svg
    band = figures.errors_along_path("rect", measured, {"GP": predicted}, {"GP": spread})
    assert "GP: 95% band" in band
    assert not figures.is_path(rng.uniform(0, 1000, (300, 3)))
    assert figures.is_path(np.c_[np.linspace(0, 1000, 300), np.zeros(300), np.ones(300)])


def test_a_run_gives_the_iso_figures_and_each_models_spread(report):
    from partcal.data.iso9283 import cycles_from_joints, pose_figures
    from partcal.study.scoring import errors_left

    result, out = report
    metrics = json.loads((out / "metrics.json").read_text())
    iso = metrics["iso9283"]
    assert list(iso) == ["rectangle"] and iso["rectangle"]["poses"] == 200
    m = result.datasets["rectangle"]
    cycles = cycles_from_joints(m.q_deg)
    expected = pose_figures(m.nominal_mm, m.measured_mm, cycles).ap_mm         # one cycle: AP is each |error|
    assert iso["rectangle"]["uncompensated"]["AP_max_mm"] == pytest.approx(np.linalg.norm(m.errors_mm, axis=1).max())
    assert iso["rectangle"]["uncompensated"]["AP_mean_mm"] == pytest.approx(expected.mean())
    for r in result.models:
        left = errors_left(m, r.predictions["rectangle"])[0]
        assert iso["rectangle"]["models"][r.spec.name]["AP_mean_mm"] == pytest.approx(
            np.linalg.norm(left, axis=1).mean())
        spread = metrics["models"][r.spec.name]["rectangle"]["spread"]
        std = r.spreads["rectangle"]
        assert spread["coverage_95"] == pytest.approx(np.mean(np.abs(left) <= 1.959963984540054 * std))
    header = (out / "predictions" / result.models[1].spec.slug / "rectangle.csv").read_text().splitlines()[0]
    assert header.endswith("dx_pred,dy_pred,dz_pred,dx_sd,dy_sd,dz_sd")
    page = (out / "index.html").read_text()
    assert 'id="iso9283"' in page and 'id="spread"' in page and "95% band" in page
    assert "rectangle: coverage of the 95% interval" in page and "5 contiguous blocks in measurement order" in page


def test_a_run_calibrates_every_spread_on_later_blocks_of_the_identification_set(report):
    from scipy.stats import norm
    from sklearn.base import clone

    from partcal.study.prepare import model_inputs

    def depth(train, at):               # Mahalanobis in the training inputs; a held input at the least moved sd
        sd = train.std(axis=0)
        cov = np.cov(train, rowvar=False, bias=True) + np.diag(np.where(sd > 1e-6, 0.0, sd[sd > 1e-6].min() ** 2))
        diff = at - train.mean(axis=0)
        return np.sqrt(np.einsum("ij,jk,ik->i", diff, np.linalg.pinv(cov), diff))

    def loglik(scores, d, beta):        # half-normal scores of sd c_k sqrt(1 + beta d^2), c_k at its optimum
        g2 = 1.0 + beta * d ** 2
        return sum(-0.5 * (len(d) * np.log(np.mean(col ** 2 / g2)) + np.log(g2).sum()) for col in scores.T)

    result, out = report
    metrics = json.loads((out / "metrics.json").read_text())
    ident = result.datasets["identification"]
    grew = 0
    for r in result.models:
        X, y = model_inputs(r.spec.inputs, ident), ident.errors_mm
        scores, depths = [], []         # by hand: 5 blocks in measurement order (85 rows: 17 each), each after
        for k in range(1, 5):           # the first predicted by the model fitted on the rows before it
            fold = clone(r.model).fit(X[:17 * k], y[:17 * k])
            mean, std = fold.predict_with_std(X[17 * k:17 * (k + 1)])
            scores.append(np.abs(y[17 * k:17 * (k + 1)] - mean) / std)
            depths.append(depth(X[:17 * k], X[17 * k:17 * (k + 1)]))
        scores, depths = np.vstack(scores), np.concatenate(depths)
        calibration = metrics["models"][r.spec.name]["spread_calibration"]
        beta = r.model.spread_depth_.beta if r.model.spread_depth_ is not None else 0.0
        assert calibration["depth_beta"] == pytest.approx(beta, abs=1e-6)
        assert calibration["method"] == "forward" and calibration["folds"] == 5 and calibration["depth"] is True
        assert 0.0 <= beta <= 4.0 and loglik(scores, depths, beta) >= loglik(scores, depths, 0.0) - 1e-9
        assert loglik(scores, depths, beta) >= max(loglik(scores, depths, b) for b in (beta / 2, min(2 * beta, 4.0)))
        grew += beta > 0
        expected = np.quantile(scores / np.sqrt(1.0 + beta * depths ** 2)[:, None], 0.95, axis=0) / norm.ppf(0.975)
        np.testing.assert_allclose(calibration["scale"], expected, rtol=1e-5)
        written = json.loads((out / "models" / f"{r.spec.slug}.json").read_text())
        np.testing.assert_allclose(written["spread_scale"], expected, rtol=1e-9)
        rect = model_inputs(r.spec.inputs, result.datasets["rectangle"])
        own = r.model.std_validated(rect)[1]
        growth = np.sqrt(1.0 + beta * depth(X, rect) ** 2)[:, None]
        np.testing.assert_allclose(r.spreads["rectangle"], own * expected * growth, rtol=1e-7)
    assert grew                         # some model's residuals grow towards the edges of the virtual SK120's poses


def test_a_scatter_of_many_poses_draws_an_evenly_spaced_share_and_says_so():
    from partcal.report import figures

    rng = np.random.default_rng(1)
    measured = rng.normal(0, 1, size=(12_000, 3))
    many = figures.errors_scattered("big", measured, {"M": 0.9 * measured})
    few = figures.errors_scattered("small", measured[:figures.MAX_SCATTERED], {"M": 0.9 * measured[:5000]})
    assert "(5,000 of 12,000 poses drawn, evenly spaced)" in many and "poses drawn" not in few
    assert len(many) < 1.2 * len(few)


def test_one_warning_of_several_models_is_one_bullet_naming_them(report, tmp_path):
    import dataclasses

    result, _ = report
    shared = "theta[5] comes out beyond 1 deg from nominal: kept nominal and the rest refitted"
    models = [dataclasses.replace(r, notes=[shared] + (["its own warning"] if k == 1 else []))
              for k, r in enumerate(result.models)]
    page = render_report(dataclasses.replace(result, models=models), tmp_path).read_text()
    block = page[page.index('id="fit-warnings"'):]
    bullets = [html.unescape(b) for b in re.findall(r"<li>(.*?)</li>", block[:block.index("</ul>")], flags=re.S)]
    names = [r.spec.name for r in result.models]
    assert bullets == [f"{', '.join(names)}: {shared}", f"{names[1]}: its own warning"]


def _captured(monkeypatch):
    """Figures as matplotlib keeps them (the SVG writer replaced), laid out as the SVG would be."""
    from partcal.report import figures

    kept = []
    monkeypatch.setattr(figures, "svg_of", lambda fig: kept.append(fig) or "")
    return figures, kept


def _drawn_texts(ax):
    """The axis labels and the tick labels matplotlib draws (those of ticks within the view limits)."""
    def drawn(labels, limits, coordinate):
        low, high = sorted(limits)
        return [t for t in labels if low - 1e-9 <= t.get_position()[coordinate] <= high + 1e-9]
    texts = [ax.xaxis.label, ax.yaxis.label, *drawn(ax.get_xticklabels(), ax.get_xlim(), 0),
             *drawn(ax.get_yticklabels(), ax.get_ylim(), 1)]
    return [t for t in texts if t.get_visible() and t.get_text()]


def _overlap(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def test_a_figure_legend_covers_no_axis_label_tick_label_or_curve(monkeypatch):
    figures, kept = _captured(monkeypatch)
    rng = np.random.default_rng(0)
    measured = rng.normal(0, 3, size=(300, 3)) - 20
    predicted = measured + rng.normal(0, 1, size=(300, 3))
    spread = np.full((300, 3), 0.8)
    figures.errors_scattered("C", measured, {"SDP(AI)": predicted}, {"SDP(AI)": spread})
    figures.errors_along_path("rectangle", measured, {"SDP(AI)": predicted, "GP": 0.5 * predicted},
                              {"SDP(AI)": spread})
    figures.residual_histogram("rectangle", {"uncompensated": measured, "SDP(AI)": measured - predicted})
    for fig in kept:
        renderer = fig.canvas.get_renderer()
        legends = [*fig.legends, *(ax.get_legend() for ax in fig.axes if ax.get_legend() is not None)]
        assert legends
        for legend in legends:
            box = legend.get_window_extent(renderer)
            for ax in fig.axes:
                for t in _drawn_texts(ax):
                    assert not _overlap(box, t.get_window_extent(renderer)), t.get_text()
                assert not _overlap(box, ax.get_window_extent(renderer))          # not over the data
        for ax in fig.axes:                  # the labels of one axes never touch each other
            boxes = [t.get_window_extent(renderer) for t in _drawn_texts(ax)]
            assert not any(_overlap(a, b) for i, a in enumerate(boxes) for b in boxes[i + 1:])


def test_poses_measured_in_clusters_are_scattered_poses_drawn_as_points(monkeypatch):
    # The IPA UR10's series B: each joint configuration measured in a cluster of poses a few mm apart, then a
    # jump of about 100 mm to the next one: the median step is short, but the way is travelled in the jumps.
    rng = np.random.default_rng(3)
    centres = rng.uniform(0, 1000, (100, 3))
    clusters = np.repeat(centres, 10, axis=0) + rng.uniform(-2, 2, (1000, 3))
    figures, kept = _captured(monkeypatch)
    steps = np.linalg.norm(np.diff(clusters, axis=0), axis=1)
    assert np.median(steps) < 0.05 * np.linalg.norm(np.ptp(clusters, axis=0))     # short steps, mostly
    assert not figures.is_path(clusters)
    assert figures.is_path(np.c_[np.linspace(0, 1000, 300), np.zeros(300), np.ones(300)])
    rect = np.concatenate([np.c_[np.linspace(0, 400, 50), np.zeros(50), np.zeros(50)],
                           np.c_[np.full(50, 400.0), np.linspace(0, 300, 50), np.zeros(50)]])
    assert figures.is_path(rect)


def test_the_identification_observability_and_the_kinematic_fit_say_how_they_differ(tmp_path):
    from partcal.report import kept_as_implausible

    (tmp_path / "run.yaml").write_text(f"""name: dh
robot: motoman_sk120
cv_folds: 3
data:
  identification: {DATA / 'identification.csv'}
  tests:
    rectangle: {DATA / 'test_rectangle.csv'}
models:
  - {{name: DH, kind: kinematic}}
""")
    result = run(load_config(tmp_path / "run.yaml"))
    page = render_report(result, tmp_path).read_text()
    ev = result.design
    table = result.models[0].model.identification_
    # The plan (at nominal, columns in mm of tool motion) and the fit (unit columns) keep different members of
    # the groups of parameters with one effect: on the SK120's 85 poses the same count, other names.
    planned = set(ev.identified)
    fitted = {n for n, s in zip(table.names, table.status) if s == "identified"}
    assert len(planned) == len(fitted) == 19 and planned != fitted
    block = page[page.index('id="design-indices"'):page.index('id="comparison"')]
    assert f"of its {len(table.names)} parameters they identify {len(planned)}" in block
    assert len(ev.identified) + len(ev.missing) + len(ev.never) == len(table.names) == 41
    assert ", ".join(ev.never) in block and "This is the plan, not the fit" in block
    assert "may keep different members of such a group" in block
    summary = page[page.index('class="kinematic-summary"'):]
    summary = summary[:summary.index("</p>")]
    assert f"{len(fitted)} of {len(table.names)} parameters identified" in summary
    assert "with unit columns at the identified values" in summary and "beyond a plausible range" not in summary
    assert f"not identifiable from these data ({len(table.names) - len(fitted) - table.status.count('fixed')})" in summary
    # A fit that keeps identifiable parameters nominal as implausible names them apart, from its warnings.
    note = ("{} comes out beyond 1 deg from nominal (10 times a plausible manufacturing error), and the data "
            "do not fix it (nominal is within 3 standard errors): kept nominal and the rest refitted")
    fake = type("R", (), {"notes": [note.format("theta[5]"), "spread calibration: ... the first: "
                                    + note.format("alpha[5]"), note.format("alpha[5]")]})()
    assert kept_as_implausible(fake, ["theta[5]", "alpha[5]", "d[2]"], 2) == ["theta[5]", "alpha[5]"]
    assert kept_as_implausible(fake, ["theta[5]", "alpha[5]"], 1) == []        # not exactly the count: none named


@needs_chromium
def test_every_table_fits_the_page_width(report, tmp_path):
    from partcal.report.browser import open_report

    _, out = report
    check = open_report(out / "index.html", width=800)
    assert "spread" not in check.wider_than_page              # its headers wrap: nothing cut in a screenshot


def test_a_partition_picture_names_its_regions_beside_the_scene():
    import io

    import matplotlib.colors as mcolors
    import matplotlib.image as mpimg

    from partcal.report.scene import SCENE_SHARE, legend_entries, region_colour, render_scenes

    rng = np.random.default_rng(0)
    points = rng.uniform(0, 1000, (90, 3))
    labels = (points[:, 0] // 334).astype(int)                     # three slabs along x
    path = np.c_[np.linspace(100, 900, 50), np.full(50, 500.0), np.full(50, 500.0)]
    spec = {"points": points, "labels": labels, "boxes": np.zeros((0, 2, 3)), "n_paths": 1, "path0": path,
            "residual0": np.linspace(0, 2, 50), "joined0": np.asarray(True), "residual_max": 2.0}
    pngs, problem = render_scenes({"m": spec})
    if problem:
        pytest.skip(f"no 3-D rendering here: {problem}")
    image = mpimg.imread(io.BytesIO(pngs["m"]), format="png")[:, :, :3]
    side = image[:, int(SCENE_SHARE * image.shape[1]) + 2:]         # the column beside the scene
    assert [text for text, _ in legend_entries(labels)] == ["region 1", "region 2", "region 3"]
    for k in range(3):                                             # each region's colour in the legend
        colour = np.array(mcolors.to_rgb(region_colour(k)))
        assert (np.abs(side - colour).max(axis=2) < 0.08).sum() > 20, k


def test_the_scatter_panels_keep_their_tick_labels_apart(monkeypatch):
    figures, kept = _captured(monkeypatch)
    rng = np.random.default_rng(2)
    measured = rng.normal([-0.5, 0.8, -0.2], [0.5, 0.5, 0.4], size=(2773, 3))     # the IPA UR10's random poses
    predicted = measured * 0.6 + rng.normal(0, 0.3, size=(2773, 3))
    figures.errors_scattered("random_poses", measured, {"DH + GP(AI)": predicted, "k-means": predicted + 0.01})
    fig = kept[0]
    renderer = fig.canvas.get_renderer()

    def texts(ax):
        return [t.get_window_extent(renderer) for t in _drawn_texts(ax)]
    for a in fig.axes:
        for b in fig.axes:
            if a is not b:                   # one panel's labels never run into the next panel or its labels
                assert not any(_overlap(t, a.get_window_extent(renderer)) for t in texts(b))
                assert not any(_overlap(s, t) for s in texts(a) for t in texts(b))


def test_a_run_on_data_without_error_reports_that_there_was_none_to_reduce(tmp_path):
    """Measured = nominal everywhere: every model's error left is 0 of 0 before, which is no change in percent
    (the report divided by the uncompensated RMS and crashed with ZeroDivisionError, exit 1)."""
    from conftest import partcal_cli

    for name in ("identification", "test_rectangle"):
        lines = [line.split(",") for line in (DATA / f"{name}.csv").read_text().splitlines() if line[:1] != "#"]
        at = {c: lines[0].index(c) for c in lines[0]}
        for row in lines[1:]:
            for axis in "xyz":
                row[at[f"{axis}_meas"]] = row[at[f"{axis}_nom"]]
        (tmp_path / f"{name}.csv").write_text("".join(",".join(row) + "\n" for row in lines))
    (tmp_path / "run.yaml").write_text("name: exact\nrobot: motoman_sk120\ncv_folds: 3\ndata:\n"
                                       "  identification: identification.csv\n  tests:\n"
                                       "    rectangle: test_rectangle.csv\nmodels:\n"
                                       "  - {name: FDP(CI), degree: 1, solver: {method: lstsq}}\noutput: out\n")
    done = partcal_cli("run", str(tmp_path / "run.yaml"))
    assert done.returncode == 0, done.stderr
    text = (tmp_path / "out" / "index.html").read_text()
    assert "from 0.00 to 0.00 mm (no error before to reduce)" in text
