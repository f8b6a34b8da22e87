"""Model files: bit-for-bit round trips, refusal of damaged and foreign files."""

import json

import numpy as np
import pytest
from conftest import ROOT

from partcal import ModelFileError, load_robot, read_measurements
from partcal.models.partition import KMeansPartition, Octree
from partcal.models.partitioned import PartitionedErrorModel
from partcal.models.series import ErrorModel
from partcal.study.persist import load_model, save_model
from partcal.study.predictor import load_predictor

IDENT = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
MODELS = [
    ("cartesian", ErrorModel(degree=2, solver="pso", random_state=0)),
    ("joint", ErrorModel(inputs="joint", basis="fourier", harmonics=2, solver="lstsq")),
    ("cartesian", ErrorModel(degree=2, cross_terms=True, solver="lstsq")),
    ("cartesian", PartitionedErrorModel(partition=Octree(max_depth=1, min_samples=12),
                                        local=ErrorModel(solver="lstsq"), random_state=0)),
    ("joint", PartitionedErrorModel(partition=KMeansPartition(3), local=ErrorModel(inputs="joint", solver="lstsq"),
                                    blend="hard", random_state=0)),
]


@pytest.mark.parametrize("inputs, model", MODELS)
def test_round_trip_reproduces_predictions_bit_for_bit(tmp_path, inputs, model):
    X = IDENT.nominal_mm if inputs == "cartesian" else IDENT.q_deg
    model.fit(X, IDENT.errors_mm)
    path = tmp_path / "m.json"
    save_model(model, path, name="demo", robot=load_robot("motoman_sk120"))
    loaded, doc = load_model(path)
    query = X + np.random.default_rng(0).normal(0, 5, X.shape)
    assert np.array_equal(loaded.predict(query), model.predict(query))
    assert doc["format"] == "partcal-model" and doc["version"] == 2 and doc["name"] == "demo"
    assert load_predictor(path).robot.name == "motoman_sk120"
    assert "pickle" not in path.read_text()


def test_damaged_and_foreign_files_are_refused(tmp_path):
    model = ErrorModel(solver="lstsq").fit(IDENT.nominal_mm, IDENT.errors_mm)
    path = tmp_path / "m.json"
    save_model(model, path)
    good = json.loads(path.read_text())

    def refused(doc, match):
        bad = tmp_path / "bad.json"
        bad.write_text(doc if isinstance(doc, str) else json.dumps(doc))
        with pytest.raises(ModelFileError, match=match):
            load_model(bad)

    refused("{not json", r"bad.json: not a partcal model file \(invalid JSON at line 1")
    refused({**good, "format": "sklearn"}, r"field 'format': expected 'partcal-model'")
    refused({**good, "version": 3}, r"field 'version': this partcal reads versions 1, 2; the file has version 3")
    refused({k: v for k, v in good.items() if k != "kind"}, r"field 'kind': missing")
    coef = json.loads(json.dumps(good))
    coef["model"]["coef"] = coef["model"]["coef"][:-1]
    refused(coef, r"field 'model.coef': expected finite numbers of shape \(4, 3\); got shape \(3, 3\)")
    nan = json.loads(json.dumps(good))
    nan["model"]["scaling"]["centre"][0] = "NaN"
    refused(nan, r"field 'model.scaling.centre': holds a non-finite value")
    refused([1, 2], r"field 'top level': expected an object; got list")
    with pytest.raises(ModelFileError, match=r"nope.json: no such model file"):
        load_model(tmp_path / "nope.json")
