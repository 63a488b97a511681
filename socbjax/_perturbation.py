"""The lateral perturbation of strands: :func:`strand_perturbation` and its differentiable
form :func:`perturbation_pattern`.  Units: pN, µm.

A straight inextensible strand between probe and surface carries any axial force (its
stiffness is singular), so compressions need an imperfection: a small lateral force on the
middle node of every strand (the paper's perturbation).  The random choices (which node,
the direction around a 3D strand) are made on the host from the topology and a seed; the
direction itself is a jax function of the node positions, so loads follow a traced geometry
(e.g. a fitted branch angle).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._network import Network

__all__ = ["strand_perturbation", "perturbation_pattern", "default_perturbation"]


def _strands(network: Network) -> list[np.ndarray]:
    strand = np.asarray(network.strand)
    return [np.flatnonzero(strand == k) for k in np.unique(strand)]


def _perturbation_plan(network: Network, seed: int = 0, positions=None, reference: bool = True) -> dict:
    """Choices of :func:`strand_perturbation`: per strand k the loaded node, its first and
    last node, the random angle (from ``seed`` and the strand count only) and, if
    ``reference``, from concrete ``positions`` (default the network's) a reference lateral direction in 3D that fixes the
    sign and the direction of strands parallel to the probe axis."""
    rng = np.random.default_rng(seed)
    seg, strands = np.asarray(network.segments), _strands(network)
    plan = {key: [] for key in ("node", "first", "last", "angle")}
    for k, segs in enumerate(strands):
        segs = np.sort(segs)
        angle = (0.0 if k % 2 == 0 else np.pi) if network.dim == 2 else (0.0 if len(strands) == 1 else rng.uniform(0, 2 * np.pi))
        for key, value in zip(plan, (seg[segs[(len(segs) - 1) // 2], 1], seg[segs[0], 0], seg[segs[-1], 1], angle)):
            plan[key].append(value)
    plan = {key: np.asarray(value) for key, value in plan.items()}
    plan["reference"] = np.zeros((len(strands), network.dim))
    if not reference:
        return plan  # the caller supplies the reference (from concrete positions)
    pos, axis = np.asarray(network.positions if positions is None else positions), np.asarray(network.probe_direction)
    for k in range(len(strands) if network.dim == 3 else 0):
        t = pos[plan["last"][k]] - pos[plan["first"][k]]
        t = t / np.linalg.norm(t)
        basis = np.linalg.svd(np.eye(3) - np.outer(t, t))[0][:, :2]
        along = basis.T @ axis
        reference = basis @ (np.array([-along[1], along[0]]) if np.linalg.norm(along) > 1e-6 else np.array([1.0, 0.0]))
        plan["reference"][k] = reference / np.linalg.norm(reference)
    return plan


def perturbation_pattern(positions, plan: dict, axis, n_nodes: int):
    """Unit lateral loads [N, d] of :func:`strand_perturbation` as a differentiable function
    of the node ``positions`` [N, d] (jax): perpendicular to each strand's chord; in 3D
    cos(angle) e₁ + sin(angle) t × e₁ with e₁ ∥ t × axis (sign and degenerate case from the
    plan's reference direction)."""
    t = positions[plan["last"]] - positions[plan["first"]]
    t = t / jnp.linalg.norm(t, axis=-1, keepdims=True)
    if positions.shape[-1] == 2:
        lateral = jnp.stack([-t[:, 1], t[:, 0]], -1) * jnp.cos(jnp.asarray(plan["angle"]))[:, None]
    else:
        reference = jnp.asarray(plan["reference"])
        c = jnp.cross(t, jnp.asarray(axis)[None, :])
        norm = jnp.linalg.norm(c, axis=-1, keepdims=True)
        sign = jax.lax.stop_gradient(jnp.sign(jnp.sum(c * reference, -1, keepdims=True)))
        e1 = jnp.where(norm > 1e-6, sign * c / jnp.where(norm > 1e-6, norm, 1.0), reference)
        angle = jnp.asarray(plan["angle"])[:, None]
        lateral = jnp.cos(angle) * e1 + jnp.sin(angle) * jnp.cross(t, e1)
        lateral = lateral / jnp.linalg.norm(lateral, axis=-1, keepdims=True)
    return jnp.zeros((n_nodes, positions.shape[-1]), lateral.dtype).at[plan["node"]].add(lateral)


def strand_perturbation(network: Network, magnitude: float, *, seed: int = 0) -> np.ndarray:
    """Loads [N, d] (pN): a lateral force of ``magnitude`` on the middle node of every strand
    (the end node of its middle segment), perpendicular to the strand and to the probe
    direction where possible; random direction from ``seed`` in 3D, alternating sign in 2D
    (single strands: always the first perpendicular, positive)."""
    plan = _perturbation_plan(network, seed)
    pattern = perturbation_pattern(jnp.asarray(network.positions), plan, network.probe_direction, network.n_nodes)
    return float(magnitude) * np.asarray(pattern)


def default_perturbation(EI, lengths, strands) -> jax.Array:
    """The default lateral force (pN): 1e-4 EI/L² per strand (mean EI, L the longest
    strand's contour length); differentiable in ``EI`` [S] and ``lengths`` [S]."""
    L = jnp.max(jnp.stack([jnp.sum(jnp.asarray(lengths)[s]) for s in strands]))
    return 1e-4 * jnp.mean(jnp.asarray(EI)) / L**2
