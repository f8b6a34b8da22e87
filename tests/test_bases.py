"""Feature maps and raw-unit equations."""

import numpy as np
import pytest

from numpy.polynomial import polynomial as P

from partcal.models.bases import (Basis, Scaling, SeriesPlan, coef_centred, coef_from_scaled, lift_coefficients,
                                  lowered_terms, monomials)


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


def test_coefficients_from_scaled_inputs_with_cross_terms():
    # 3 + 2 u v with u = (x - 1)/2, v = (y + 2)/4  ->  3 + (x - 1)(y + 2)/4 = 2.5 + x/2 - y/4 + xy/4
    terms = [(0, 0), (1, 1)]
    raw = coef_from_scaled(terms, np.array([[3.0], [2.0]]), np.array([2.0, 4.0]), np.array([1.0, -2.0]))
    assert lowered_terms(terms) == [(0, 0), (1, 1), (0, 1), (1, 0)]
    np.testing.assert_allclose(raw[:, 0], [2.5, 0.25, -0.25, 0.5], rtol=1e-15)


@pytest.mark.parametrize("scale, shift", [(1.0, 0.0), (2.0, 10.0), (0.05, -3.0), (250.0, 1200.0), (-1.5, 0.7)])
def test_coefficients_from_scaled_match_numpy_polynomial_composition(scale, shift):
    """One input: sum c_k ((x - shift) / scale)^k composed by numpy.polynomial, degrees 0 to 8."""
    rng = np.random.default_rng(7)
    c = rng.normal(size=9)
    expected = np.zeros(1)
    for k in range(9)[::-1]:                                   # Horner in the polynomial u(x)
        expected = P.polyadd(P.polymul(expected, [-shift / scale, 1 / scale]), [c[k]])
    got = coef_from_scaled([(k,) for k in range(9)], c[:, None], np.array([scale]), np.array([shift]))[:, 0]
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())


def direct(v, terms, coef):
    """A polynomial evaluated term by term: sum_t coef_t prod_i v_i^e_ti (v: (n, d))."""
    return np.stack([np.prod(v ** np.array(e, dtype=float), axis=1) for e in terms], axis=1) @ coef


@pytest.mark.parametrize("seed", range(4))
def test_coefficients_from_scaled_keep_the_function_for_any_terms_and_frames(seed):
    """Random term lists (gaps, repeats, cross terms) in 3 inputs, random frames, 2 problems at once."""
    rng = np.random.default_rng(seed)
    terms = [tuple(int(k) for k in rng.integers(0, 4, 3)) for _ in range(6)] + [(0, 0, 0)]
    terms.append(terms[1])
    coef = rng.normal(size=(2, len(terms), 2))
    scale, shift = rng.uniform(0.5, 3.0, (2, 3)) * rng.choice([-1, 1], (2, 3)), rng.normal(size=(2, 3))
    v = rng.uniform(-2, 2, size=(50, 3))
    batch = coef_from_scaled(terms, coef, scale, shift)
    for p in range(2):
        expected = direct((v - shift[p]) / scale[p], terms, coef[p])
        np.testing.assert_allclose(direct(v, lowered_terms(terms), batch[p]), expected, rtol=1e-10, atol=1e-10)
        np.testing.assert_array_equal(coef_from_scaled(terms, coef[p], scale[p], shift[p]), batch[p])


def test_centred_coefficients_divide_by_the_scale_powers():
    terms, coef = coef_centred([(0, 0), (2, 1), (0, 1), (2, 1)], np.array([[1.0], [2.0], [3.0], [4.0]]),
                               np.array([2.0, 5.0]))
    assert terms == [(0, 0), (2, 1), (0, 1)]
    np.testing.assert_allclose(coef[:, 0], [1.0, 6.0 / 20.0, 3.0 / 5.0], rtol=1e-15)


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
    reframed = coef_from_scaled(full, lifted, own.scale / frame.scale, (own.centre - frame.centre) / frame.scale)
    assert reframed.shape == lifted.shape                      # a basis's term list is closed under lowering
    expected = basis.transform(X, own, terms) @ coef
    np.testing.assert_allclose(basis.transform(X, frame, full) @ reframed, expected, rtol=1e-11, atol=1e-9)


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


@pytest.mark.parametrize("seed", range(5))
def test_monomials_fill_every_term_of_any_term_list(seed):
    rng = np.random.default_rng(seed)
    d = int(rng.integers(1, 5))
    terms = [tuple(int(k) for k in rng.integers(0, 5, d) * (rng.random(d) < 0.6)) for _ in range(12)]
    mono = monomials(terms)
    u = rng.uniform(-1.5, 1.5, size=(30, d))
    M = np.full((mono.n_rows, 30), np.nan)
    M[0] = 1.0
    M[1:1 + mono.columns.size] = u[:, mono.columns].T
    mono.fill(M)
    np.testing.assert_allclose(M[mono.rows(terms)].T, direct(u, terms, np.eye(len(terms))), rtol=1e-13)


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
