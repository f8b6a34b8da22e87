"""Feature maps and raw-unit equations."""

import numpy as np
import pytest

from partcal.models.bases import Basis, PolynomialReframe, Scaling, SeriesPlan, lift_coefficients, raw_polynomial


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


def test_raw_polynomial_with_cross_terms():
    # c = 3 + 2 u v with u = (x - 1)/2, v = (y + 2)/4  ->  3 + (x - 1)(y + 2)/4 = 2.5 + x/2 - y/4 + xy/4
    s = Scaling(np.array([1.0, -2.0]), np.array([2.0, 4.0]), np.array([True, True]))
    raw = raw_polynomial([(0, 0), (1, 1)], np.array([3.0, 2.0]), s)
    assert raw == pytest.approx({(0, 0): 2.5, (1, 0): 0.5, (0, 1): -0.25, (1, 1): 0.25})


@pytest.mark.parametrize("degree, cross", [(1, False), (2, False), (3, True), (5, False)])
def test_reframed_polynomials_are_the_same_functions(degree, cross):
    """A series in one scaling, re-expressed in another frame, evaluates to the same values there."""
    rng = np.random.default_rng(degree)
    X = rng.uniform([-800, 0, 300], [600, 900, 1200], size=(400, 3))
    basis = Basis("polynomial", "cartesian", degree, cross)
    own = Scaling.fit(X[:, [0, 1, 2]] * [1, 0, 1] + [0, 5, 0])          # the y input constant in this region
    terms = basis.terms(own)
    coef = rng.normal(size=(len(terms), 3))
    full = basis.terms(Scaling(np.zeros(3), np.ones(3), np.ones(3, bool)))
    lifted = lift_coefficients(terms, coef, full)
    frame = Scaling(np.array([-100.0, 450, 750]), np.array([40.0, 70, 55]), np.ones(3, bool))
    reframed = PolynomialReframe(full).apply(lifted[None], (frame.scale / own.scale)[None],
                                             ((frame.centre - own.centre) / own.scale)[None])[0]
    expected = basis.transform(X, own, terms) @ coef
    np.testing.assert_allclose(basis.transform(X, frame, full) @ reframed, expected, rtol=1e-11, atol=1e-9)


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
