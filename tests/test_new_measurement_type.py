"""A measurement type added from this module alone (docs/architecture.md, "Adding a measurement type"): a height
gauge read in inches, with a section of its own in the cell's description and a simulate hook, runs through
``partcal simulate``, ``partcal run`` and ``partcal plan --evaluate`` with nothing added to partcal/."""

import json

import numpy as np
import pytest

from partcal.calibration.measurement import Column, MeasurementRows, MeasurementType, Residuals
from partcal.calibration.registry import MEASUREMENT_TYPES, add_measurement_type
from partcal.cli import main

MM_PER_IN = 25.4
TRUE_ZERO_IN = {"g1": 12.0, "g2": 30.0}


class Gauge(MeasurementType):
    """A dial gauge fixed in the cell reads the tool tip's height above its zero, in inches: ``(z - zero) / 25.4``.
    Each gauge's zero is an unknown of the type (mm), or known (``zero_in`` in the cell's ``gauges:``)."""

    name = "gauge"
    unit = "in"
    default_noise = 0.0004
    columns = {"gauge": Column(text=True, required=True), "reading_in": Column("in", required=True)}
    summary = "the tool tip's height above gauge `gauge`'s zero, read in inches"
    cell_section, feature_column = "gauges", "gauge"

    def __init__(self, rows, index, cell, noise):
        super().__init__(rows, index, cell, noise)
        self.gauge = rows.text("gauge", index)
        self.reading = rows.number("reading_in", index)
        known = cell.get("gauges") or {}
        self.unknown = [g for g in dict.fromkeys(self.gauge) if "zero_in" not in known.get(g, {})]
        self.known = {g: float(s["zero_in"]) * MM_PER_IN for g, s in known.items() if "zero_in" in s}

    @classmethod
    def read_section(cls, sec) -> dict:
        out = {}
        for name in list(sec.data):
            entry = sec.section(name)
            out[name] = {"zero_in": entry.get("zero_in", "float")} if entry.has("zero_in") else {}
            entry.done()
        return out

    def unknowns(self, positions, rotations):
        names = [(f"gauge {g}.zero", "mm") for g in self.unknown]
        start = [float(np.median(positions[self.index[[x == g for x in self.gauge]], 2] -
                                 MM_PER_IN * self.reading[[x == g for x in self.gauge]])) for g in self.unknown]
        return names, np.array(start)

    def residuals(self, positions, rotations, u):
        m = self.index.size
        zero, du = np.empty(m), np.zeros((m, u.size))
        for i, g in enumerate(self.gauge):
            if g in self.unknown:
                k = self.unknown.index(g)
                zero[i], du[i, k] = u[k], -1.0 / MM_PER_IN
            else:
                zero[i] = self.known[g]
        grad = np.zeros((m, 3))
        grad[:, 2] = 1.0 / MM_PER_IN
        values = (positions[self.index, 2] - zero) / MM_PER_IN - self.reading
        return Residuals(values, self.index.copy(), grad, du)

    def moved(self, u, omega, shift):
        return np.full_like(u, shift[2])          # the gauges stand in the cell: a shift along z moves their zeros

    @classmethod
    def simulate(cls, truth, spec, rng, noise):
        """``spec``: gauge name -> readings; each at poses drawn by the truth, the true zero from the true cell."""
        qs, names, readings = [], [], []
        for gauge, count in spec.items():
            q = truth.sample(int(count), rng)
            z = truth.positions(q)[:, 2]
            zero_mm = float(truth.cell["gauges"][gauge]["zero_in"]) * MM_PER_IN
            qs.append(q)
            names += [gauge] * len(q)
            readings.append((z - zero_mm) / MM_PER_IN + rng.normal(0.0, noise, len(q)))
        q = np.vstack(qs)
        return MeasurementRows(q, ("gauge",) * len(q), tuple(str(i + 1) for i in range(len(q))),
                               tuple(range(1, len(q) + 1)), "gauges", {"reading_in": np.concatenate(readings)},
                               {"gauge": tuple(names)})


@pytest.fixture(scope="module")
def registered():
    add_measurement_type(Gauge)
    yield
    del MEASUREMENT_TYPES["gauge"]


