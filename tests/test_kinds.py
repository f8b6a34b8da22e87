"""A model kind is one unit: a kind defined here, outside partcal, runs through everything.

The toy kind predicts a constant offset, the mean error of its training data.
It is registered in the one table of kinds and then goes through a YAML run,
a model file, ``load_predictor`` and the report without any change to partcal.
"""

import json

import numpy as np
import pytest
from conftest import ROOT
from sklearn.utils.validation import check_is_fitted, validate_data

from partcal._validation import one_of, real
from partcal.cli import main
from partcal.data.measurements import read_measurements
from partcal.errors import ConfigError, ModelFileError, PartcalError
from partcal.metrics import distance_outside_boxes
from partcal.models.base import ErrorModelBase
from partcal.models.kinds import KINDS, Kind, register_kind, unregister_kind
from partcal.study.config import load_config
from partcal.study.predictor import load_predictor

DATA = ROOT / "data" / "sk120"


class ConstantOffset(ErrorModelBase):
    """The mean error of the training data, times ``gain``, whatever the inputs."""

    kind = "constant_offset"
    _parameter_rules = {"inputs": one_of("cartesian", "joint"), "gain": real(0.0, 1.0, default=1.0)}

    def __init__(self, *, inputs="cartesian", gain=1.0, random_state=None):
        self.inputs = inputs
        self.gain = gain
        self.random_state = random_state

    def fit(self, X, y, sample_weight=None):          # no _check_rules(): the base runs the declared rules
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        self._y_1d = y.ndim == 1
        Y = y.reshape(len(y), -1)
        w = np.ones(len(Y)) if sample_weight is None else np.asarray(sample_weight, dtype=float)
        self.offset_ = self.gain * (w @ Y) / w.sum()
        self.n_outputs_ = Y.shape[1]
        self.data_bounds_ = np.stack([X[w > 0].min(axis=0), X[w > 0].max(axis=0)])
        return self

    def region_minimum(self, n_active):               # what a partition asks of a kind registered regions=True
        return 2, "2 samples for a mean", "partition"

    def predict(self, X):
        check_is_fitted(self, "offset_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self._shape_output(np.tile(self.offset_, (len(X), 1)))

    def distance_to_data(self, X):
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return distance_outside_boxes(X, self.data_bounds_[:1], self.data_bounds_[1:])

    def describe(self):
        return f"a constant offset ({self.gain:g} times the mean error)"

    def file_section(self):
        return {"gain": self.gain, "offset": self.offset_.tolist(), "data_bounds": self.data_bounds_.tolist()}

    @classmethod
    def from_file_section(cls, r, inputs, n_in, n_out):
        model = cls(inputs=inputs, gain=r.rule("gain", cls._parameter_rules["gain"]))
        model.offset_ = r.array("offset", (n_out,))
        model.data_bounds_ = r.array("data_bounds", (2, n_in))
        model.n_features_in_, model.n_outputs_, model._y_1d = n_in, n_out, False
        return model


@pytest.fixture
def offset_kind():
    kind = register_kind(Kind("constant_offset", ConstantOffset))
    yield kind
    unregister_kind("constant_offset")


@pytest.fixture
def regional_offset_kind():
    kind = register_kind(Kind("constant_offset", ConstantOffset, regions=True))
    yield kind
    unregister_kind("constant_offset")


def run_config(tmp_path, models: str) -> str:
    path = tmp_path / "run.yaml"
    path.write_text(f"""name: toy
robot: motoman_sk120
cv_folds: 4
data:
  identification: {DATA / 'identification.csv'}
  tests:
    rectangle: {DATA / 'test_rectangle.csv'}
models:
{models}
output: {tmp_path / 'out'}
""")
    return path


def test_a_kind_defined_outside_partcal_runs_through_config_model_file_predictor_and_report(offset_kind, tmp_path):
    config = run_config(tmp_path, "  - {name: Offset, kind: constant_offset, gain: 0.5}\n"
                                  "  - {name: FDP(CI), solver: {method: lstsq}}\n")
    assert main(["run", str(config), "-q"]) == 0
    ident = read_measurements(DATA / "identification.csv")
    rect = read_measurements(DATA / "test_rectangle.csv")
    offset = 0.5 * ident.errors_mm.mean(axis=0)                   # the toy model, computed here

    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    entry = metrics["models"]["Offset"]
    assert entry["kind"] == "constant_offset" and entry["solver"] == "-" and entry["regions"] == 1
    for name, m in (("identification", ident), ("rectangle", rect)):
        np.testing.assert_allclose(entry[name]["rms"], np.sqrt(np.mean((m.errors_mm - offset) ** 2, axis=0)),
                                   rtol=1e-12)

    predictor = load_predictor(tmp_path / "out" / "models" / "offset.json")
    assert predictor.document["kind"] == "constant_offset" and predictor.inputs == "cartesian"
    np.testing.assert_allclose(predictor.predict(positions=rect.nominal_mm[:7]), np.tile(offset, (7, 1)),
                               rtol=1e-12)
    np.testing.assert_allclose(predictor.predict(joints=rect.q_deg[:3]), np.tile(offset, (3, 1)), rtol=1e-12)
    np.testing.assert_allclose(predictor.compensate(rect.nominal_mm[:5]), rect.nominal_mm[:5] - offset, atol=1e-9)

    html = (tmp_path / "out" / "index.html").read_text()
    assert 'data-model="Offset"' in html                           # a row of the comparison table
    assert "<b>Offset</b>: a constant offset (0.5 times the mean error)" in html
    assert "Global Cartesian-input models (2)" in html                # one family with the series model


def test_a_registered_kind_applies_its_declared_rules_in_config_and_model_file(offset_kind, tmp_path):
    config = run_config(tmp_path, "  - {name: Offset, kind: constant_offset, gain: 2}\n")
    with pytest.raises(ConfigError, match=r"models\[0\]\.gain \(line \d+\): must be a real number in "
                                          r"\[0\.0, 1\.0\]; got 2\.0"):
        load_config(config)
    config = run_config(tmp_path, "  - {name: Offset, kind: constant_offset, degree: 2}\n")
    with pytest.raises(ConfigError, match=r"models\[0\]\.degree \(line \d+\): applies to kind: series only; "
                                          r"this entry is kind: constant_offset"):
        load_config(config)
    with pytest.raises(PartcalError, match=r"The 'gain' parameter of ConstantOffset must be a real number in "
                                           r"\[0\.0, 1\.0\]\. Got -1 instead\."):
        ConstantOffset(gain=-1).fit(np.zeros((3, 3)), np.zeros((3, 3)))

    config = run_config(tmp_path, "  - {name: Offset, kind: constant_offset}\n")
    assert main(["run", str(config), "-q"]) == 0
    path = tmp_path / "out" / "models" / "offset.json"
    doc = json.loads(path.read_text())
    del doc["checksum"]
    doc["model"]["gain"] = 3.5
    path.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match=r"field 'model\.gain': expected a real number in \[0\.0, 1\.0\]; "
                                             r"got 3\.5"):
        load_predictor(path)


