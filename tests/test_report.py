"""The HTML report, opened in headless Chromium as an engineer would open it."""

import json
import re
import shutil

import html5lib
import pytest
from conftest import ROOT

from partcal.report import render_report
from partcal.study.config import load_config
from partcal.study.outputs import write_run
from partcal.study.registry import run

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
