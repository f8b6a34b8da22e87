"""Model files: bit-for-bit round trips, refusal of damaged and foreign files."""

import json
import re

import numpy as np
import pytest
from conftest import ROOT
from sklearn.base import clone

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
    far = query + [0.0, 0.0, 400.0] if inputs == "cartesian" else query + 100.0
    assert np.array_equal(loaded.distance_to_data(far), model.distance_to_data(far))   # the samples are kept
    assert np.array_equal(loaded.train_inputs_, X)


def test_files_without_training_inputs_fall_back_to_box_distances():
    """Model files of partcal 0.1 keep no samples: the distance is then the one outside the data's boxes."""
    from partcal.metrics import distance_outside_boxes

    for name in ("v0.1_sdp-ci.json", "v0.1_fdp-ci-octree.json"):
        model, doc = load_model(ROOT / "tests" / "fixtures" / name)
        assert "train_inputs" not in doc and model.train_inputs_ is None
        far = IDENT.nominal_mm[:5] + [0.0, 0.0, 500.0]
        if doc["kind"] == "global":
            low, high = model.data_bounds_[:1], model.data_bounds_[1:]
        else:
            low, high = model.region_bounds_[:, 0], model.region_bounds_[:, 1]
        np.testing.assert_array_equal(model.distance_to_data(far), distance_outside_boxes(far, low, high))
    kmeans, doc = load_model(ROOT / "tests" / "fixtures" / "v0.1_fdp-ai-kmeans.json")
    assert "active" not in doc["partition"]
    assert kmeans.partition_.active.tolist() == [True, True, True, False, False, True]   # q4, q5 held at 0


def test_damaged_and_foreign_files_are_refused(tmp_path):
    model = ErrorModel(solver="lstsq").fit(IDENT.nominal_mm, IDENT.errors_mm)
    path = tmp_path / "m.json"
    save_model(model, path)
    good = json.loads(path.read_text())

    def refused(doc, match):
        bad = tmp_path / "bad.json"
        if isinstance(doc, dict):
            doc = {k: v for k, v in doc.items() if k != "checksum"}    # edits on purpose: the field checks must hold
        bad.write_text(doc if isinstance(doc, str) else json.dumps(doc))
        with pytest.raises(ModelFileError, match=match):
            load_model(bad)

    refused("{not json", r"bad.json: not a partcal model file \(invalid JSON at line 1")
    refused('{"version": ' + "9" * 5001 + "}", r"bad.json: not a partcal model file \(Exceeds the limit")
    refused("[" * 100_000, r"bad.json: not a partcal model file \(maximum recursion depth exceeded")
    refused({**good, "format": "sklearn"}, r"field 'format': expected 'partcal-model'")
    refused({**good, "version": 3}, r"field 'version': this partcal reads versions 1, 2; the file has version 3")
    refused({k: v for k, v in good.items() if k != "kind"}, r"field 'kind': missing")
    coef = json.loads(json.dumps(good))
    coef["model"]["coef"] = coef["model"]["coef"][:-1]
    refused(coef, r"field 'model.coef': expected shape \(4, 3\); got shape \(3, 3\)")
    nan = json.loads(json.dumps(good))
    nan["model"]["scaling"]["centre"][0] = "NaN"
    refused(nan, r"field 'model.scaling.centre': expected float values; found str 'NaN'")
    refused([1, 2], r"field 'top level': expected an object; got list")
    with pytest.raises(ModelFileError, match=r"nope.json: no such model file"):
        load_model(tmp_path / "nope.json")


def edited(doc, path, value):
    """A deep copy of ``doc`` with the field at ``path`` (keys and indices) set to ``value``."""
    out = json.loads(json.dumps(doc))
    target = out
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value(target[path[-1]]) if callable(value) else value
    return out


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("files")
    out = {}
    for name, (inputs, model) in {"global": MODELS[0], "octree": MODELS[3], "kmeans": MODELS[4]}.items():
        X = IDENT.nominal_mm if inputs == "cartesian" else IDENT.q_deg
        model = clone(model).fit(X, IDENT.errors_mm)
        save_model(model, tmp / f"{name}.json", robot=load_robot("motoman_sk120"))
        out[name] = json.loads((tmp / f"{name}.json").read_text())
    return out


