"""Every public estimator: scikit-learn's estimator checks, and reads that leave a fitted model unchanged.

A read (``predict``, ``distance_to_data``, ``warn_if_extrapolating``, ``score``, ...) must not
change the estimator: not an attribute, not the contents of an array, not a cache inside a
fitted object. Such state is built in ``fit`` (and by ``_prepare()`` after a model file is
loaded), never on first use. :func:`snapshot` records the whole object graph of a fitted
estimator (every attribute, recursively, with each object's identity and each array's bytes)
so that a cache filled on first use anywhere inside it shows up as a difference.
"""

import warnings

import numpy as np
import pytest
from conftest import ROOT
from sklearn.utils.estimator_checks import parametrize_with_checks

from partcal import read_measurements
from partcal.models.gp import GaussianProcessErrorModel
from partcal.models.kinematic import KinematicModel
from partcal.models.partition import KMeansPartition, Octree
from partcal.models.partitioned import PartitionedErrorModel
from partcal.models.pose import PoseErrorModel
from partcal.models.series import ErrorModel
from partcal.robot.description import load_robot, robot_from_dict
from partcal.study.persist import model_from_dict, model_to_dict

IDENT = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
SK120 = load_robot("motoman_sk120")

# A planar two-joint arm: the smallest robot a kinematic model can be checked with.
PLANAR = robot_from_dict({"name": "planar2", "joints": 2, "tool_mm": [100, 0, 0],
                          "limits_deg": [[-170, 170], [-150, 150]],
                          "links": [{"theta": "q1", "d": 0, "a": 500, "alpha": 0},
                                    {"theta": "q2", "d": 0, "a": 400, "alpha": 0}]})


# ---------------------------------------------------------------------- scikit-learn's checks
# A kinematic model reads a robot's joint angles and predicts 3-D position errors, so it refuses data of
# another shape with a DataError (tested in test_kinematic.py). These checks feed such data: X with other
# than the robot's 2 columns (3, 4, 5 or 10), or a y that is not (n, 3). What they would check (cloning
# and pickling fitted models, reads that change nothing, idempotent fits, NaN refusal, n_features_in_)
# is checked on a real robot below and in test_kinematic.py.
KINEMATIC_JOINTS = "X must hold the robot's joint angles (2 columns here); the check's X has another width"
KINEMATIC_Y = "y must be position errors, shape (n, 3); the check fits a 1-D y"
KINEMATIC_FAILURES = {
    **dict.fromkeys([
        "check_dict_unchanged", "check_dont_overwrite_parameters", "check_dtype_object", "check_estimators_dtypes",
        "check_estimators_nan_inf", "check_estimators_pickle", "check_estimators_pickle(readonly_memmap=True)",
        "check_f_contiguous_array_estimator", "check_fit2d_1feature", "check_fit2d_1sample",
        "check_fit2d_predict1d", "check_fit_score_takes_y", "check_methods_sample_order_invariance",
        "check_methods_subset_invariance", "check_n_features_in_after_fitting", "check_pipeline_consistency",
        "check_positive_only_tag_during_fit", "check_regressor_data_not_an_array", "check_regressor_multioutput",
        "check_regressors_int", "check_regressors_no_decision_function", "check_regressors_train",
        "check_regressors_train(readonly_memmap=True)", "check_regressors_train(readonly_memmap=True,X_dtype=float32)",
        "check_supervised_y_2d"], KINEMATIC_JOINTS),
    **dict.fromkeys([
        "check_estimators_fit_returns_self", "check_estimators_overwrite_params", "check_fit_check_is_fitted",
        "check_fit_idempotent", "check_n_features_in", "check_readonly_memmap_input"], KINEMATIC_Y),
}


GP_WEIGHTS = ("a Gaussian process fits the samples of positive weight (a partition's region takes those within its "
              "reach); the sizes of the weights do not matter to it, so weight 2 is not a repeated sample")


SERIES_WEIGHTS = ("the check fits 30 inputs (31 terms per output) on 27 repeated samples: fewer samples than "
                  "coefficients is refused (test_models.py checks the weights on data a series model can fit)")


def _expected_failures(estimator) -> dict:
    if isinstance(estimator, GaussianProcessErrorModel):
        return {"check_sample_weight_equivalence_on_dense_data": GP_WEIGHTS}
    if isinstance(estimator, ErrorModel):
        return {"check_sample_weight_equivalence_on_dense_data": SERIES_WEIGHTS}
    return KINEMATIC_FAILURES if isinstance(estimator, KinematicModel) else {}


CHECKED = [
    ErrorModel(solver="lstsq"),
    PartitionedErrorModel(partition=KMeansPartition(n_regions=2, min_samples=5), local=ErrorModel(solver="lstsq"),
                          random_state=0),
    GaussianProcessErrorModel(restarts=0, hyper_samples=20, random_state=0),
    KinematicModel(robot=PLANAR),
    KinematicModel(robot=PLANAR, residual=ErrorModel(solver="lstsq")),
]