VIRTUAL = """robot: universal_robots_ur10
seed: 7
output: data
errors:
  dh_sigma: {length_mm: 0.5, twist_deg: 0.03, zero_offset_deg: 0.05}
  tool_mm: [0.3, -0.2, 0.4]
  base: {rotation_deg: [0.02, -0.03, 0.04], translation_mm: [1.0, -0.5, 0.8]}
tracker: {position_mm: [2500, 0, 0], accuracy_ppm: 0, repeatability_ppm: 10, readings: 1}
sampling:
  ranges_deg: {q1: [-90, 90], q2: [-150, -30], q3: [-140, 140], q4: [-180, 180], q5: [-150, 150], q6: [-180, 180]}
cell:
  planes:
    top:  {normal: [0, 0, 1], offset_mm: 500}
    side: {normal: [1, 0, 0.02], offset_mm: 600}
  gauges:
    g1: {zero_in: 12.0}
    g2: {zero_in: 30.0}
datasets:
  touches: {plane: {top: 120, side: 120}, noise: 0.01}
  heights: {gauge: {g1: 60, g2: 60}, noise: 0.0004}
  test:    {sample: 150}
"""

RUN = """name: gauges
robot: universal_robots_ur10
seed: 0
data:
  identification: [data/touches.csv, data/heights.csv]
  cell: data/cell.yaml
  tests: {test: data/test.csv}
models:
  - {name: DH, kind: kinematic}
output: out
"""


def test_a_type_added_here_is_simulated_run_and_evaluated_through_the_command_line(registered, tmp_path, capsys):
    (tmp_path / "virtual.yaml").write_text(VIRTUAL)
    assert main(["simulate", str(tmp_path / "virtual.yaml")]) == 0, capsys.readouterr().err
    data = tmp_path / "data"
    header = [x for x in (data / "heights.csv").read_text().splitlines() if not x.startswith("#")][0]
    assert header == "q1,q2,q3,q4,q5,q6,measurement,id,reading_in,gauge"
    assert "gauges:\n  g1: {}\n  g2: {}" in (data / "cell.yaml").read_text()    # what the cell knows: unknown zeros

    (tmp_path / "run.yaml").write_text(RUN)
    assert main(["run", "-q", str(tmp_path / "run.yaml")]) == 0, capsys.readouterr().err
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert metrics["measurement_types"]["gauge"] == "120 gauge rows; noise 0.0004 in"
    entry = metrics["models"]["DH"]
    assert 0.0002 < entry["cv_rms_by_type"]["gauge"] < 0.0008         # held out: the gauges' 0.0004 in
    assert entry["tests"]["test"]["rigid_fit"] and entry["tests"]["test"]["rms_3d"] < 0.1
    model = json.loads((tmp_path / "out" / "models" / "dh.json").read_text())
    table = model["model"]["identification"]
    zero = {n: v for n, v in zip(table["names"], table["value"]) if n.startswith("gauge ")}
    assert set(zero) == {"gauge g1.zero", "gauge g2.zero"}      # in the base frame the touches fixed, after a fit
    spread = zero["gauge g2.zero"] - zero["gauge g1.zero"]
    assert spread == pytest.approx((TRUE_ZERO_IN["g2"] - TRUE_ZERO_IN["g1"]) * MM_PER_IN, abs=0.5)

    capsys.readouterr()
    assert main(["plan", "universal_robots_ur10", "--evaluate", str(data / "heights.csv"),
                 "--cell", str(data / "cell.yaml")]) == 0
    said = capsys.readouterr().out
    assert "120 gauge rows" in said and "held nominal" in said


def test_a_gauge_row_without_its_reading_is_refused_naming_file_line_and_column(registered, tmp_path, capsys):
    rows = tmp_path / "heights.csv"
    rows.write_text("q1,q2,q3,q4,q5,q6,measurement,gauge,reading_in\n0,-90,90,0,90,0,gauge,g1,\n")
    (tmp_path / "cell.yaml").write_text("gauges: {g1: {}}\n")
    assert main(["plan", "universal_robots_ur10", "--evaluate", str(rows), "--cell", str(tmp_path / "cell.yaml")]) == 2
    err = capsys.readouterr().err
    assert f"{rows}:2: column 'reading_in': expected a value on a gauge row (gauge rows read gauge, reading_in)" in err
