"""The quintic polynomial of Eqs 5/6a and the Gauss–Legendre tables of Eq. 7."""

import numpy as np
import pytest

from socbjax._quadrature import (
    coupling_matrix,
    gauss_legendre,
    hermite_basis,
    integration_matrix,
    quintic_coefficients,
)


def test_coupling_matrix_recovers_a_quintic(rng):
    coeffs = rng.normal(size=6)
    length = 0.7
    poly = np.polynomial.Polynomial(coeffs)
    d1, d2 = poly.deriv(1), poly.deriv(2)
    data = [poly(0), d1(0), d2(0), poly(length), d1(length), d2(length)]
    np.testing.assert_allclose(quintic_coefficients(data, length), coeffs, rtol=1e-10, atol=1e-10)


def test_coupling_matrix_row4_is_the_corrected_one():
    # θ(l) = a + b l + c l² + ... : the paper's printed "1 1 l² ..." would be wrong.
    np.testing.assert_allclose(coupling_matrix(2.0)[3], [1, 2, 4, 8, 16, 32])


@pytest.mark.parametrize("order", [2, 4, 8, 12])
def test_gauss_legendre_exact_to_degree_2k_minus_1(order):
    x, w = gauss_legendre(order)
    for p in range(2 * order):
        assert np.isclose(w @ x**p, 1.0 / (p + 1), rtol=1e-13, atol=1e-15)
    # and not beyond
    p = 2 * order
    assert not np.isclose(w @ x**p, 1.0 / (p + 1), rtol=1e-13, atol=0)


def test_integration_matrix_exact_for_polynomials_below_order():
    order = 8
    x, _ = gauss_legendre(order)
    A = integration_matrix(order)
    for p in range(order):
        np.testing.assert_allclose(A @ x**p, x ** (p + 1) / (p + 1), rtol=1e-12, atol=1e-14)


def test_hermite_basis_interpolates_end_data():
    H = hermite_basis((0.0, 1.0))
    np.testing.assert_allclose(H[0], [1, 0, 0, 0, 0, 0], atol=1e-14)
    np.testing.assert_allclose(H[1], [0, 0, 0, 1, 0, 0], atol=1e-14)


def test_quadrature_order_validation():
    with pytest.raises(ValueError, match="order"):
        gauss_legendre(1)