# Each edit used to load and then predict -inf, 1e300 or a silently wrong value (or crash later).
SEMANTIC = [
    ("global", ["model", "scaling", "scale", 0], 1e-300, r"'model.scaling.scale': disagrees with data_bounds"),
    ("global", ["model", "scaling", "scale", 1], -2.0, r"'model.scaling.scale': disagrees with data_bounds"),
    ("global", ["model", "scaling", "centre", 2], lambda v: v + 100.0, r"'model.scaling.centre': disagrees with data_bounds"),
    ("global", ["model", "terms", 1], [9, 0, 0], r"'model.terms': are not the 7 terms of a polynomial basis of order 2"),
    ("global", ["model", "basis"], "fourier", r"'model.terms\[0\]': expected \[\"1\"\|\"cos\"\|\"sin\", input, harmonic\]"),
    ("global", ["model", "order"], 3, r"'model.terms': are not the 10 terms of a polynomial basis of order 3"),
    ("global", ["model", "coef", 2, 0], 1e300, r"'model.coef': predicts 1e\+300 mm within the box of its data"),
    ("global", ["model", "coef", 0, 1], "0.5", r"'model.coef': expected float values; found str '0.5'"),
    ("global", ["model", "coef", 0, 1], True, r"'model.coef': expected float values; found bool True"),
    ("global", ["model", "scaling", "active", 0], 1, r"'model.scaling.active': expected bool values; found int 1"),
    ("global", ["n_inputs"], 3.0, r"'n_inputs': expected int; got float 3.0"),
    ("global", ["model", "data_bounds", 0, 0], lambda v: v + 1e4, r"'model.data_bounds': a low bound exceeds its high bound"),
    ("global", ["model", "solver"], "magic", r"'model.solver': expected one of 'pso', 'lstsq'; got 'magic'"),
    ("octree", ["blend", "method"], "cubic", r"'blend.method': expected one of 'gaussian', 'hard'; got 'cubic'"),
    ("octree", ["blend", "width"], -1.0, r"'blend.width': expected a real number in \[0.6, 10.0\]"),
    ("octree", ["partition", "kind"], "voronoi", r"'partition.kind': expected one of 'octree', 'kmeans'; got 'voronoi'"),
    ("octree", ["partition", "sigmas", 0, 0], 0.0, r"'partition.sigmas': kernel widths must be > 0"),
    ("octree", ["partition", "kernel_region", 0], 99, r"'partition.kernel_region': must map the \d+ kernels onto all regions"),
    ("octree", ["partition", "tree", "child", 0], 10**6, r"'partition.tree.child': child indices must point forward"),
    ("octree", ["partition", "tree", "leaf"], lambda v: [len(v) + 5 if x >= 0 else x for x in v], r"'partition.tree.leaf': every node is either split"),
    ("octree", ["partition", "active"], lambda v: [False] * len(v), r"'partition.active': no input varies"),
    ("octree", ["train_inputs", 0, 1], "1.5", r"'train_inputs': expected float values; found str '1.5'"),
    ("octree", ["regions", 0, "coef", 0, 0], -1e300, r"'regions\[0\].coef': predicts"),
    ("kmeans", ["partition", "kernel_region"], lambda v: list(reversed(v)), r"'partition.kernel_region': a k-means partition has one kernel per region"),
    ("kmeans", ["partition", "centres", 0, 0], "x", r"'partition.centres': expected float values; found str 'x'"),
    ("kmeans", ["n_inputs"], 5, r"'n_inputs': a joint model of robot 'motoman_sk120' takes 6 joints; got 5"),
]


