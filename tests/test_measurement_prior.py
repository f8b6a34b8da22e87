"""Priors with measurement types (partcal.calibration.stacked.identify_measurements(prior=...), partcal.calibration.cv,
KinematicModel.fit(measures=..., prior...)): MAP against an independently written augmented least squares, the
fit unchanged without a prior, a strong prior's mean, the scale a prior holds, a list of strengths chosen on
random folds of the rows by the one-standard-error rule recomputed here."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from conftest import random_row_prior

from partcal import load_robot
from partcal.errors import DataError, PartcalError
from partcal.metrics import within_one_standard_error
from partcal.calibration.chain import model_positions
from partcal.calibration.parameters import nominal_values, PLAUSIBLE_ERROR, robot_with
from partcal.models.kinematic import KinematicModel
from partcal.calibration.cv import fold_rows
from partcal.calibration.measurement import MeasurementRows, SCALE
from partcal.calibration.stacked import identify_measurements
from partcal.calibration.prior import Prior

ROBOT = load_robot("universal_robots_ur10")
NESTS = {"a": np.array([600.0, -500.0, 200.0]), "b": np.array([500.0, 400.0, 500.0]),
         "c": np.array([800.0, 0.0, -100.0])}
BAR = {"points": {"b": {"distance_to": "a", "distance_mm": float(np.linalg.norm(NESTS["b"] - NESTS["a"]))}}}
WEIGHT = 0.02 / 0.01            # a fixed point's residuals: the reference noise over the type's default noise


def _visits(per_nest: int, seed: int):
    """Nest visits of a UR10 with DH errors: commanded joints whose true tip reaches each nest (plus 0.01 mm per
    axis) from random orientations; the rows, the true parameter values."""
    rng = np.random.default_rng(seed)
    true = nominal_values(ROBOT)
    true[:24] += rng.normal(0, 1, 24) * np.tile([0.05, 0.3, 0.3, 0.03], 6)
    true[24:27] += [0.3, -0.2, 0.4]
    robot = robot_with(ROBOT, true)
    lo, hi = np.array([-90, -150, -140, -180, -150, -180.0]), np.array([90, -30, 140, 180, 150, 180.0])
    qs, names = [], []
    for name, c in NESTS.items():
        q = lo + (hi - lo) * rng.random((4 * per_nest, 6))
        aim = c + rng.normal(0, 0.01, (len(q), 3))
        for _ in range(8):
            q[:, :3] += np.linalg.solve(robot.jacobian(q)[:, :, :3], (aim - robot.positions(q))[:, :, None])[:, :, 0]
        q = (q + 180.0) % 360.0 - 180.0         # the same tips with the joints in one turn (the steps may wind)
        ok = np.linalg.norm(robot.positions(q) - aim, axis=1) < 1e-6
        qs.append(q[ok][:per_nest])
        names += [name] * len(qs[-1])
    q = np.vstack(qs)
    n = len(q)
    rows = MeasurementRows(q, ("fixed",) * n, tuple(str(i + 1) for i in range(n)), tuple(range(2, n + 2)), "nests.csv", {},
                {"feature": tuple(names)})
    return rows, true


def test_map_with_measurement_types_equals_an_independent_augmented_least_squares():
    rows, _ = _visits(10, 1)
    q, feature = rows.q_deg, rows.texts["feature"]
    v0 = nominal_values(ROBOT)
    noise = 0.02
    index, mean, cov = random_row_prior(v0)                   # on the DH rows' parameters
    table, notes = identify_measurements(ROBOT, rows, {}, prior=Prior.from_covariance(index, mean, cov, noise))
    plain, plain_notes = identify_measurements(ROBOT, rows, {})
    # every nest unknown: nothing measures a length; without a prior one length is held nominal, with it the prior
    # holds the scale, and it makes more of the robot identifiable
    assert plain_notes[0].startswith(SCALE) and "one length is held nominal" in plain_notes[0]
    assert notes[0].startswith(SCALE) and "the prior holds it" in notes[0]
    n_free = [sum(s == "identified" for s in t.status[:33]) for t in (plain, table)]
    assert n_free[0] < n_free[1]
    free = np.flatnonzero(np.array(table.status) == "identified")
    names = list(table.names)
    centres = np.array([[names.index(f"point {f}.{c}") for c in "xyz"] for f in feature])      # (n, 3)
    chol = np.linalg.cholesky(cov)

    def resid(x):               # written out: |W (p - c)|^2 + sigma^2 (v - m)^T C^-1 (v - m), W the type's weight
        v = table.nominal.copy()
        v[free] = x
        p = model_positions(ROBOT, None, q, v[:33], np.zeros(len(q)))
        return np.concatenate([WEIGHT * (p - v[centres]).ravel(), noise * np.linalg.solve(chol, v[index] - mean)])

    x = least_squares(resid, table.nominal[free], jac="3-point", x_scale="jac", xtol=1e-15, ftol=1e-15,
                      gtol=1e-15).x
    np.testing.assert_allclose(np.sum(resid(table.value[free]) ** 2), np.sum(resid(x) ** 2), rtol=1e-9)
    np.testing.assert_allclose(table.value[free], x, atol=1e-5)
    # the types' RMS figures are the rows' alone (the prior's rows are not residuals of any type)
    p = model_positions(ROBOT, None, q, table.value[:33], np.zeros(len(q)))
    assert table.target_rms_mm["fixed"] == pytest.approx(np.sqrt(np.mean((p - table.value[centres]) ** 2)),
                                                         rel=1e-12)


def test_no_prior_or_a_zero_strength_leaves_the_fit_bit_for_bit():
    """A plausible prior of strength 0 is no prior: the fit is the plain one bit for bit, and that is the least
    squares of the weighted visits alone, as an independently written one finds it."""
    rows, _ = _visits(8, 2)
    plain = KinematicModel(robot=ROBOT).fit(rows.q_deg, None, rows=rows, cell={})
    zero = KinematicModel(robot=ROBOT, prior="plausible", prior_strength=0.0).fit(rows.q_deg, None,
                                                                                  rows=rows, cell={})
    a, b = plain.identification_, zero.identification_
    assert a.status == b.status and a.names == b.names
    for field in ("value", "std_error", "covariance"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert plain.measurement_notes_ == zero.measurement_notes_
    free = np.flatnonzero(np.array(a.status) == "identified")
    names, q = list(a.names), rows.q_deg
    centres = np.array([[names.index(f"point {f}.{c}") for c in "xyz"] for f in rows.texts["feature"]])

    def resid(x):               # written out: |W (p - c)|^2, W the type's weight, no prior rows
        v = a.nominal.copy()
        v[free] = x
        return WEIGHT * (model_positions(ROBOT, None, q, v[:33], np.zeros(len(q))) - v[centres]).ravel()

    x = least_squares(resid, a.nominal[free], jac="3-point", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    np.testing.assert_allclose(np.sum(resid(a.value[free]) ** 2), np.sum(resid(x) ** 2), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(a.value[free], x, atol=1e-5)
    weak = KinematicModel(robot=ROBOT, prior="plausible", prior_strength=0.1).fit(rows.q_deg, None,
                                                                                 rows=rows, cell={})
    assert np.max(np.abs(weak.identification_.value[:24] - a.value[:24])) > 1e-3       # a prior would show


def test_a_strong_prior_returns_its_mean_and_a_prior_on_the_measurement_types_unknowns_is_refused():
    rows, _ = _visits(8, 3)
    mean = nominal_values(ROBOT)[:24] + np.random.default_rng(7).normal(size=24) * 0.2
    strong, _ = identify_measurements(ROBOT, rows, {}, prior=Prior.from_std(np.arange(24), mean, np.full(24, 1e-3), 1e4))
    np.testing.assert_allclose(strong.value[:24], mean, atol=1e-6)
    with pytest.raises(DataError, match=r"the prior holds parameter 33; the robot has 33 .*never on the types'"):
        identify_measurements(ROBOT, rows, {}, prior=Prior.from_std([33], [0.0], [1.0], 0.02))


def test_the_plausible_prior_holds_the_scale_every_unknown_nest_leaves_free():
    """Every nest unknown: nothing measures a length. Without a prior the rank rule holds one length nominal; with
    the plausible prior every length is identified, the scale held by the prior's rows: the fit is the MAP of the
    weighted visits and those rows (each row parameter's plausible error under the strength), written out here,
    and the robot's shape comes out nearer the truth than nominal."""
    rows, true = _visits(12, 5)
    q = np.random.default_rng(0).uniform([-90, -150, -140, -180, -150, -180], [90, -30, 140, 180, 150, 180],
                                         (300, 6))
    truth = robot_with(ROBOT, true).positions(q)

    def shape_error(values):        # after the best rigid fit: the nests fix no frame
        from partcal.robot.frames import kabsch
        p = robot_with(ROBOT, values[:33]).positions(q)
        rot, t = kabsch(p, truth)
        return float(np.sqrt(np.mean(np.sum((p @ rot.T + t - truth) ** 2, axis=1))))

    with_prior = KinematicModel(robot=ROBOT, prior="plausible", prior_strength=1.0).fit(
        rows.q_deg, None, rows=rows, cell={})
    plain = KinematicModel(robot=ROBOT).fit(rows.q_deg, None, rows=rows, cell={}).identification_
    table = with_prior.identification_
    lengths = [k for k in range(24) if table.units[k] == "mm"]
    assert any(plain.status[k] == "unidentifiable" for k in lengths)
    assert sum(table.status[k] == "identified" for k in lengths) > sum(plain.status[k] == "identified"
                                                                        for k in lengths)
    assert any("the prior holds it" in n for n in with_prior.fit_notes())
    free = np.flatnonzero(np.array(table.status) == "identified")
    names, qv, v0 = list(table.names), rows.q_deg, table.nominal
    centres = np.array([[names.index(f"point {f}.{c}") for c in "xyz"] for f in rows.texts["feature"]])
    plausible = np.array([PLAUSIBLE_ERROR[table.units[k]] for k in range(24)])

    def resid(x):               # the weighted visits and the plausible prior's rows (strength 1 mm)
        v = v0.copy()
        v[free] = x
        return np.concatenate([WEIGHT * (model_positions(ROBOT, None, qv, v[:33], np.zeros(len(qv))) -
                                         v[centres]).ravel(), (v[:24] - v0[:24]) / plausible])

    x = least_squares(resid, v0[free], jac="3-point", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    np.testing.assert_allclose(np.sum(resid(table.value[free]) ** 2), np.sum(resid(x) ** 2), rtol=1e-8)
    np.testing.assert_allclose(table.value[free], x, atol=1e-4)
    assert shape_error(table.value) < shape_error(nominal_values(ROBOT))


def test_a_list_of_strengths_is_chosen_on_random_folds_of_the_rows_by_the_one_standard_error_rule():
    rows, _ = _visits(8, 6)
    strengths = (0.0, 1.0, 30.0)
    model = KinematicModel(robot=ROBOT, prior="plausible", prior_strength=list(strengths), random_state=3).fit(
        rows.q_deg, None, rows=rows, cell=BAR)
    table = model.prior_strength_table_
    assert [row["prior_strength"] for row in table] == list(strengths)
    # recomputed here: each strength fitted on the training rows of 5 folds drawn from the model's seed, each
    # held-out visit's miss of its nest as that fit placed it, weighted as the fit weighs a visit
    scores, errors = [], []
    for s in strengths:
        sq = np.zeros(len(rows))
        for train, out in fold_rows(rows, 3, 5):
            t = KinematicModel(robot=ROBOT, prior="plausible", prior_strength=s).fit(
                train.q_deg, None, rows=train, cell=BAR).identification_
            names = list(t.names)
            for i in out:
                c = t.value[[names.index(f"point {rows.texts['feature'][i]}.{x}") for x in "xyz"]]
                p = robot_with(ROBOT, t.value[:33]).positions(rows.q_deg[i:i + 1])[0]
                sq[i] = np.sum((WEIGHT * (p - c)) ** 2)
        mse = sq.sum() / (3 * len(rows))
        scores.append(np.sqrt(mse))
        g = len(rows)                # one group per row (its three coordinates together)
        se_mse = np.sqrt(np.sum((sq - 3 * mse) ** 2) / (g * (g - 1))) / 3
        errors.append(se_mse / (2 * np.sqrt(mse)))
    np.testing.assert_allclose([row["cv_weighted_rms_mm"] for row in table], scores, rtol=1e-9)
    np.testing.assert_allclose([row["cv_se"] for row in table], errors, rtol=1e-9)
    within = within_one_standard_error(scores, errors)
    assert model.prior_strength_ == max(strengths[i] for i in within)
    assert [row["chosen"] for row in table] == [s == model.prior_strength_ for s in strengths]
    assert any(n.startswith(f"prior strength {model.prior_strength_:g} chosen by 5-fold CV of the rows")
               for n in model.fit_notes())


def test_a_list_of_strengths_is_refused_where_nothing_measures_a_length():
    rows, _ = _visits(6, 7)
    model = KinematicModel(robot=ROBOT, prior="plausible", prior_strength=[0.01, 0.1])
    with pytest.raises(PartcalError, match=r"The 'prior_strength' parameter of KinematicModel must be one number "
                                           r"here \(a list of strengths cannot be chosen on these rows: nothing here "
                                           r"measures a length.*Got \[0.01, 0.1\] instead"):
        model.fit(rows.q_deg, None, rows=rows, cell={})
    model.fit(rows.q_deg, None, rows=rows, cell=BAR)          # one known length: chosen
    table = model.prior_strength_table_
    assert [row["prior_strength"] for row in table] == [0.01, 0.1]
    scores, errors = [row["cv_weighted_rms_mm"] for row in table], [row["cv_se"] for row in table]
    chosen = max(table[i]["prior_strength"] for i in within_one_standard_error(scores, errors))
    assert model.prior_strength_ == chosen and [row["chosen"] for row in table] == [s == chosen for s in (0.01, 0.1)]
    at_chosen = KinematicModel(robot=ROBOT, prior="plausible", prior_strength=chosen).fit(
        rows.q_deg, None, rows=rows, cell=BAR)
    np.testing.assert_array_equal(model.identification_.value, at_chosen.identification_.value)
