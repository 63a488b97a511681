"""The quintic angle polynomial (paper Eqs 5, 6a) and Gauss–Legendre quadrature (Eq. 7).

Everything here is plain numpy, computed once per quadrature order and used as
constants inside traced code.

A segment of length ``l`` carries an angle polynomial (Eq. 5)

    θ(s) = a + b s + c s² + d s³ + e s⁴ + f s⁵ ,   0 ≤ s ≤ l,

whose six coefficients follow from the Hermite data (θ, θ', θ'') at both ends through the
"coupling matrix" of Eq. 6a (with the misprinted row 4 corrected to ``1 l l² l³ l⁴ l⁵``).
Inside the solver the polynomial is written in the normalised coordinate σ = s/l ∈ [0, 1]
with scaled data (θ, l θ', l² θ''): this is Eq. 6a with l = 1, and it keeps the linear
algebra independent of the segment length (and well conditioned for any l).  The basis
``hermite_basis`` tabulates, at the quadrature points, the six cardinal polynomials
H_j(σ) with θ(σ) = Σ_j H_j(σ) d_j, obtained by inverting the coupling matrix.

Positions inside a segment, r(s) − r_i = ∫_0^s t, are needed by the bending equation
(Eq. 9).  They come from the Gauss–Legendre *integration matrix* A (A[k, j] = ∫_0^{σ_k}
L_j(σ) dσ with L_j the Lagrange polynomials on the Gauss points), which is exact when the
tangent is a polynomial of degree < K and spectrally accurate for the smooth tangents here.
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = [
    "coupling_matrix",
    "HERMITE_TO_MONOMIAL",
    "quintic_coefficients",
    "gauss_legendre",
    "integration_matrix",
    "hermite_basis",
    "hermite_basis_derivative",
    "SegmentQuadrature",
    "get_quadrature",
]


def coupling_matrix(length: float) -> np.ndarray:
    """The 6×6 coupling matrix of Eq. 6a (row 4 corrected), for a segment of ``length`` µm.

    Maps the polynomial coefficients (a, b, c, d, e, f) to the end data
    (θ(0), θ'(0), θ''(0), θ(l), θ'(l), θ''(l)).
    """
    l = float(length)
    return np.array(
        [
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 2.0, 0.0, 0.0, 0.0],
            [1.0, l, l**2, l**3, l**4, l**5],
            [0.0, 1.0, 2 * l, 3 * l**2, 4 * l**3, 5 * l**4],
            [0.0, 0.0, 2.0, 6 * l, 12 * l**2, 20 * l**3],
        ]
    )


# Hermite end data in σ-units (θ, θ', θ'' at σ = 0 and 1) -> monomial coefficients in σ
HERMITE_TO_MONOMIAL = np.linalg.inv(coupling_matrix(1.0))


def quintic_coefficients(end_data: np.ndarray, length: float) -> np.ndarray:
    """Solve Eq. 6a: coefficients (a..f) of θ(s) from (θ, θ', θ'') at s = 0 and s = l.

    Note: Eq. 6a as printed has ``1`` in the third diagonal entry (θ''(0) = c); the
    derivative of c s² is 2c, so the matrix above uses 2.
    """
    return np.linalg.solve(coupling_matrix(length), np.asarray(end_data, dtype=np.float64))


@functools.lru_cache(maxsize=None)
def gauss_legendre(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre points and weights on [0, 1] (``order`` points, exact to degree 2·order−1)."""
    if order < 2:
        raise ValueError(f"quadrature order must be >= 2, got {order}")
    x, w = np.polynomial.legendre.leggauss(order)
    return 0.5 * (x + 1.0), 0.5 * w


@functools.lru_cache(maxsize=None)
def integration_matrix(order: int) -> np.ndarray:
    """A[k, j] = ∫_0^{σ_k} L_j(σ) dσ for the Lagrange basis L_j on the Gauss points."""
    sigma, _ = gauss_legendre(order)
    vander = np.vander(sigma, order, increasing=True)  # [k, p] = σ_k^p
    # Coefficients of each Lagrange polynomial: solve V c = I.
    lagrange_coeffs = np.linalg.solve(vander, np.eye(order))  # [p, j]
    powers = np.arange(order)
    integrated = sigma[:, None] ** (powers + 1)[None, :] / (powers + 1)[None, :]  # [k, p]
    return integrated @ lagrange_coeffs


@functools.lru_cache(maxsize=None)
def hermite_basis(points: tuple[float, ...]) -> np.ndarray:
    """Cardinal quintic Hermite basis H[k, j] at normalised points σ_k (Eq. 6a with l = 1).

    θ(σ_k) = Σ_j H[k, j] d_j with d = (θ_0, θ'_0, θ''_0, θ_1, θ'_1, θ''_1) in σ-units.
    """
    sigma = np.asarray(points, dtype=np.float64)
    monomials = sigma[:, None] ** np.arange(6)[None, :]
    return monomials @ HERMITE_TO_MONOMIAL


@functools.lru_cache(maxsize=None)
def hermite_basis_derivative(points: tuple[float, ...]) -> np.ndarray:
    """dH[k, j]/dσ at normalised points σ_k: θ'(σ_k) = Σ_j dH[k, j] d_j (per unit σ)."""
    sigma = np.asarray(points, dtype=np.float64)
    powers = np.arange(6)
    monomials = powers[None, :] * sigma[:, None] ** np.maximum(powers - 1, 0)[None, :]
    return monomials @ HERMITE_TO_MONOMIAL


class SegmentQuadrature:
    """Constant tables for one quadrature order: points, weights, Hermite basis and its
    σ-derivative, A."""

    def __init__(self, order: int = 8):
        if not isinstance(order, (int, np.integer)) or order < 2:
            raise ValueError(f"quadrature_order must be an integer >= 2, got {order!r}")
        self.order = int(order)
        self.points, self.weights = gauss_legendre(self.order)
        self.basis = hermite_basis(tuple(self.points.tolist()))
        self.dbasis = hermite_basis_derivative(tuple(self.points.tolist()))  # d/dσ of the basis
        self.integration = integration_matrix(self.order)

    def __hash__(self) -> int:
        return hash(("SegmentQuadrature", self.order))

    def __eq__(self, other) -> bool:
        return isinstance(other, SegmentQuadrature) and other.order == self.order

    def __repr__(self) -> str:
        return f"SegmentQuadrature(order={self.order})"


@functools.lru_cache(maxsize=None)
def get_quadrature(order: int = 8) -> SegmentQuadrature:
    """Cached :class:`SegmentQuadrature` (one object per order, so jit caches hit)."""
    return SegmentQuadrature(order)
