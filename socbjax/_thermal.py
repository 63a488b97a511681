"""Thermally curved filaments: :func:`thermal_network`.

A worm-like chain of bending stiffness EI at temperature T has persistence length
Lp = EI / (k_B T).  In the plane its tangent angle is a Brownian motion in arc length: the
turn of a piece of length l is Gaussian with mean 0 and variance l / Lp, independent between
pieces.  In space (twisting networks) each segment's two bending angles κ₁l, κ₂l on its
material frame are independent N(0, l/Lp), so the squared bending angle has mean 2l/Lp; the
tangent correlation ⟨t(0)·t(s)⟩ is then exp(−s/Lp) up to a relative O((l/Lp)²) per segment
(the exact spherical Brownian step is not Gaussian).  No natural twist is drawn.  :func:`thermal_network` draws one such turn τ_k per segment and freezes it as the
segment's stress-free shape (natural curvature κ₀ = τ_k / l_k, a circular arc), so the
node tangents of the result are an exact sample of the chain's equilibrium tangent
statistics at the nodes (⟨cos(θ(s) − θ(0))⟩ = exp(−s / 2Lp) along any strand).  The shape
between nodes is the arc, not a finer random walk: finer detail needs more nodes.

k_B = 1.380649e-5 pN·µm/K (1.380649e-23 J/K; 1 pN·µm = 1e-18 J); at 298 K, k_B T =
4.114e-3 pN·µm and actin (EI = 0.071 pN·µm²) has Lp = 17.3 µm.  Units: µm, pN, K.
"""

from __future__ import annotations

import numpy as np

from ._checks import check_int, check_real
from ._curved import check_curvable, with_natural_curvature
from ._network import Network

__all__ = ["BOLTZMANN", "persistence_length", "thermal_network"]

BOLTZMANN = 1.380649e-5  # k_B in pN·µm/K
# A drawn turn of half a circle in one segment is impossible; below this spread (rad) the
# chance of one in a million segments is < 1e-300, so nothing is truncated in practice.
MAX_TURN_SPREAD = np.pi / 8


def persistence_length(EI, temperature: float = 298.0):
    """Lp = EI / (k_B T) (µm) for ``EI`` in pN·µm² and ``temperature`` in K."""
    T = check_real("temperature", temperature, "K", low=0.0)
    return np.asarray(EI, float) / (BOLTZMANN * T)


def thermal_network(network: Network, temperature: float = 298.0, seed: int = 0) -> Network:
    """``network`` with each segment's stress-free shape drawn from the worm-like-chain
    equilibrium at ``temperature`` (K).  2D: a turn τ_k ~ N(0, l_k / Lp_k) per segment with
    Lp_k = EI_k / (k_B T), added to any natural curvature the segment already has, and the
    reference positions and tangents rebuilt as in :func:`socbjax.with_natural_curvature`
    (one anchor node per piece keeps its place; supports keep their kind at the new node
    positions; junction angles are kept).  Deterministic in ``seed`` (numpy's default
    generator, one standard normal per segment in segment order).

    ``ValueError`` when a segment is so long that its turns are not small
    (√(l/Lp) > π/8): refine the segments.  3D: two bending angles per segment (see the
    module), for twisting networks only (``ValueError`` for a torsion-free 3D network).
    """
    check_curvable(network, "thermal_network")
    seed = check_int("seed", seed, minimum=0, maximum=None)
    Lp = persistence_length(np.asarray(network.EI, float), temperature)
    lengths = np.asarray(network.lengths, float)
    spread = np.sqrt(lengths / Lp)
    if np.any(spread > MAX_TURN_SPREAD):
        k = int(np.argmax(spread))
        raise ValueError(f"segment {k} (length {lengths[k]:.4g} µm) is {lengths[k] / Lp[k]:.3g} persistence lengths long "
                         f"at {temperature} K (Lp = {Lp[k]:.4g} µm): its thermal turns (spread {np.degrees(spread[k]):.3g}°) "
                         f"are not small; use segments shorter than {Lp[k] * MAX_TURN_SPREAD**2:.3g} µm")
    rng = np.random.default_rng(seed)
    if network.dim == 2:
        turns = spread * rng.standard_normal(len(lengths))
        return with_natural_curvature(network, np.asarray(network.natural_curvature, float) + turns / lengths)
    if not network.twisting:
        raise ValueError("thermal_network: a naturally curved 3D filament needs its torsional stiffness; build the "
                         "network with GJ= (e.g. actin's 8e-3 pN·µm²)")
    bends = spread[:, None] * rng.standard_normal((len(lengths), 2))  # (κ₁ l, κ₂ l): variance l/Lp each
    kappa = np.asarray(network.natural_curvature, float) + np.concatenate([bends / lengths[:, None],
                                                                          np.zeros((len(lengths), 1))], axis=1)
    return with_natural_curvature(network, kappa)
