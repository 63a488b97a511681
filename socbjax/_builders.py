"""Builders of single-filament networks: :func:`cantilever`, :func:`column`, and the naturally
curved :func:`arc`, :func:`helix` and :func:`crimped_fibre`.

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
from ._curved import ACTIN_GJ, with_natural_curvature
from ._network import Network, is_traced, make_network

__all__ = ["SUPPORTS", "arc", "cantilever", "column", "crimped_fibre", "helix"]

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
    n_nodes: int, *, length: float = 1.0, EI: float = 1.0, dim: int = 3, direction=None, origin=None, GJ=None,
    natural_curvature=None,
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
    natural_curvature : per segment or one for all, the rest shape (see
        :func:`socbjax.with_natural_curvature`: 2D κ₀ in 1/µm, 3D (κ₁, κ₂, τ₀) with ``GJ``);
        the filament is then built in that stress-free shape from node 0 along ``direction``.

    Bad arguments raise ``TypeError`` (wrong type: a float or boolean count, a string) or
    ``ValueError`` (NaN, infinite, non-positive, too many nodes) naming the argument.
    """
    return column(n_nodes, length=length, EI=EI, supports=("clamped", "free"), dim=dim, direction=direction,
                  origin=origin, GJ=GJ, natural_curvature=natural_curvature)


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
    natural_curvature=None,
) -> Network:
    """A straight column from the origin along ``direction`` with end ``supports``.

    ``supports`` = (first node, last node), each ``"clamped"``, ``"pinned"`` or ``"free"``.
    The first node's position is fixed by "clamped"/"pinned".  The last node is always free
    to move along the axis (the axial load goes there); "clamped" or "pinned" at the last
    node fix its lateral position, "clamped" also its tangent.  Classic cases and their
    Euler loads (EI/L²): ("clamped", "free") π²/4, ("pinned", "pinned") π²,
    ("clamped", "pinned") 20.19, ("clamped", "clamped") 4π².  ``origin``: position of
    node 0 (µm), default the origin.  ``GJ`` (pN·µm²) as for :func:`cantilever`; a clamped
    end then fixes the frame, other ends leave the twist free; ``natural_curvature`` as for
    :func:`cantilever`.  Other arguments (and their limits) as for
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
    network = make_network(
        positions,
        tangents,
        segments,
        (jnp if is_traced(L) else np).full(n - 1, 1.0) * (L / (n - 1)),
        EI_arr,
        fixed_directions=fixed,
        clamped=clamped,
        GJ=GJ,
    )
    return network if natural_curvature is None else with_natural_curvature(network, natural_curvature)


def arc(n_nodes: int, *, radius: float, angle: float, EI=0.071, GJ=None, dim: int = 3) -> Network:
    """A naturally curved filament, stress-free as built: a circular arc of ``radius`` (µm)
    turning by ``angle`` (degrees, positive) that starts at the origin along +x and curves
    toward +y in the x–y plane; node 0 clamped, the last node free; equal segments of natural
    curvature 1/radius.  ``EI`` (pN·µm², default actin's 0.071) scalar or per segment.

    ``dim=3`` (default) builds a Kirchhoff rod with twist, ``GJ`` (pN·µm²) defaulting to
    actin's 8e-3 (Tsuda et al. 1996); its material frame at rest is the arc's (no natural
    twist).  ``dim=2``: a planar arc (``GJ`` unused).  Each segment must turn by less than
    180° (``ValueError`` otherwise: use more nodes)."""
    dim = check_dim(dim)
    n = check_int("n_nodes", n_nodes, minimum=2, maximum=None, hint=" (a filament needs at least 2 nodes, one segment)")
    R = check_real("radius", radius, "µm", low=0.0)
    phi = check_real("angle", angle, "degrees", low=0.0)
    if phi / (n - 1) >= 180.0:
        raise ValueError(f"angle = {angle!r}° over {n - 1} segments turns each by {phi / (n - 1):.4g}°; a segment turns "
                         f"by less than 180°: use n_nodes > {int(phi // 180) + 1}")
    if dim == 2:
        return cantilever(n, length=R * np.radians(phi), EI=EI, dim=2, natural_curvature=1.0 / R)
    straight = cantilever(n, length=R * np.radians(phi), EI=EI, dim=3, GJ=ACTIN_GJ if GJ is None else GJ)
    return with_natural_curvature(straight, _components(straight, 0, np.array([0.0, 0.0, 1.0 / R])))


def _components(network: Network, node: int, darboux) -> np.ndarray:
    """(κ₁, κ₂, τ₀): a world Darboux vector on the reference material frame of ``node``."""
    t, d1 = np.asarray(network.tangents[node], float), np.asarray(network.directors[node], float)
    return np.array([darboux @ d1, darboux @ np.cross(t, d1), darboux @ t])


def helix(n_nodes: int, *, radius: float, pitch: float, turns: float, EI=0.071, GJ=None) -> Network:
    """A naturally helical filament, stress-free as built (3D, a Kirchhoff rod with twist):
    the helix of ``radius`` and ``pitch`` (µm per turn, positive: right-handed) about an axis
    parallel to +z, ``turns`` turns long, starting at the origin; node 0 clamped, the last
    node free, equal segments.  Its material frame at rest is the Frenet frame carried from
    node 0, so each segment has the helix's curvature R/(R² + c²) and twist c/(R² + c²)
    (c = pitch/2π).  ``GJ`` defaults to actin's 8e-3 pN·µm², ``EI`` to 0.071."""
    n = check_int("n_nodes", n_nodes, minimum=2, maximum=None, hint=" (a filament needs at least 2 nodes, one segment)")
    R = check_real("radius", radius, "µm", low=0.0)
    c = check_real("pitch", pitch, "µm") / (2 * np.pi)
    N = check_real("turns", turns, "turns", low=0.0)
    speed = np.hypot(R, c)
    length = 2 * np.pi * N * speed
    t0 = np.array([0.0, R, c]) / speed
    binormal = np.cross(t0, [-1.0, 0.0, 0.0])  # the principal normal points to the axis (−x from the start)
    darboux = (c * t0 + R * binormal) / speed**2  # τ t + κ B
    if R / speed**2 * length / (n - 1) >= np.pi:
        raise ValueError(f"turns = {turns!r} over {n - 1} segments bends each by 180° or more: use more nodes")
    straight = cantilever(n, length=length, EI=EI, dim=3, direction=t0, GJ=ACTIN_GJ if GJ is None else GJ)
    return with_natural_curvature(straight, _components(straight, 0, darboux))


def crimped_fibre(n_nodes: int, *, length: float, wavelength: float, crimp_angle: float, EI=0.071,
                  supports=("clamped", "free"), dim: int = 2) -> Network:
    """A crimped (wavy) fibre, stress-free as built: the sine-generated curve whose tangent
    angle is θ(s) = crimp_angle · sin(2π s / wavelength) along the contour s ∈ [0, length]
    (µm), starting at the origin with mean direction +x (the shape of crimped collagen and of
    meanders).  Segment k is the arc that turns from θ(s_k) to θ(s_{k+1}), so the node
    tangents are the curve's own; with a whole number of wavelengths and of segments per
    half wavelength the last node lies on the x axis.

    ``crimp_angle`` in degrees (0 < crimp_angle < 90), ``wavelength`` the contour length of
    one period (µm); ``supports`` as for :func:`socbjax.column` (the supported directions
    keep their orientation: a "pinned" last node slides along x).  Planar only: ``dim=3``
    raises ``NotImplementedError`` (give a twisting 3D network its (κ₁, κ₂, τ₀) per segment
    with :func:`socbjax.with_natural_curvature`)."""
    if check_dim(dim) == 3:
        raise NotImplementedError("crimped_fibre(dim=3): the 3D crimp is not built in; give a twisting 3D network its "
                                  "(κ₁, κ₂, τ₀) per segment with socbjax.with_natural_curvature")
    n = check_int("n_nodes", n_nodes, minimum=2, maximum=None, hint=" (a filament needs at least 2 nodes, one segment)")
    L = check_real("length", length, "µm", low=0.0)
    lam = check_real("wavelength", wavelength, "µm", low=0.0)
    amp = check_real("crimp_angle", crimp_angle, "degrees", low=0.0)
    if amp >= 90.0:
        raise ValueError(f"crimp_angle must be below 90° (the fibre would fold back), got {crimp_angle!r}")
    s = np.linspace(0.0, L, n)
    theta = np.radians(amp) * np.sin(2 * np.pi * s / lam)
    straight = column(n, length=L, EI=EI, supports=supports, dim=2)  # node 0 (the anchor) keeps θ(0) = 0
    return with_natural_curvature(straight, np.diff(theta) / np.diff(s))
