"""Priors in kinematic identification (MAP) and `partcal update`: a model file as the prior of a new fit."""

import numpy as np
import pytest
from scipy.optimize import least_squares

from partcal import load_robot
from partcal.models.identification import identify, model_positions, nominal_values, parameter_names
from partcal.models.prior import Prior, plausible_prior


@pytest.fixture(scope="module")
def ur10():
    return load_robot("universal_robots_ur10")


def poses(robot, n, seed, spread=1.0):
    rng = np.random.default_rng(seed)
    lo, hi = robot.limits_deg[:, 0], robot.limits_deg[:, 1]
    mid = (lo + hi) / 2
    return mid + spread * rng.uniform(-1, 1, (n, robot.n_joints)) * np.minimum((hi - lo) / 2, 120.0)


def moved(robot, seed):
    """Measured positions of a robot whose rows' parameters are off by about 0.5 mm / 0.05 deg, with noise."""
    units = np.array([u for _, u in parameter_names(robot)])
    rng = np.random.default_rng(seed)
    true = nominal_values(robot) + rng.normal(size=units.size) * np.where(units == "mm", 0.5, 0.05)
    true[-15:] = nominal_values(robot)[-15:]                  # tool, base: nominal
    return true


def test_map_equals_an_independent_augmented_least_squares(ur10):
    q = poses(ur10, 25, 1)
    true = moved(ur10, 2)
    measured = model_positions(ur10, None, q, true, np.zeros(len(q))) + \
        np.random.default_rng(3).normal(scale=0.05, size=(len(q), 3))
    v0 = nominal_values(ur10)
    index = np.arange(24)                                     # the DH rows' parameters
    rng = np.random.default_rng(4)
    a = rng.normal(size=(24, 24)) * 0.05
    cov = a @ a.T + np.diag(np.where(np.isin(np.arange(24) % 4, (1, 2)), 0.3, 0.03) ** 2)
    mean = v0[index] + rng.normal(size=24) * 0.1
    noise = 0.05
    table = identify(ur10, q, measured, prior=Prior.from_covariance(index, mean, cov, noise))
    free = np.flatnonzero(np.array(table.status) == "identified")
    plain = identify(ur10, q, measured)
    assert np.sum(np.array(plain.status)[:24] == "identified") < 20
    # the prior makes every row parameter identifiable but the two whose column is nil (the flange's turn
    # and twist do not move a tool on its axis: the lever rule drops them, with or without a prior)
    assert set(index) - set(free) == {20, 23}
    chol = np.linalg.cholesky(cov)

    def resid(x):                                             # written out: |r|^2 + sigma^2 (v-m)^T C^-1 (v-m)
        v = v0.copy()
        v[free] = x
        p = model_positions(ur10, None, q, v, np.zeros(len(q)))
        return np.concatenate([(p - measured).ravel(), noise * np.linalg.solve(chol, v[index] - mean)])

    x = least_squares(resid, v0[free], jac="3-point", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    np.testing.assert_allclose(np.sum(resid(table.value[free]) ** 2), np.sum(resid(x) ** 2), rtol=1e-9)
    np.testing.assert_allclose(table.value[free], x, atol=1e-5)     # the valley is flat to 1e-13 mm^2 there


def test_a_strong_prior_returns_its_mean_and_a_zero_one_the_plain_fit(ur10):
    q = poses(ur10, 40, 5)
    true = moved(ur10, 6)
    measured = model_positions(ur10, None, q, true, np.zeros(len(q)))
    v0 = nominal_values(ur10)
    units = [u for _, u in parameter_names(ur10)]
    mean = v0.copy()
    mean[:24] += np.random.default_rng(7).normal(size=24) * 0.2
    strong = identify(ur10, q, measured, prior=Prior.from_std(np.arange(24), mean[:24], np.full(24, 1e-3), 1e4))
    np.testing.assert_allclose(strong.value[:24], mean[:24], atol=1e-6)
    plain = identify(ur10, q, measured)
    none = identify(ur10, q, measured, prior=Prior.from_std(np.arange(24), mean[:24], np.ones(24), 0.0))
    identified = np.array(plain.status) == "identified"
    assert none.status == plain.status
    np.testing.assert_allclose(none.value[identified], plain.value[identified], atol=1e-8)
    assert plausible_prior(units, 24, v0, 0.0, {"mm": 1.0, "deg": 0.1}) is None


def test_without_a_prior_the_fit_is_unchanged_bit_for_bit(ur10):
    q = poses(ur10, 30, 8)
    measured = model_positions(ur10, None, q, moved(ur10, 9), np.zeros(len(q)))
    a, b = identify(ur10, q, measured), identify(ur10, q, measured, prior=None)
    assert np.array_equal(a.value, b.value) and a.status == b.status and a.rms_mm == b.rms_mm


def test_a_bad_prior_covariance_is_refused():
    with pytest.raises(ValueError, match=r"\(2, 2\) matrix"):
        Prior.from_covariance([0, 1], [0.0, 0.0], np.eye(3), 1.0)
    with pytest.raises(ValueError, match="positive definite"):
        Prior.from_covariance([0, 1], [0.0, 0.0], -np.eye(2), 1.0)
    with pytest.raises(ValueError, match="standard deviations > 0"):
        Prior.from_std([0], [0.0], [0.0], 1.0)
