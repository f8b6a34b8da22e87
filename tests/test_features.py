"""Feature maps, input scaling and compiled series."""

import numpy as np
import pytest

from partcal.models.features import Basis, Scaling, SeriesPlan


def test_scaling_maps_training_range_to_unit_and_drops_constant_inputs():
    X = np.array([[0.0, 5.0, 1.0], [10.0, 5.0, 3.0]])
    s = Scaling.fit(X)
    assert s.active.tolist() == [True, False, True]
    np.testing.assert_allclose((X - s.centre) / s.scale, [[-1, 0, -1], [1, 0, 1]])


def test_polynomial_terms_follow_the_paper_order():
    s = Scaling.fit(np.array([[0.0, 0.0], [2.0, 4.0]]))
    basis = Basis("polynomial", "cartesian", 2)
    assert basis.terms(s) == [(0, 0), (1, 0), (2, 0), (0, 1), (0, 2)]      # 1, u1, u1², u2, u2²
    phi = basis.transform(np.array([[2.0, 1.0]]), s)                        # u = (1, -0.5)
    np.testing.assert_allclose(phi, [[1, 1, 1, -0.5, 0.25]])
    cross = Basis("polynomial", "cartesian", 2, cross_terms=True)
    assert len(cross.terms(s)) == 6 == cross.n_terms(2)                     # 1, u1, u2, u1², u1u2, u2²


def test_fourier_terms_use_joint_angles_in_radians():
    s = Scaling.fit(np.array([[0.0], [90.0]]))
    basis = Basis("fourier", "joint", 2)
    phi = basis.transform(np.array([[30.0]]), s)
    c, si = np.cos(np.pi / 6), np.sin(np.pi / 6)
    np.testing.assert_allclose(phi, [[1, c, si, np.cos(np.pi / 3), np.sin(np.pi / 3)]])
    assert basis.n_terms(6) == 25                # 25 per axis: 75 for x, y, z


def sequential_features(u, terms):
    """Features in the documented order: u^k = u^(k-1) * u, then the inputs' powers multiplied left to right."""
    out = np.empty((u.shape[0], len(terms)))
    for t, e in enumerate(terms):
        value = np.ones(u.shape[0])
        for n, (i, k) in enumerate((i, k) for i, k in enumerate(e) if k):
            power = u[:, i]
            for _ in range(k - 1):
                power = power * u[:, i]
            value = power if n == 0 else value * power
        out[:, t] = value
    return out


@pytest.mark.parametrize("d, degree, cross", [(3, 2, False), (3, 8, False), (3, 3, True), (3, 6, True),
                                              (6, 4, True), (6, 8, False)])
def test_fitted_features_are_the_sequential_products_to_the_last_bit(d, degree, cross):
    """The swarm compares fitnesses to the last bit: the feature matrix is pinned exactly, not to rounding."""
    rng = np.random.default_rng(degree)
    X = rng.uniform(-1700, 1500, size=(200, d))
    s = Scaling.fit(X)
    basis = Basis("polynomial", "joint", degree, cross)
    terms = basis.terms(s)
    phi = basis.transform(X, s, terms)
    np.testing.assert_array_equal(phi, sequential_features((X - s.centre) / s.scale, terms))
    assert phi.flags.c_contiguous


SERIES = [("polynomial", "cartesian", 1, False), ("polynomial", "cartesian", 2, False),
          ("polynomial", "cartesian", 8, False), ("polynomial", "cartesian", 3, True),
          ("polynomial", "joint", 2, False), ("polynomial", "joint", 4, True),
          ("fourier", "joint", 1, False), ("fourier", "joint", 5, False), ("fourier", "cartesian", 3, False)]


@pytest.mark.parametrize("kind, inputs, order, cross", SERIES)
def test_compiled_series_equals_the_feature_matrix_product(kind, inputs, order, cross):
    rng = np.random.default_rng(order)
    d = 3 if inputs == "cartesian" else 6
    train = rng.uniform(-800, 1500, size=(50, d))
    if inputs == "joint":
        train[:, 3:5] = [0.0, 30.0]                    # constant joints, left out of the basis
    scaling = Scaling.fit(train)
    basis = Basis(kind, inputs, order, cross)
    terms = basis.terms(scaling)
    coef = rng.normal(size=(len(terms), 3))
    plan = SeriesPlan.build(basis, scaling, terms, coef)
    X = rng.uniform(-1200, 1900, size=(3 * plan.chunk + 17, d))     # beyond the data, several chunks
    np.testing.assert_allclose(plan.evaluate(X), basis.transform(X, scaling, terms) @ coef, rtol=0, atol=1e-9)
    assert plan.evaluate(X[:0]).shape == (0, 3)


def test_compiled_polynomial_keeps_unusual_term_lists():
    # a model file may list terms in any order, with gaps: x^3 without x^2, a repeated term
    s = Scaling(np.array([100.0, -50.0]), np.array([20.0, 40.0]), np.array([True, True]))
    terms = [(0, 0), (3, 0), (1, 2), (0, 1), (3, 0)]
    coef = np.array([[1.0], [2.0], [-3.0], [0.5], [0.25]])
    X = np.array([[110.0, -30.0], [60.0, 10.0]])
    u = (X - s.centre) / s.scale
    expected = 1 + 2.25 * u[:, 0] ** 3 - 3 * u[:, 0] * u[:, 1] ** 2 + 0.5 * u[:, 1]
    plan = SeriesPlan.build(Basis("polynomial", "cartesian", 3, True), s, terms, coef)
    np.testing.assert_allclose(plan.evaluate(X)[:, 0], expected, rtol=1e-13)


def test_compiled_series_memory_is_bounded_by_its_output():
    import tracemalloc

    rng = np.random.default_rng(0)
    scaling = Scaling.fit(rng.uniform(-1000, 1000, size=(40, 3)))
    basis = Basis("polynomial", "cartesian", 4, True)            # 35 terms
    terms = basis.terms(scaling)
    plan = SeriesPlan.build(basis, scaling, terms, rng.normal(size=(len(terms), 3)))
    X = rng.uniform(-1000, 1000, size=(200_000, 3))
    tracemalloc.start()
    out = plan.evaluate(X)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    feature_matrix = X.shape[0] * len(terms) * 8
    assert peak < out.nbytes + 2 * 2**20 < feature_matrix / 5
