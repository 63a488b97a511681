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

from ._network import Network, is_traced, make_network

__all__ = ["cantilever", "column", "SUPPORTS"]

SUPPORTS = ("clamped", "pinned", "free")


def _check_positive(name: str, value, unit: str):
    """``value`` as a float64 array; concrete values must be finite and positive (traced
    values are kept as they are: they cannot be checked before tracing)."""
    if is_traced(value):
        return jnp.asarray(value, jnp.float64)
    arr = np.asarray(value, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if np.any(arr <= 0):
        raise ValueError(f"{name} must be positive ({unit}), got {value!r}")
    return arr


def _check_n_nodes(n_nodes) -> int:
    if isinstance(n_nodes, bool) or not isinstance(n_nodes, (int, np.integer)):
        raise TypeError(f"n_nodes must be an integer, got {n_nodes!r}")
    if n_nodes < 2:
        raise ValueError(f"a filament needs at least 2 nodes (one segment), got n_nodes={n_nodes}")
    return int(n_nodes)


def _check_direction(direction, dim: int) -> np.ndarray:
    if dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3, got {dim!r}")
    if direction is None:
        return np.eye(dim)[0]
    d = np.asarray(direction, dtype=np.float64).ravel()
    if d.shape != (dim,):
        raise ValueError(f"direction must have {dim} components for dim={dim}, got shape {d.shape}")
    if not np.all(np.isfinite(d)):
        raise ValueError(f"direction must be finite, got {direction!r}")
    norm = np.linalg.norm(d)
    if norm < 1e-12:
        raise ValueError("direction must be a non-zero vector (it is normalised to unit length)")
    return d / norm


def _check_origin(origin, dim: int):
    if origin is None:
        return np.zeros(dim)
    if is_traced(origin):
        o = jnp.asarray(origin, jnp.float64).ravel()
    else:
        o = np.asarray(origin, dtype=np.float64).ravel()
        if not np.all(np.isfinite(o)):
            raise ValueError(f"origin must be finite, got {origin!r}")
    if o.shape != (dim,):
        raise ValueError(f"origin must have {dim} components for dim={dim}, got shape {o.shape}")
    return o


def _chain(n_nodes: int, length, EI, dim: int, direction, origin=None):
    n = _check_n_nodes(n_nodes)
    L = _check_positive("length", length, "µm")
    if np.ndim(L) != 0:
        raise ValueError(f"length must be a scalar (µm), got shape {np.shape(L)}")
    EI_arr = _check_positive("EI", EI, "pN·µm²")
    if EI_arr.ndim > 1 or (EI_arr.ndim == 1 and EI_arr.shape[0] != n - 1):
        raise ValueError(f"EI must be a scalar or have one value per segment ({n - 1}), got shape {EI_arr.shape}")
    axis = _check_direction(_concrete("direction", direction), dim)
    xp = jnp if is_traced(L, origin) else np
    s = xp.linspace(0.0, 1.0, n) * L
    positions = _check_origin(origin, dim)[None, :] + s[:, None] * axis[None, :]
    tangents = np.tile(axis, (n, 1))
    segments = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    return n, L, EI_arr, axis, positions, tangents, segments


def _concrete(name: str, value):
    if is_traced(value):
        raise TypeError(f"{name} sets the supports (topology) and must be concrete, not a traced JAX value")
    return value


def cantilever(
    n_nodes: int, *, length: float = 1.0, EI: float = 1.0, dim: int = 3, direction=None, origin=None
) -> Network:
    """A straight filament from the origin along ``direction``: node 0 clamped, last node free.

    Parameters
    ----------
    n_nodes : number of nodes (≥ 2); segments are equal, ``length / (n_nodes − 1)`` µm.
    length : contour length (µm).
    EI : bending stiffness (pN·µm²), scalar or one value per segment.
    dim : 2 (planar) or 3 (spatial).
    direction : unit vector of the filament axis (normalised if not unit); default +x.
    origin : position of the clamped node 0 (µm); default the origin.
    """
    return column(
        n_nodes, length=length, EI=EI, supports=("clamped", "free"), dim=dim, direction=direction, origin=origin
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
) -> Network:
    """A straight column from the origin along ``direction`` with end ``supports``.

    ``supports`` = (first node, last node), each ``"clamped"``, ``"pinned"`` or ``"free"``.
    The first node's position is fixed by "clamped"/"pinned".  The last node is always free
    to move along the axis (the axial load goes there); "clamped" or "pinned" at the last
    node fix its lateral position, "clamped" also its tangent.  Classic cases and their
    Euler loads (EI/L²): ("clamped", "free") π²/4, ("pinned", "pinned") π²,
    ("clamped", "pinned") 20.19, ("clamped", "clamped") 4π².  ``origin``: position of
    node 0 (µm), default the origin.  Other arguments as for :func:`cantilever`.
    """
    n, L, EI_arr, axis, positions, tangents, segments = _chain(n_nodes, length, EI, dim, direction, origin)
    if isinstance(supports, str) or len(supports) != 2:
        raise ValueError(f"supports must be a pair (first, last), e.g. ('clamped', 'free'), got {supports!r}")
    first, last = supports
    for name in (first, last):
        if name not in SUPPORTS:
            raise ValueError(f"unknown support {name!r}; use one of {SUPPORTS}")
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
    )

