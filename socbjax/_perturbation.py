"""The lateral perturbation of strands: :func:`strand_perturbation` and its differentiable
form :func:`perturbation_pattern`.  Units: pN, µm.

A straight inextensible strand between probe and surface carries any axial force (its
stiffness is singular), so compressions need an imperfection: a small lateral force on the
middle node of every strand (the paper's perturbation).  The random choices (which node,
the direction around a 3D strand) are made on the host from the topology and a seed
(:func:`perturbation_plan`); the direction itself is a JAX function of the node positions,
so loads follow a traced geometry (e.g. a fitted branch angle) and a traced magnitude.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import check_int, check_real
from ._network import Network

__all__ = ["default_perturbation", "perturbation_pattern", "perturbation_plan", "strand_perturbation", "strand_segments"]


def strand_segments(network: Network) -> list[np.ndarray]:
    """The segment indices of every strand, in strand-id order (host side)."""
    strand = np.asarray(network.strand)
    return [np.flatnonzero(strand == k) for k in np.unique(strand)]


def perturbation_plan(network: Network, seed: int = 0) -> dict:
    """Choices of :func:`strand_perturbation` (topology and ``seed`` only): per strand k the
    loaded node (the end node of its middle segment), its first and last node and the random
    azimuth (3D; 2D alternates the side, one strand: always the first perpendicular)."""
    rng = np.random.default_rng(seed)
    seg, strands = np.asarray(network.segments), strand_segments(network)
    plan = {key: [] for key in ("node", "first", "last", "angle")}
    for k, segs in enumerate(strands):
        segs = np.sort(segs)
        angle = (0.0 if k % 2 == 0 else np.pi) if network.dim == 2 else (0.0 if len(strands) == 1 else rng.uniform(0, 2 * np.pi))
        for key, value in zip(plan, (seg[segs[(len(segs) - 1) // 2], 1], seg[segs[0], 0], seg[segs[-1], 1], angle)):
            plan[key].append(value)
    return {key: np.asarray(value) for key, value in plan.items()}


def _reference(t, axis):
    """A lateral reference direction per 3D strand (unit chords ``t`` [K, 3]) that fixes the
    sign of t × axis and the direction of strands parallel to the probe axis; not
    differentiated (it only makes a discrete choice)."""
    t = jax.lax.stop_gradient(t)
    basis = jax.vmap(lambda tk: jnp.linalg.svd(jnp.eye(3) - jnp.outer(tk, tk))[0][:, :2])(t)  # [K, 3, 2]
    along = jnp.einsum("kij,i->kj", basis, axis)
    parallel = jnp.linalg.norm(along, axis=-1, keepdims=True) <= 1e-6
    plane = jnp.where(parallel, jnp.array([1.0, 0.0]), jnp.stack([-along[:, 1], along[:, 0]], -1))
    ref = jnp.einsum("kij,kj->ki", basis, plane)
    return ref / jnp.linalg.norm(ref, axis=-1, keepdims=True)


def perturbation_pattern(positions, plan: dict, axis, n_nodes: int):
    """Unit lateral loads [N, d] of :func:`strand_perturbation` as a differentiable function
    of the node ``positions`` [N, d]: perpendicular to each strand's chord; in 3D
    cos(angle) e₁ + sin(angle) t × e₁ with e₁ ∥ t × axis."""
    t = positions[plan["last"]] - positions[plan["first"]]
    t = t / jnp.linalg.norm(t, axis=-1, keepdims=True)
    if positions.shape[-1] == 2:
        lateral = jnp.stack([-t[:, 1], t[:, 0]], -1) * jnp.cos(jnp.asarray(plan["angle"]))[:, None]
    else:
        axis = jnp.asarray(axis)
        reference = _reference(t, axis)
        c = jnp.cross(t, axis[None, :])
        norm = jnp.linalg.norm(c, axis=-1, keepdims=True)
        sign = jax.lax.stop_gradient(jnp.sign(jnp.sum(c * reference, -1, keepdims=True)))
        e1 = jnp.where(norm > 1e-6, sign * c / jnp.where(norm > 1e-6, norm, 1.0), reference)
        angle = jnp.asarray(plan["angle"])[:, None]
        lateral = jnp.cos(angle) * e1 + jnp.sin(angle) * jnp.cross(t, e1)
        lateral = lateral / jnp.linalg.norm(lateral, axis=-1, keepdims=True)
    return jnp.zeros((n_nodes, positions.shape[-1]), lateral.dtype).at[plan["node"]].add(lateral)


def strand_perturbation(network: Network, magnitude, *, seed: int = 0):
    """Loads [N, d] (pN, a JAX array): a lateral force of ``magnitude`` (may be traced) on the
    middle node of every strand (the end node of its middle segment), perpendicular to the
    strand and to the probe direction where possible; random azimuth from ``seed`` in 3D,
    alternating sign in 2D (single strands: always the first perpendicular, positive).
    A concrete ``magnitude`` must be finite and >= 0 and ``seed`` an integer >= 0
    (``ValueError``/``TypeError`` naming them)."""
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network, got {type(network).__name__}")
    magnitude = check_real("magnitude", magnitude, "pN", low=0.0, low_open=False)
    seed = check_int("seed", seed, minimum=0, maximum=None, hint=" (numpy's random generator needs a non-negative seed)")
    pattern = perturbation_pattern(network.positions, perturbation_plan(network, seed), network.probe_direction,
                                   network.n_nodes)
    return jnp.asarray(magnitude, jnp.float64) * pattern


def default_perturbation(EI, lengths, strands) -> jax.Array:
    """The default lateral force (pN): 1e-4 EI/L² per strand (mean EI, L the longest
    strand's contour length); differentiable in ``EI`` [S] and ``lengths`` [S]."""
    L = jnp.max(jnp.stack([jnp.sum(jnp.asarray(lengths)[s]) for s in strands]))
    return 1e-4 * jnp.mean(jnp.asarray(EI)) / L**2
