"""The rank-checked fit on linear problems whose answers are known independently: numpy's least squares, scipy's own
count of evaluations, condition numbers and a prior's variance written out, a robust fit redone by iteratively
reweighted least squares, implausible values kept nominal or kept as fitted by the rule's own words (the survivors
of mutation testing on ``partcal/calibration/fit.py``)."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from partcal.calibration.fit import IMPLAUSIBLE, UNFIXED, fit_parameters, held_still, prior_variance
from partcal.calibration.parameters import PLAUSIBLE_ERROR


def _linear(a, b):
    """``jac_at`` of the residuals ``a v - b``."""
    def jac_at(v, jacobian=True):
        return a @ v - b, (a.copy() if jacobian else None)
    return jac_at


def _fit(a, b, units, size=None, nominal=None, **options):
    """``fit_parameters`` on ``a v - b`` from ``nominal`` (default zero), every parameter wanted; ``size`` geometric
    parameters (default: all, the first ``size - 9`` of them the rows' that the implausibility rule reads)."""
    p = a.shape[1]
    names = [(f"p{k}", unit) for k, unit in enumerate(units)]
    return fit_parameters(_linear(a, b), np.zeros(p) if nominal is None else nominal, a, np.ones(p, dtype=bool),
                          names, 1e-6, p if size is None else size, len(b) // 3, **options)


def test_the_rank_rule_reads_the_weighted_jacobian():
    """Two parameters, the second seen only by rows weighed 1e-8: weighted, the unit columns are orthogonal and both
    are identified, at numpy's weighted least squares. (Dividing by the weights instead would make the unit columns
    agree to 1e-8, below rcond, and drop one.) A third that no row moves stays unidentified."""
    a = np.array([[1.0, 0.0, 0.0]] * 3 + [[1.0, 1.0, 0.0]] * 3)
    b = np.array([1.0, 1.1, 0.9, 3.0, 3.2, 2.8])
    w = np.array([1.0] * 3 + [1e-8] * 3)
    table, resid = _fit(a, b, ["1", "1", "1"], row_weight=w)
    assert table.status == ("identified", "identified", "unidentifiable")      # no row moves the third
    expected = np.linalg.lstsq(a[:, :2] * w[:, None], b * w, rcond=None)[0]
    np.testing.assert_allclose(table.value, [*expected, 0.0], rtol=1e-9)
    np.testing.assert_allclose(resid, a[:, :2] @ expected - b, atol=1e-9)   # the residuals returned are unweighted


def test_the_evaluations_are_scipys_count():
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(12, 3)), rng.normal(size=12)
    table = _fit(a, b, ["1"] * 3)[0]
    scipy = least_squares(lambda x: a @ x - b, np.zeros(3), jac=lambda x: a, method="lm", x_scale="jac",
                          ftol=1e-15, xtol=1e-15, gtol=1e-15)
    assert table.evaluations == scipy.nfev > 0
    np.testing.assert_allclose(table.value, np.linalg.lstsq(a, b, rcond=None)[0], rtol=1e-9)


def test_the_condition_number_is_that_of_the_unit_columns():
    """Orthogonal columns of lengths 1 and 1000: scaled to unit length their condition number is 1 (the raw one,
    1000); columns at 45 degrees give (1 + cos 45) / (1 - cos 45) under the root."""
    a = np.zeros((6, 2))
    a[:3, 0], a[3:, 1] = 1.0, 1000.0
    assert _fit(a, np.arange(6.0), ["1", "1"])[0].condition == pytest.approx(1.0, rel=1e-12)
    a = np.array([[1.0, 1.0], [0.0, 1.0], [0.0, 0.0]] * 2) * [[1.0, 50.0]]
    c = np.cos(np.pi / 4)
    assert _fit(a, np.arange(6.0), ["1", "1"])[0].condition == pytest.approx(np.sqrt((1 + c) / (1 - c)), rel=1e-9)


def test_the_prior_variance_is_the_diagonal_of_j_p_j_transposed():
    rng = np.random.default_rng(3)
    j_i, j_u, absorbed, std = rng.normal(size=(5, 2)), rng.normal(size=(5, 3)), rng.normal(size=(2, 3)), [0.5, 2, 1]
    j = j_u - j_i @ absorbed
    np.testing.assert_allclose(prior_variance(j_i, j_u, absorbed, np.array(std)), np.diag(j @ np.diag(np.square(std))
                                                                                           @ j.T), rtol=1e-12)


def _implausible_problem(first, noise, seed=4):
    """Twelve geometric parameters in mm (the first three rows' parameters, the rest tool and base) whose first two
    columns agree to a part in a thousand. The least-squares answer is ``truth`` (the first parameter ``first``, the
    second 0): the noise, of norm ``noise``, is made orthogonal to the columns. ``std``: the standard errors."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(60, 12))
    a[:, 1] = a[:, 0] + 1e-3 * rng.normal(size=60)
    truth = np.r_[first, 0.0, rng.normal(size=10)]
    r = rng.normal(size=60)
    r -= a @ np.linalg.lstsq(a, r, rcond=None)[0]
    std = np.sqrt(noise**2 / (60 - 12) * np.diag(np.linalg.inv(a.T @ a)))
    return a, a @ truth + noise * r / np.linalg.norm(r), truth, std


def test_a_row_parameter_just_beyond_its_plausible_range_that_the_data_do_not_fix_is_kept_nominal(caplog):
    """10.5 mm is beyond ten plausible errors (10 mm) and within 3 standard errors (about 90 mm) of nominal: held
    nominal (unidentifiable), said in the log, and the rest fitted again (numpy, without its column); 9.5 mm is
    kept as fitted."""
    limit = IMPLAUSIBLE * PLAUSIBLE_ERROR["mm"]
    assert limit == 10.0
    a, b, truth, std = _implausible_problem(60.5, 5.0)
    assert UNFIXED * std[0] > 100.0
    nominal = np.r_[50.0, np.zeros(11)]                        # 10.5 mm out
    with caplog.at_level("INFO", logger="partcal.calibration.fit"):
        table = _fit(a, b, ["mm"] * 12, nominal=nominal)[0]
    assert table.value[0] == 50.0 and table.status[0] == "unidentifiable"
    rest = np.linalg.lstsq(a[:, 1:], b - 50.0 * a[:, 0], rcond=None)[0]
    np.testing.assert_allclose(table.value[1:], rest, rtol=1e-8)
    assert "p0 comes out +10.5 mm from nominal" in caplog.text
    assert "p0 comes out beyond 10 mm from nominal" in caplog.text
    a, b, truth, std = _implausible_problem(9.5, 5.0)
    table = _fit(a, b, ["mm"] * 12)[0]
    assert table.status[0] == "identified"
    np.testing.assert_allclose(table.value, truth, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("errors, held", [(2.5, True), (3.5, False)])
def test_the_data_fix_a_parameter_three_standard_errors_from_nominal(errors, held):
    """10.5 mm out, the noise scaled so that this is 2.5 (or 3.5) of its standard errors: held nominal (kept)."""
    unit = _implausible_problem(60.5, 1.0)[3][0]                # the standard error per unit of noise
    a, b, truth, std = _implausible_problem(60.5, 10.5 / errors / unit)
    assert 10.5 / std[0] == pytest.approx(errors)
    table = _fit(a, b, ["mm"] * 12, nominal=np.r_[50.0, np.zeros(11)])[0]
    assert (table.value[0] == 50.0) == held and (table.status[0] == "unidentifiable") == held
    if not held:
        assert table.value[0] == pytest.approx(60.5, rel=1e-9)


def test_a_row_parameter_far_out_that_the_data_fix_is_kept():
    """The same columns, the first parameter at 30 mm and no noise: beyond the range, but fixed."""
    a, b, truth, std = _implausible_problem(30.0, 0.0, seed=5)
    table = _fit(a, b, ["mm"] * 12)[0]
    np.testing.assert_allclose(table.value, truth, atol=1e-6)


def test_with_nothing_wanted_the_values_stay_nominal():
    rng = np.random.default_rng(6)
    a, b = rng.normal(size=(9, 2)), rng.normal(size=9)
    names = [("p0", "1"), ("p1", "1")]
    table, resid = fit_parameters(_linear(a, b), np.array([0.5, -0.5]), a, np.zeros(2, dtype=bool), names, 1e-6, 2, 3)
    assert table.value.tolist() == [0.5, -0.5] and table.status == ("fixed", "fixed") and table.condition == 1.0
    assert table.covariance.shape == (0, 0)
    np.testing.assert_allclose(resid, a @ [0.5, -0.5] - b)
    assert table.sigma_mm == pytest.approx(np.sqrt(np.sum(resid**2) / 9), rel=1e-12)


def test_an_unidentifiable_geometric_parameter_gets_its_plausible_error_and_is_absorbed_by_its_stand_in():
    """Two equal columns: the second is held (ties go to the first), its prior standard deviation the plausible
    error of its unit, and the identified parameters absorb it as numpy's least squares of its column on theirs
    (the first parameter alone, one for one)."""
    rng = np.random.default_rng(7)
    a = rng.normal(size=(30, 12))
    a[:, 1] = a[:, 0]
    table = _fit(a, rng.normal(size=30), ["mm"] * 11 + ["deg"])[0]
    free = np.flatnonzero(np.array(table.status) == "identified")
    assert table.status[1] == "unidentifiable" and free.size == 11
    np.testing.assert_array_equal(np.isnan(table.prior_std), np.arange(12) != 1)
    assert table.prior_std[1] == PLAUSIBLE_ERROR["mm"]
    expected = np.linalg.lstsq(a[:, free], a[:, [1]], rcond=None)[0]
    np.testing.assert_allclose(table.prior_absorbed, expected, atol=1e-12)
    assert table.prior_absorbed[0, 0] == pytest.approx(1.0)
    single = _fit(a[:, :2], rng.normal(size=30), ["mm", "mm"])[0]            # one identified, one held
    assert single.status == ("identified", "unidentifiable")
    np.testing.assert_allclose(single.prior_absorbed, [[1.0]], rtol=1e-12)


WEIGHTS = {"cauchy": lambda z2: 1.0 / (1.0 + z2), "soft_l1": lambda z2: 1.0 / np.sqrt(1.0 + z2)}
"""The derivative of each of scipy's losses, ``rho'(z^2)``: the weights of iteratively reweighted least squares."""


def _irls(a, b, scale, v, loss="cauchy"):
    """The M-estimate of ``loss`` at ``scale`` by iteratively reweighted least squares (a second method: scipy's fit
    is a trust-region one)."""
    for _ in range(500):
        w = WEIGHTS[loss](((a @ v - b) / scale) ** 2)
        new = np.linalg.lstsq(a * np.sqrt(w)[:, None], b * np.sqrt(w), rcond=None)[0]
        if np.max(np.abs(new - v)) < 1e-13:
            return new
        v = new
    raise AssertionError("IRLS did not converge")


def _spread_scale(resid):
    """The robust loss's scale read from residuals: 3 x 1.4826 x their median absolute value."""
    return 3.0 * 1.4826 * np.median(np.abs(resid))


def _robust_reference(a, b, loss):
    """The robust fit as documented, with IRLS for each fit: the scale 3 x 1.4826 x the median absolute residual,
    taken again after each fit until it moves by less than 5 %, at most four fits. The values and the fits made."""
    v, scale, fits = np.linalg.lstsq(a, b, rcond=None)[0], None, 0
    for _ in range(4):
        new = _spread_scale(a @ v - b)
        if scale is not None and abs(new - scale) < 0.05 * scale:
            break
        scale, fits = new, fits + 1
        v = _irls(a, b, scale, v, loss)
    return v, fits


def _one_far_row():
    """Twenty rows of three residuals, row 4 pushed off."""
    rng = np.random.default_rng(9)
    a = rng.normal(size=(60, 3))
    b = a @ [1.0, -2.0, 0.5] + rng.normal(0, 0.01, 60)
    b[12:15] += [2.0, -1.0, 1.5]
    return a, b


def test_the_robust_fit_re_estimates_its_scale_until_it_settles_and_names_the_far_row():
    """One row pushed off: the scale settles after two fits. The far row is named with its residual's norm and its
    worst coordinate's weight."""
    a, b = _one_far_row()
    v, fits = _robust_reference(a, b, "cauchy")
    assert fits == 2                                            # the rule stopped it early
    table, resid = _fit(a, b, ["1"] * 3, loss="cauchy")
    np.testing.assert_allclose(table.value, v, rtol=1e-7)
    final = _spread_scale(resid)
    weight = WEIGHTS["cauchy"]((resid / final) ** 2)
    assert table.robust["loss"] == "cauchy" and table.robust["scale_mm"] == pytest.approx(final, rel=1e-12)
    assert [d["row"] for d in table.robust["downweighted"]] == [4]
    (named,) = table.robust["downweighted"]
    assert named["residual_mm"] == pytest.approx(np.linalg.norm(resid[12:15]), rel=1e-12)
    assert named["weight"] == pytest.approx(weight[12:15].min(), rel=1e-9) and weight.reshape(-1, 3).min(axis=1)[
        np.arange(20) != 4].min() >= 0.5
    # the rows of the residuals as given: the far residuals are row 15's when the rows run backwards
    backwards = _fit(a, b, ["1"] * 3, loss="cauchy", row_of=np.repeat(np.arange(20)[::-1], 3))[0]
    assert [d["row"] for d in backwards.robust["downweighted"]] == [15]


def test_the_robust_scale_is_taken_at_most_four_times_and_every_loss_is_its_own():
    """Three of ten rows scattered by 2 (against 0.01): the scale still moves by more than 5 % after the fourth fit
    (a fifth would move it by 29 %), and the fit stops there. soft_l1 is fitted as soft_l1; least squares names no
    loss."""
    rng = np.random.default_rng(0)
    a = rng.normal(size=(30, 3))
    b = a @ [1.0, -2.0, 0.5] + rng.normal(0, 0.01, 30)
    b[:9] += rng.normal(0, 2.0, 9)
    v, fits = _robust_reference(a, b, "cauchy")
    assert fits == 4
    np.testing.assert_allclose(_fit(a, b, ["1"] * 3, loss="cauchy")[0].value, v, rtol=1e-7)
    a, b = _one_far_row()
    v = _robust_reference(a, b, "soft_l1")[0]
    table = _fit(a, b, ["1"] * 3, loss="soft_l1")[0]
    assert table.robust["loss"] == "soft_l1"
    np.testing.assert_allclose(table.value, v, rtol=1e-7)
    assert np.abs(v - np.linalg.lstsq(a, b, rcond=None)[0]).max() > 1e-3     # not least squares
    assert _fit(a, b, ["1"] * 3)[0].robust is None


def test_a_robust_fit_of_data_it_fits_exactly_needs_no_stated_noise():
    """No residual left: the robust spread is zero, and the fit still runs (on a floor of 1e-12) to the exact values;
    so does a fit of one parameter."""
    rng = np.random.default_rng(10)
    a = rng.normal(size=(30, 3))
    table = _fit(a, a @ [1.0, -2.0, 0.5], ["1"] * 3, loss="huber")[0]
    np.testing.assert_allclose(table.value, [1.0, -2.0, 0.5], atol=1e-12)
    assert 0.0 < table.robust["scale_mm"] <= 3e-12
    one = _fit(a[:, :1], 2.0 * a[:, 0] + 0.1, ["1"])[0]
    assert one.value[0] == pytest.approx(np.linalg.lstsq(a[:, :1], 2.0 * a[:, 0] + 0.1, rcond=None)[0][0], rel=1e-12)


def test_a_joint_held_with_jitter_is_set_to_its_median_from_two_poses_on():
    """Readings within 0.01 degrees are one held angle: from two poses on, the middle of them; one pose is left as
    read, and so is a joint that moves."""
    q = np.array([[10.0, 0.0], [10.004, 30.0]])
    np.testing.assert_allclose(held_still(q), [[10.002, 0.0], [10.002, 30.0]], rtol=0, atol=1e-12)
    q3 = np.array([[10.0, 0.0], [10.004, 30.0], [10.001, 60.0]])
    np.testing.assert_allclose(held_still(q3)[:, 0], 10.001, rtol=0, atol=1e-12)
    assert held_still(q[:1]).tolist() == [[10.0, 0.0]]


def test_a_robust_fits_evaluations_are_every_solvers_count(monkeypatch):
    """The table's evaluations add up what scipy reports for each fit made: least squares, then the two robust fits
    that the scale settles in (see the test above)."""
    import partcal.calibration.fit as fit

    counts, solve = [], fit._solve

    def counted(*args, **kwargs):
        v, nfev = solve(*args, **kwargs)
        counts.append(nfev)
        return v, nfev
    monkeypatch.setattr(fit, "_solve", counted)
    a, b = _one_far_row()
    table = _fit(a, b, ["1"] * 3, loss="cauchy")[0]
    assert len(counts) == 3 and min(counts) > 0 and table.evaluations == sum(counts)


def test_the_robust_fit_is_the_same_in_any_unit_and_with_a_stated_noise_fits_once():
    """Everything a hundred times larger: the values a hundred times larger too (the 5 % rule is relative). With the
    noise stated (0.01), one fit at three times it, IRLS's."""
    a, b = _one_far_row()
    small = _fit(a, b, ["1"] * 3, loss="cauchy")[0]
    large = _fit(a, 100.0 * b, ["1"] * 3, loss="cauchy")[0]
    np.testing.assert_allclose(large.value, 100.0 * small.value, rtol=1e-9)
    assert large.robust["scale_mm"] == pytest.approx(100.0 * small.robust["scale_mm"], rel=1e-9)
    stated = _fit(a, b, ["1"] * 3, loss="cauchy", reference_mm=0.01)[0]
    lsq = np.linalg.lstsq(a, b, rcond=None)[0]
    np.testing.assert_allclose(stated.value, _irls(a, b, 0.03, lsq), rtol=1e-7)
    assert stated.robust["scale_mm"] == pytest.approx(0.03, rel=1e-12)


def test_a_robust_fit_names_rows_by_their_own_map_and_their_residuals_in_mm():
    """The far residuals mapped to row 0 are row 0's; mapped to no row (-1, as a prior's rows are) they name none.
    With every residual weighed 2 (in ``row_weight`` and as ``weighted_by``) the far row's residual is still its miss
    in the data's own unit."""
    a, b = _one_far_row()
    first = _fit(a, b, ["1"] * 3, loss="cauchy", row_of=np.repeat((np.arange(20) - 4) % 20, 3))[0]
    assert [d["row"] for d in first.robust["downweighted"]] == [0]
    row_of = np.repeat(np.arange(20), 3)
    row_of[12:15] = -1
    assert _fit(a, b, ["1"] * 3, loss="cauchy", row_of=row_of)[0].robust["downweighted"] == []
    table, resid = _fit(a, b, ["1"] * 3, loss="cauchy")
    weighted = _fit(a, b, ["1"] * 3, loss="cauchy", row_weight=np.full(60, 2.0))[0]
    np.testing.assert_allclose(weighted.value, table.value, rtol=1e-7)
    assert weighted.robust["downweighted"][0]["residual_mm"] == pytest.approx(np.linalg.norm(resid[12:15]), rel=1e-6)
    jac_at = _linear(2.0 * a, 2.0 * b)                          # residuals already weighed 2 by the caller
    names = [(f"p{k}", "1") for k in range(3)]
    given = fit_parameters(jac_at, np.zeros(3), 2.0 * a, np.ones(3, dtype=bool), names, 1e-6, 3, 20, loss="cauchy",
                           weighted_by=np.full(60, 2.0))[0]
    assert given.robust["downweighted"][0]["residual_mm"] == pytest.approx(np.linalg.norm(resid[12:15]), rel=1e-6)


def test_the_noise_needs_a_residual_beyond_the_parameters():
    """As many residuals as parameters: no spread and no standard errors (NaN); one more: the residual's square."""
    a = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    square = _fit(a, np.array([1.0, 2.0, 3.0]), ["1"] * 3)[0]
    assert np.isnan(square.sigma_mm) and np.isnan(square.std_error).all()
    a, b = np.vstack([a, [1.0, 1.0, 1.0]]), np.array([1.0, 2.0, 3.0, 1.0])
    one = _fit(a, b, ["1"] * 3)[0]
    rss = np.sum((a @ one.value - b) ** 2)
    assert rss > 1.0 and one.sigma_mm == pytest.approx(np.sqrt(rss), rel=1e-9)