@parametrize_with_checks(CHECKED, expected_failed_checks=_expected_failures)
def test_sklearn_compatible(estimator, check):
    check(estimator)


# ---------------------------------------------------------------------- reads are pure
def snapshot(obj) -> dict:
    """``{path: fingerprint}`` of everything reachable from ``obj``'s attributes.

    A fingerprint is the object's type and identity, plus its value for
    scalars and strings and its dtype, shape and bytes for arrays; objects,
    dicts, lists and tuples are followed into (objects through ``__dict__``
    and ``__slots__``). Objects with neither (a KD-tree, a function) count by
    identity only.
    """
    out: dict = {}
    seen: set = set()

    def walk(path: str, value) -> None:
        if value is None or isinstance(value, (bool, int, float, complex, str, bytes, np.generic)):
            out[path] = (type(value).__name__, repr(value))
            return
        out[path] = (type(value).__name__, id(value))
        if id(value) in seen:
            return
        seen.add(id(value))
        if isinstance(value, np.ndarray):
            out[path + ".<data>"] = (value.dtype.str, value.shape, value.tobytes())
        elif isinstance(value, dict):
            for key in sorted(value, key=repr):
                walk(f"{path}[{key!r}]", value[key])
        elif isinstance(value, (list, tuple, set, frozenset)):
            items = sorted(value, key=repr) if isinstance(value, (set, frozenset)) else value
            for i, item in enumerate(items):
                walk(f"{path}[{i}]", item)
        elif not isinstance(value, type) and not callable(value) or hasattr(value, "__dict__"):
            for name in getattr(type(value), "__slots__", ()):
                if hasattr(value, name):
                    walk(f"{path}.{name}", getattr(value, name))
            for name, item in getattr(value, "__dict__", {}).items():
                walk(f"{path}.{name}", item)

    walk("self", obj)
    return out


def changes(before: dict, after: dict) -> list[str]:
    keys = sorted(set(before) | set(after))
    return [k for k in keys if before.get(k) != after.get(k)]


def test_snapshot_sees_a_changed_array_and_a_cache_filled_deep_inside():
    model = PartitionedErrorModel(partition=KMeansPartition(n_regions=2), local=ErrorModel(solver="lstsq"),
                                  random_state=0).fit(IDENT.nominal_mm, IDENT.errors_mm)
    before = snapshot(model)
    assert changes(before, snapshot(model)) == []
    model.models_[1].coef_[0, 0] += 1e-6                       # the same array, other contents
    assert changes(before, snapshot(model)) == ["self.models_[1].coef_.<data>"]
    model.models_[1].coef_[0, 0] -= 1e-6
    model.partition_.lookup.__dict__["memo"] = {3: np.zeros(2)}          # a frozen object's cache
    found = changes(before, snapshot(model))
    assert len(found) == 3 and all(k.endswith(("lookup.memo", "lookup.memo[3]", "lookup.memo[3].<data>"))
                                   for k in found)


def cartesian():
    return IDENT.nominal_mm, IDENT.errors_mm


def joints():
    return IDENT.q_deg, IDENT.errors_mm


def _pose(errors):
    return np.hstack([errors, 0.3 * errors[:, ::-1]])        # six columns, the last three standing for mrad


def cartesian_pose():
    return IDENT.nominal_mm, _pose(IDENT.errors_mm)


def joints_pose():
    return IDENT.q_deg, _pose(IDENT.errors_mm)


# (id, make the estimator, its data)
PURE = [
    ("series-cartesian", lambda: ErrorModel(degree=2, solver="lstsq"), cartesian),
    ("series-pso", lambda: ErrorModel(solver="pso", random_state=0), cartesian),
    ("series-fourier-joint", lambda: ErrorModel(inputs="joint", basis="fourier", solver="lstsq"), joints),
    ("octree", lambda: PartitionedErrorModel(partition=Octree(max_depth=1, min_samples=12),
                                             local=ErrorModel(solver="lstsq"), random_state=0), cartesian),
    ("kmeans", lambda: PartitionedErrorModel(partition=KMeansPartition(4), local=ErrorModel(solver="lstsq"),
                                             random_state=0), cartesian),
    ("kmeans-hard", lambda: PartitionedErrorModel(partition=KMeansPartition(3), local=ErrorModel(solver="lstsq"),
                                                  blend="hard", random_state=0), cartesian),
    ("octree-hard", lambda: PartitionedErrorModel(partition=Octree(max_depth=1, min_samples=12),
                                                  local=ErrorModel(solver="lstsq"), blend="hard",
                                                  random_state=0), cartesian),
    ("kmeans-joint", lambda: PartitionedErrorModel(partition=KMeansPartition(3),
                                                   local=ErrorModel(inputs="joint", solver="lstsq"),
                                                   random_state=0), joints),
    ("kmeans-gp", lambda: PartitionedErrorModel(partition=KMeansPartition(2),
                                                local=GaussianProcessErrorModel(restarts=0),
                                                random_state=0), cartesian),
    ("gp", lambda: GaussianProcessErrorModel(restarts=0, random_state=0), cartesian),
    ("gp-joint", lambda: GaussianProcessErrorModel(inputs="joint", restarts=0, random_state=0), joints),
    ("kinematic", lambda: KinematicModel(robot=SK120), joints),
    ("hybrid", lambda: KinematicModel(robot=SK120, residual=ErrorModel(solver="lstsq"), random_state=0), joints),
    ("hybrid-partitioned", lambda: KinematicModel(
        robot=SK120, residual=PartitionedErrorModel(partition=KMeansPartition(2), local=ErrorModel(solver="lstsq")),
        random_state=0), joints),
    ("pose-gp", lambda: PoseErrorModel(GaussianProcessErrorModel(restarts=0, random_state=0)), cartesian_pose),
    ("pose-kmeans", lambda: PoseErrorModel(PartitionedErrorModel(partition=KMeansPartition(3), random_state=0,
                                                                 local=ErrorModel(solver="lstsq"))), cartesian_pose),
    ("hybrid-pose", lambda: KinematicModel(robot=SK120, residual=ErrorModel(inputs="joint", solver="lstsq"),
                                           random_state=0), joints_pose),
]