def test_the_table_refuses_a_name_taken_and_a_class_that_disagrees(offset_kind):
    with pytest.raises(PartcalError, match="kind 'constant_offset' .* is taken by kind 'constant_offset'"):
        register_kind(Kind("constant_offset", ConstantOffset))
    with pytest.raises(PartcalError, match="its estimator's class attribute 'kind' is 'constant_offset'"):
        register_kind(Kind("offset2", ConstantOffset))
    with pytest.raises(PartcalError, match="'series' is built in"):
        unregister_kind("series")
    assert set(KINDS) >= {"series", "gaussian_process", "kinematic", "partitioned", "constant_offset"}


def test_a_kind_registered_as_a_residual_runs_as_a_hybrids_residual(offset_kind, tmp_path):
    """The table's ``residual`` flag is the only statement of who may be a residual: the toy kind (registered
    with the default ``residual=True``) is a kinematic entry's residual in a run and in its model file."""
    from partcal import KinematicModel, load_robot

    config = run_config(tmp_path, "  - {name: DH + offset, kind: kinematic, "
                                  "residual: {kind: constant_offset, inputs: joint, gain: 1.0}}\n")
    assert main(["run", str(config), "-q"]) == 0
    ident = read_measurements(DATA / "identification.csv")
    rect = read_measurements(DATA / "test_rectangle.csv")
    dh = KinematicModel(robot=load_robot("motoman_sk120")).fit(ident.q_deg, ident.errors_mm)
    left = ident.errors_mm - dh.predict(ident.q_deg)
    expected = dh.predict(rect.q_deg) + left.mean(axis=0)                  # the toy residual, computed here
    predictor = load_predictor(tmp_path / "out" / "models" / "dh-offset.json")
    np.testing.assert_allclose(predictor.predict(joints=rect.q_deg), expected, atol=1e-9)
    with pytest.raises(ValueError, match="may be a residual"):
        KinematicModel(robot="motoman_sk120", residual=KinematicModel(robot="motoman_sk120")).fit(
            ident.q_deg, ident.errors_mm)