@pytest.mark.parametrize("kind, path, value, message", SEMANTIC)
def test_files_are_checked_for_meaning(saved, tmp_path, kind, path, value, message):
    bad = tmp_path / "bad.json"
    doc = edited(saved[kind], path, value)
    del doc["checksum"]             # an edit made on purpose: the meaning checks alone must catch it
    bad.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match="bad.json: field " + message):
        load_model(bad)


def test_the_saved_files_themselves_load(saved, tmp_path):
    """The control of the edits above: the checks refuse none of the files partcal itself wrote."""
    for name, doc in saved.items():
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps(doc))
        model, loaded = load_model(path)
        assert loaded == doc and type(model).__name__ == {"global": "ErrorModel"}.get(name, "PartitionedErrorModel")


def test_a_number_changed_after_writing_is_refused_by_the_checksum(saved, tmp_path):
    doc = edited(saved["global"], ["model", "coef", 0, 0], lambda v: v + 5.0)     # plausible, and wrong
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match=r"bad.json: field 'checksum': does not match the content"):
        load_model(bad)
    del doc["checksum"]                                 # a deliberate edit: accepted, and used as written
    bad.write_text(json.dumps(doc))
    model, _ = load_model(bad)
    assert model.coef_[0, 0] == saved["global"]["model"]["coef"][0][0] + 5.0


@pytest.fixture(scope="module")
def gp_files(tmp_path_factory):
    from partcal import GaussianProcessErrorModel

    tmp = tmp_path_factory.mktemp("gp")
    out = {}
    gp = GaussianProcessErrorModel(inputs="joint", restarts=0, random_state=0).fit(IDENT.q_deg, IDENT.errors_mm)
    regional = PartitionedErrorModel(partition=KMeansPartition(2, min_samples=30),
                                     local=GaussianProcessErrorModel(inputs="joint", restarts=0),
                                     random_state=0).fit(IDENT.q_deg, IDENT.errors_mm)
    for name, model in (("gp", gp), ("regional", regional)):
        save_model(model, tmp / f"{name}.json", robot=load_robot("motoman_sk120"))
        out[name] = json.loads((tmp / f"{name}.json").read_text())
    return out


@pytest.mark.parametrize("kind, path, value, message", [
    ("gp", ["model", "input_map", "scale", 0], 0.0, r"'model.input_map.scale': the scales of the varying inputs must be > 0"),
    ("gp", ["model", "y_std", 0], 0.0, r"'model.y_std': the output scales must be > 0"),
    ("gp", ["model", "dual_coef", 0, 0], 1e6, r"'model.dual_coef': predicts [\d.e+]+ mm within the box of its data"),
    ("regional", ["regions", 0, "input_map", "scale", 0], 0.0, r"'regions\[0\].input_map.scale': the scales of the varying"),
    ("regional", ["regions", 1, "dual_coef", 0, 0], 1e6, r"'regions\[1\].dual_coef': predicts"),
])
def test_gaussian_process_files_are_checked_for_meaning(gp_files, tmp_path, kind, path, value, message):
    """These edits used to load, then predict NaN (a zero scale) or 43 km (a huge dual coefficient)."""
    doc = edited(gp_files[kind], path, value)
    del doc["checksum"]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match="bad.json: field " + message):
        load_model(bad)


@pytest.fixture(scope="module")
def kinematic_file(tmp_path_factory):
    from partcal import KinematicModel

    path = tmp_path_factory.mktemp("kinematic") / "dh.json"
    save_model(KinematicModel(robot="motoman_sk120").fit(IDENT.q_deg, IDENT.errors_mm), path,
               robot=load_robot("motoman_sk120"))
    return json.loads(path.read_text())


