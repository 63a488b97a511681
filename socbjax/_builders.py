"""Builders of single-filament networks: :func:`cantilever` and :func:`column`.

Arguments are validated here, before anything is traced: every error names the offending
argument and what would fix it.  The continuous values (``length``, ``EI``, ``origin``) may
be JAX tracers (inside ``jax.jit``, ``jax.grad``, ``jax.vmap``); ``n_nodes``, ``supports``,
``dim`` and ``direction`` fix the topology and must be concrete.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from ._checks import (
    check_array,
    check_choice,
    check_dim,
    check_int,
    check_positive_array,
    check_real,
    check_size,
    check_vector,
    describe,
)
from ._network import Network, is_traced, make_network

__all__ = ["SUPPORTS", "cantilever", "column"]

SUPPORTS = ("clamped", "pinned", "free")


def _check_direction(direction, dim: int) -> np.ndarray:
    if direction is None:
        return np.eye(dim)[0]
    d = check_vector("direction", direction, dim, nonzero=True)
    return d / np.linalg.norm(d)


def _check_origin(origin, dim: int):
    if origin is None:
        return np.zeros(dim)
    o = check_array("origin", origin, "µm").ravel()
    if o.shape != (dim,):
        raise ValueError(f"origin must have {dim} components for dim={dim} (µm), got shape {o.shape}")
    return o


def _check_supports(supports) -> tuple[str, str]:
    if isinstance(supports, str) or not isinstance(supports, Sequence) or len(supports) != 2:
        raise TypeError(f"supports must be a pair (first, last), e.g. ('clamped', 'free'), got {describe(supports)}")
    first, last = (check_choice(f"supports[{k}]", name, SUPPORTS) for k, name in enumerate(supports))
    if first == "free":
        raise ValueError(
            "supports[0] = 'free' leaves the column without an axial reaction (a mechanism); "
            "use 'clamped' or 'pinned' for the first node"
        )
    if (first, last) == ("pinned", "free"):
        raise ValueError(
            "supports ('pinned', 'free') is a mechanism (rigid rotation about the pin); "
            "clamp one end or support the last node"
        )
    return first, last


def _chain(n_nodes: int, length, EI, dim: int, direction, origin=None):
    n = check_int("n_nodes", n_nodes, minimum=2, maximum=None, hint=" (a filament needs at least 2 nodes, one segment)")
    check_size("n_nodes", n_nodes, n - 1, fix="use fewer nodes")
    dim = check_dim(dim)
    L = check_real("length", length, "µm", low=0.0)
    EI_arr = check_positive_array("EI", EI, "pN·µm²")
    if EI_arr.ndim > 1 or (EI_arr.ndim == 1 and EI_arr.shape[0] != n - 1):
        raise ValueError(f"EI must be a scalar or have one value per segment ({n - 1}), got shape {EI_arr.shape}")
    axis = _check_direction(_concrete("direction", direction), dim)
    origin = _check_origin(origin, dim)
    xp = jnp if is_traced(L, origin) else np
    s = xp.linspace(0.0, 1.0, n) * L
    positions = origin[None, :] + s[:, None] * axis[None, :]
    tangents = np.tile(axis, (n, 1))
    segments = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    return n, L, EI_arr, axis, positions, tangents, segments


def _concrete(name: str, value):
    if is_traced(value):
        raise TypeError(f"{name} sets the supports (topology) and must be concrete, not a traced JAX value")
    return value


def cantilever(
    n_nodes: int, *, length: float = 1.0, EI: float = 1.0, dim: int = 3, direction=None, origin=None, GJ=None
) -> Network:
    """A straight filament from the origin along ``direction``: node 0 clamped, last node free.

    Parameters
    ----------
    n_nodes : number of nodes, an integer from 2 to 200,001 (at most 200,000 segments,
        ``socbjax._checks.MAX_SEGMENTS``); segments are equal, ``length / (n_nodes − 1)`` µm.
    length : contour length (µm), finite and positive.
    EI : bending stiffness (pN·µm²), finite and positive, scalar or one value per segment.
    dim : the integer 2 (planar) or 3 (spatial); floats such as ``2.0`` are refused.
    direction : non-zero vector of the filament axis (normalised if not unit); default +x.
    origin : position of the clamped node 0 (µm); default the origin.
    GJ : torsional stiffness (pN·µm²), scalar or per segment: in 3D a Kirchhoff rod with
        twist whose clamp fixes the whole frame (see :func:`socbjax.make_network`); None
        (default): the torsion-free rod.

    Bad arguments raise ``TypeError`` (wrong type: a float or boolean count, a string) or
    ``ValueError`` (NaN, infinite, non-positive, too many nodes) naming the argument.
    """
    return column(
        n_nodes, length=length, EI=EI, supports=("clamped", "free"), dim=dim, direction=direction, origin=origin, GJ=GJ
    )


def column(
    n_nodes: int,
    *,
    length: float = 1.0,
    EI: float = 1.0,
    supports: Sequence[str] = ("clamped", "free"),
    dim: int = 3,
    direction=None,
    origin=None,
    GJ=None,
) -> Network:
    """A straight column from the origin along ``direction`` with end ``supports``.

    ``supports`` = (first node, last node), each ``"clamped"``, ``"pinned"`` or ``"free"``.
    The first node's position is fixed by "clamped"/"pinned".  The last node is always free
    to move along the axis (the axial load goes there); "clamped" or "pinned" at the last
    node fix its lateral position, "clamped" also its tangent.  Classic cases and their
    Euler loads (EI/L²): ("clamped", "free") π²/4, ("pinned", "pinned") π²,
    ("clamped", "pinned") 20.19, ("clamped", "clamped") 4π².  ``origin``: position of
    node 0 (µm), default the origin.  ``GJ`` (pN·µm²) as for :func:`cantilever`; a clamped
    end then fixes the frame, other ends leave the twist free.  Other arguments (and their limits) as for
    :func:`cantilever`.  ``supports`` must be a pair of those strings (``TypeError``
    otherwise); an unknown name or a mechanism is a ``ValueError``.
    """
    first, last = _check_supports(supports)
    n, L, EI_arr, axis, positions, tangents, segments = _chain(n_nodes, length, EI, dim, direction, origin)
    lateral = np.linalg.qr(np.concatenate([axis[:, None], np.eye(dim)], axis=1))[0][:, 1:dim].T
    fixed = [np.zeros((0, dim)) for _ in range(n)]
    fixed[0] = np.eye(dim)
    if last in ("clamped", "pinned"):
        fixed[-1] = lateral
    clamped = np.zeros(n, bool)
    clamped[0] = first == "clamped"
    clamped[-1] = last == "clamped"
    return make_network(
        positions,
        tangents,
        segments,
        (jnp if is_traced(L) else np).full(n - 1, 1.0) * (L / (n - 1)),
        EI_arr,
        fixed_directions=fixed,
        clamped=clamped,
        GJ=GJ,
    )