def test_a_kind_registered_with_regions_runs_partitioned_in_a_run(regional_offset_kind, tmp_path):
    """A kind whose row says ``regions=True`` is a partition's local model through its public ``fit`` (with
    ``sample_weight``) and ``region_minimum``: nothing in partcal names it. Hard blend of an octree of depth 1:
    every octant of the identification data's box predicts its own samples' mean error, times the gain."""
    config = run_config(tmp_path, "  - {name: Offset regions, kind: constant_offset, gain: 0.5, "
                                  "partition: {method: octree, max_depth: 1, min_samples: 2}, "
                                  "blend: {method: hard}}\n")
    assert main(["run", str(config), "-q"]) == 0
    ident = read_measurements(DATA / "identification.csv")
    P, E = ident.nominal_mm, ident.errors_mm
    lo, hi = P.min(axis=0), P.max(axis=0)
    octant = ((P >= (lo + hi) / 2) * [1, 2, 4]).sum(axis=1)              # the octree's one split, written here
    expected = np.empty_like(E)
    for k in np.unique(octant):
        expected[octant == k] = 0.5 * E[octant == k].mean(axis=0)

    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    entry = metrics["models"]["Offset regions"]
    assert entry["kind"] == "constant_offset" and entry["regions"] == len(np.unique(octant)) > 1
    np.testing.assert_allclose(entry["identification"]["rms"], np.sqrt(np.mean((E - expected) ** 2, axis=0)),
                               rtol=1e-12)
    predictor = load_predictor(tmp_path / "out" / "models" / "offset-regions.json")
    assert predictor.document["kind"] == "partitioned" and predictor.document["local_kind"] == "constant_offset"
    np.testing.assert_allclose(predictor.predict(positions=P), expected, atol=1e-9)
    html = (tmp_path / "out" / "index.html").read_text()
    assert "a constant offset (0.5 times the mean error) in each of" in html


def test_a_kinds_declared_rules_are_checked_on_every_fit_without_the_kind_asking(offset_kind):
    """``ConstantOffset.fit`` never calls ``_check_rules()``; the base checks the declared rules before it runs,
    in a partition's regions too."""
    from partcal.models.partition import Octree
    from partcal.models.partitioned import PartitionedErrorModel

    X, y = np.random.default_rng(0).normal(size=(20, 3)), np.zeros((20, 3))
    with pytest.raises(PartcalError, match=r"The 'gain' parameter of ConstantOffset must be a real number in "
                                           r"\[0\.0, 1\.0\]\. Got 7 instead\."):
        ConstantOffset(gain=7).fit(X, y)
    with pytest.raises(PartcalError, match=r"The 'inputs' parameter of ConstantOffset must be one of"):
        ConstantOffset(inputs="polar").fit(X, y, sample_weight=np.ones(20))
    unregister_kind("constant_offset")
    register_kind(Kind("constant_offset", ConstantOffset, regions=True))
    with pytest.raises(PartcalError, match=r"The 'gain' parameter of ConstantOffset must be a real number"):
        PartitionedErrorModel(partition=Octree(max_depth=1, min_samples=2), local=ConstantOffset(gain=-1),
                              blend="hard").fit(X, y)


def test_a_kind_not_registered_for_regions_is_refused_as_a_local_model(offset_kind):
    from partcal.models.partitioned import PartitionedErrorModel

    with pytest.raises(PartcalError, match=r"The 'local' parameter of PartitionedErrorModel must be .*"
                                           r"\(series, gaussian_process\)"):
        PartitionedErrorModel(local=ConstantOffset()).fit(np.zeros((20, 3)), np.zeros((20, 3)))


def test_what_only_some_kinds_answer_is_asked_through_the_table(offset_kind):
    """The toy kind states no swarm, equations, regions or identification; the table answers for it."""
    from partcal.models.kinds import (equations_of, identification_of, is_physical, pso_rms_ratio, regions_of,
                                      run_summary, swarm_runs)
    from partcal.models.series import ErrorModel

    X = read_measurements(DATA / "identification.csv")
    toy = ConstantOffset().fit(X.nominal_mm, X.errors_mm)
    assert (equations_of(toy), regions_of(toy), identification_of(toy), pso_rms_ratio(toy)) == (None,) * 4
    assert swarm_runs(toy) == [] and run_summary(toy) == {} and is_physical(toy) is False
    series = ErrorModel(solver="lstsq").fit(X.nominal_mm, X.errors_mm)
    assert len(equations_of(series)) == 3 and pso_rms_ratio(series) is None and regions_of(series) is None
    for name in ("equations", "swarm_runs", "pso_rms_ratio", "regions_model", "identification", "run_summary",
                 "is_physical", "reads_targets", "takes_residual", "fits_pose_errors", "own_prior"):
        assert not hasattr(ErrorModelBase, name), name


def test_the_contract_documented_is_the_base_class_and_its_table_columns():
    """docs/architecture.md lists ErrorModelBase's public members and the table's columns: exactly those."""
    import dataclasses
    import re

    from partcal.models.kindtable import Kind as Row

    text = (ROOT / "docs" / "architecture.md").read_text()
    section = text[text.index("## Adding a model kind"):]
    members_table = section[section.index("| group | members |"):section.index("(`set_score_request`")]
    rows = [line for line in members_table.splitlines()[2:] if line.startswith("| ")]
    documented = {name for line in rows for name in re.findall(r"`(\w+)`", line.split("|")[2])}
    public = {n for n in vars(ErrorModelBase) if not n.startswith("_")} - {"set_score_request"}
    assert documented == public
    assert f"({len(public)} names besides scikit-learn's own" in section
    columns_table = section[section.index("| column | default |"):]
    columns = {re.findall(r"`(\w+)`", line.split("|")[1])[0] for line in columns_table.splitlines()[2:]
               if line.startswith("| `")}
    assert columns == {f.name for f in dataclasses.fields(Row)} - {"name", "estimator"}