def kinematic_edits(doc) -> list:
    """Edits of a kinematic file that used to load and predict as written, with the message each gets now."""
    ident = doc["model"]["identification"]
    names, status = ident["names"], ident["status"]
    kept = status.index("unidentifiable")
    found = status.index("identified")
    d1, a2 = names.index("d[1]"), names.index("a[2]")
    return [
        (["model", "identification", "nominal", d1], lambda v: v + 5.0,
         rf"'model.identification.nominal': entry {d1} \(d\[1\]\) is [\d.]+, but the file's robot gives"),
        (["model", "identification", "value", kept], lambda v: v + 0.5,
         rf"'model.identification.value': entry {kept} \({re.escape(names[kept])}\) is 'unidentifiable', so it "
         r"keeps its nominal value"),
        (["model", "identification", "value", a2], lambda v: v + 1e5,
         r"'model.identification.value': the identified robot moves the tool by [\d.e+]+ mm within the joint box "
         r"of its data, more than the robot's reach \(4413 mm\)"),
        (["model", "identification", "std_error", found], -0.1,
         r"'model.identification.std_error': standard errors must be finite and >= 0"),
        (["model", "data_bounds", 0, 0], lambda v: v + 1e3, r"'model.data_bounds': a low bound exceeds"),
    ]


def test_kinematic_files_are_checked_for_meaning(kinematic_file, tmp_path):
    bad = tmp_path / "bad.json"
    for path, value, message in kinematic_edits(kinematic_file):
        doc = edited(kinematic_file, path, value)
        del doc["checksum"]
        bad.write_text(json.dumps(doc))
        with pytest.raises(ModelFileError, match="bad.json: field " + message):
            load_model(bad)


def test_a_deliberate_edit_of_an_identified_value_is_used_as_written(kinematic_file, tmp_path):
    """The control of the checks above: a plausible edit (the base 1 mm along x) loads, and every
    predicted error moves by exactly 1 mm along x."""
    ident = kinematic_file["model"]["identification"]
    x = ident["names"].index("base.x")
    assert ident["status"][x] == "identified"
    doc = edited(kinematic_file, ["model", "identification", "value", x], lambda v: v + 1.0)
    del doc["checksum"]
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(doc))
    original, _ = load_model_from(kinematic_file, tmp_path / "original.json")
    model, _ = load_model(path)
    shift = model.predict(IDENT.q_deg) - original.predict(IDENT.q_deg)
    np.testing.assert_allclose(shift, np.tile([1.0, 0.0, 0.0], (len(shift), 1)), atol=1e-9)


def load_model_from(doc, path):
    path.write_text(json.dumps(doc))
    return load_model(path)


def test_empty_inputs_give_empty_answers_for_every_model_file(saved, kinematic_file, tmp_path):
    """Partitioned and kinematic files used to raise scikit-learn's 'Found array with 0 sample(s)'."""
    for name, doc in {**saved, "kinematic": kinematic_file}.items():
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps(doc))
        p = load_predictor(path)
        empty = np.zeros((0, p.n_inputs)) if p.inputs == "joint" else np.zeros((0, 3))
        given = {"joints": empty} if p.inputs == "joint" else {"positions": empty}
        assert p.predict(**given).shape == (0, 3) and p.distance_to_data(**given).shape == (0,)
        result = p.compensate_full(np.zeros((0, 3)))
        assert p.compensate(np.zeros((0, 3))).shape == (0, 3) and result.converged.shape == (0,)


@pytest.mark.parametrize("name", ["format2_sdp-ai", "format2_fdp-ci-octree", "format2_gp-ci",
                                  "format2_dh-gp-ai-k-means"])
def test_files_of_format_2_load_and_predict_what_they_predicted_when_written(name):
    """Model files written by partcal 0.1.0 in format 2 (a series, an octree, a GP and a hybrid with a
    partitioned GP residual) predict what that version predicted from them (stored beside each file)."""
    from partcal.data.measurements import read_measurements as read

    model, doc = load_model(ROOT / "tests" / "fixtures" / f"{name}.json")
    expected = json.loads((ROOT / "tests" / "fixtures" / f"{name}.expected.json").read_text())["predictions"]
    for data_set, file in (("identification", "identification.csv"), ("rectangle", "test_rectangle.csv")):
        m = read(ROOT / "data" / "sk120" / file)
        X = m.nominal_mm if doc["inputs"] == "cartesian" else m.q_deg
        np.testing.assert_allclose(model.predict(X), expected[data_set], rtol=0, atol=1e-9)