def queries(X, n=400, seed=0):
    """Points inside the data box, around it and far outside (every lookup cell kind and the far blocks)."""
    rng = np.random.default_rng(seed)
    lo, hi = X.min(axis=0), X.max(axis=0)
    span = hi - lo
    return np.vstack([rng.uniform(lo, hi, (n, X.shape[1])), rng.uniform(lo - span, hi + span, (n, X.shape[1])),
                      lo - 20 * span, hi + 20 * span, X[:5]])


def every_read(model, X, y):
    """Call every public method that only reads a fitted model (twice, to reuse anything kept)."""
    Xq = queries(X)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(2):
            model.predict(Xq)
            model.predict(Xq[:1])
            model.distance_to_data(Xq)
            model.warn_if_extrapolating(Xq)
            model.score(X, y)
            for name in ("assign", "predict_kinematic"):
                if hasattr(model, name):
                    getattr(model, name)(Xq)
            if hasattr(model, "equations"):
                model.equations()
            if hasattr(model, "sklearn_kernel"):
                model.sklearn_kernel()
            model.get_params()
            repr(model)
            model.__sklearn_tags__()


@pytest.mark.parametrize("make, data", [p[1:] for p in PURE], ids=[p[0] for p in PURE])
def test_reads_leave_a_fitted_estimator_unchanged(make, data):
    X, y = data()
    model = make().fit(X, y)
    before = snapshot(model)
    every_read(model, X, y)
    assert changes(before, snapshot(model)) == []


@pytest.mark.parametrize("make, data", [p[1:] for p in PURE], ids=[p[0] for p in PURE])
def test_reads_leave_a_loaded_estimator_unchanged(make, data):
    X, y = data()
    fitted = make().fit(X, y)
    model = model_from_dict(model_to_dict(fitted))
    before = snapshot(model)
    every_read(model, X, y)
    assert changes(before, snapshot(model)) == []
    Xq = queries(X)
    np.testing.assert_array_equal(model.predict(Xq), fitted.predict(Xq))
    np.testing.assert_array_equal(model.distance_to_data(Xq), fitted.distance_to_data(Xq))


def test_replaced_training_inputs_are_measured_without_keeping_a_tree():
    X, y = cartesian()
    model = ErrorModel(solver="lstsq").fit(X, y)
    model.train_inputs_ = X[:10].copy()                 # replaced after fit: the prepared tree is stale
    before = snapshot(model)
    far = X[50:60]
    expected = np.linalg.norm(far[:, None] - X[None, :10], axis=2).min(axis=1)
    np.testing.assert_allclose(model.distance_to_data(far), expected, rtol=1e-12)
    assert changes(before, snapshot(model)) == []


def test_replaced_coefficients_are_evaluated_without_keeping_a_series():
    X, y = cartesian()
    model = ErrorModel(degree=2, solver="lstsq").fit(X, y)
    expected = 2 * model.predict(X)
    model.coef_ = 2 * model.coef_                        # replaced after fit: the compiled series is stale
    before = snapshot(model)
    np.testing.assert_allclose(model.predict(X), expected, rtol=1e-12, atol=1e-12)
    assert changes(before, snapshot(model)) == []


@pytest.mark.parametrize("spec", [Octree(max_depth=1, min_samples=12), KMeansPartition(4)])
def test_an_unprepared_partitioned_model_predicts_the_same_and_keeps_nothing(spec):
    X, y = cartesian()
    model = PartitionedErrorModel(partition=spec, local=ErrorModel(solver="lstsq"), random_state=0).fit(X, y)
    Xq = queries(X)
    expected = model.predict(Xq)
    del model._weights, model._combiner                   # as if a loader forgot _prepare()
    before = snapshot(model)
    np.testing.assert_array_equal(model.predict(Xq), expected)
    assert changes(before, snapshot(model)) == []
