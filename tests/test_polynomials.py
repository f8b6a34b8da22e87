"""Polynomials as coefficient arrays: the change of variables and the monomial evaluator."""

import numpy as np
import pytest
from numpy.polynomial import polynomial as P

from partcal.models.features import Basis, Scaling, lift_coefficients
from partcal.models.polynomials import coef_centred, coef_from_scaled, expansion_size, lowered_terms, monomials


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


def test_expansion_size_counts_every_lower_monomial_of_every_term():
    assert expansion_size([(0, 0), (1, 1), (2, 0), (1, 1)]) == 1 + 4 + 3 + 4      # prod(e_i + 1) per term


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
