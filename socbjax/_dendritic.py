"""Dendritic actin builders: :func:`unit_dendritic_mesh` (paper Fig. 6a) and
:func:`dendritic_outcrop` (Fig. 7a).  Units µm, pN; EI in pN·µm² (actin ≈ 0.071,
persistence length ≈ 17 µm).

Geometry: the probe holds the nucleation point at the origin (node 0: clamped, position
fixed, probe node); filaments grow along +z (+y in 2D), the last coordinate axis, toward the
opposing surface at z = gap, where a filament that reaches it stops and is hinged (position
fixed, moment free).  The probe moves along +z when compressing.

Reading of the paper where it is ambiguous (documented choices):

* Branch angle: the captions of Figs 6 and 7 say 20°, the text 70° (the Arp2/3 angle); the
  default is 70° and ``branch_angle`` sets it.
* Where daughters start: every generation, each filament that has not stopped sends out one
  daughter *from its current tip node*; the filament then keeps growing, so the branch point
  becomes an interior node of the mother (which stays materially continuous through it).
  Filaments stopped at the surface no longer branch.
* Growth: after branching, every filament that has not stopped (old and new) grows by
  ``growth`` µm in straight segments of ``segment_length``.  A filament that would cross the
  surface is cut exactly at it (one that would end within ¼ ``segment_length`` of the surface
  is grown onto it at once); a last piece shorter than ¼ ``segment_length`` is merged into
  the previous segment, so no segment is shorter than ¼ or longer than 1¼ ``segment_length``
  (except a daughter born within ¼ segment of the surface).  Generation 1 grows the first mother only.
* Daughters with a non-positive component along +z (heading back toward the probe) are
  redrawn with a new random azimuth (3D) or the other side (2D).
* Perturbation: a lateral force (pN) on the middle node of every strand, perpendicular to it,
  random direction from ``seed`` (:func:`socbjax.strand_perturbation`), stored as the
  network's ``loads``.
"""

from __future__ import annotations

import numbers

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._network import Network, make_network

__all__ = ["unit_dendritic_mesh", "dendritic_outcrop"]


def _positive(name, value, unit):
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not np.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a positive number ({unit}), got {value!r}")
    return float(value)


def _angle(branch_angle):
    if isinstance(branch_angle, bool) or not isinstance(branch_angle, numbers.Real) or not 0 < branch_angle < 180:
        raise ValueError(f"branch_angle must be in (0, 180) degrees, got {branch_angle!r}")
    return np.deg2rad(float(branch_angle))


def _dim(dim):
    if dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3, got {dim!r}")
    return dim


class _Grower:
    """Accumulates nodes, segments, junctions and supports of a growing network."""

    def __init__(self, dim):
        self.dim, self.pos, self.tan, self.segs, self.lengths = dim, [], [], [], []
        self.strand, self.attach, self.pinned = [], [], []

    def node(self, position, tangent):
        self.pos.append(np.asarray(position, float))
        self.tan.append(np.asarray(tangent, float))
        return len(self.pos) - 1

    def grow(self, tip, direction, lengths, strand):
        for length in lengths:
            new = self.node(self.pos[tip] + length * direction, direction)
            self.segs.append((tip, new))
            self.lengths.append(length)
            self.strand.append(strand)
            tip = new
        return tip

    def build(self, EI, perturbation, seed) -> Network:
        from ._perturbation import strand_perturbation

        n, d = len(self.pos), self.dim
        fixed = [np.zeros((0, d)) for _ in range(n)]
        for i in [0, *self.pinned]:
            fixed[i] = np.eye(d)
        clamped = np.zeros(n, bool)
        clamped[0] = True
        net = make_network(
            np.array(self.pos), np.array(self.tan), np.array(self.segs), np.array(self.lengths), EI,
            fixed_directions=fixed, clamped=clamped, attach=self.attach or None, probe=[0],
            probe_direction=np.eye(d)[-1], strand=np.array(self.strand),
        )
        if perturbation:
            net = eqx.tree_at(lambda m: m.loads, net, jnp.asarray(strand_perturbation(net, perturbation, seed=seed)))
        return net


def _pieces(length, segment_length):
    """Segment lengths covering ``length``: equal ``segment_length`` pieces, the last one
    shorter, merged into its neighbour when below ¼ segment_length."""
    count = max(int(np.ceil(length / segment_length - 1e-9)), 1)
    pieces = [segment_length] * (count - 1) + [length - segment_length * (count - 1)]
    if len(pieces) > 1 and pieces[-1] < 0.25 * segment_length:
        last = pieces.pop()
        pieces[-1] += last
    return pieces


def _rotate_away(direction, angle, rng, dim, max_redraws):
    """A unit vector at ``angle`` to ``direction`` with random azimuth, with positive last
    component (redrawn otherwise)."""
    for _ in range(max_redraws):
        if dim == 2:
            side = rng.choice([-1.0, 1.0])
            normal = side * np.array([-direction[1], direction[0]])
        else:
            basis = np.linalg.svd(np.eye(3) - np.outer(direction, direction))[0][:, :2]
            psi = rng.uniform(0.0, 2 * np.pi)
            normal = basis @ np.array([np.cos(psi), np.sin(psi)])
        new = np.cos(angle) * direction + np.sin(angle) * normal
        if new[-1] > 1e-6:
            return new / np.linalg.norm(new)
    raise RuntimeError(
        f"no daughter direction at this branch angle points away from the probe after {max_redraws} draws; "
        "use a smaller branch_angle"
    )


def unit_dendritic_mesh(
    *,
    EI: float = 0.071,
    branch_angle: float = 70.0,
    mother_length: float = 1.0,
    daughter_length: float | None = None,
    segment_length: float = 0.25,
    dim: int = 3,
    perturbation: float = 0.0,
) -> Network:
    """Paper Fig. 6a: a mother from the probe-bound nucleation point (node 0, clamped) along
    +z to the surface at z = ``mother_length``, hinged there, and a daughter from the
    mother's middle at ``branch_angle`` degrees in the x–z plane (x–y in 2D).

    "Ends that reach the opposing surface [are] hinged there": by default
    (``daughter_length=None``) the daughter grows until it reaches the surface,
    (mother_length/2)/cos(angle) long — 0.53 µm at the paper caption's 20° (its "0.5 µm
    daughter"), 1.46 µm at 70° — and is hinged there.  A shorter ``daughter_length`` leaves
    its tip free (then the unloaded daughter only rides along: the mesh is the bare mother).
    ``segment_length`` (µm) is the node spacing (the middle must fall on a node).
    ``perturbation`` (pN): lateral force on each strand's middle node (0: none;
    :func:`socbjax.compress` then applies its default).  Deterministic (no randomness).
    """
    dim = _dim(dim)
    EI = _positive("EI", EI, "pN·µm²")
    L, ell = (_positive(n, v, "µm") for n, v in (("mother_length", mother_length), ("segment_length", segment_length)))
    phi = _angle(branch_angle)
    reach = (0.5 * L) / np.cos(phi) if np.cos(phi) > 1e-12 else np.inf
    Ld = reach if daughter_length is None else _positive("daughter_length", daughter_length, "µm")
    if not np.isfinite(Ld):
        raise ValueError("a daughter at branch_angle >= 90° never reaches the surface; give daughter_length")
    half = 0.5 * L / ell
    if abs(half - round(half)) > 1e-9 or round(half) < 1:
        raise ValueError(f"segment_length must divide half the mother ({0.5 * L} µm) into whole segments, got {ell}")
    axis, side = np.eye(dim)[-1], np.eye(dim)[0]
    g = _Grower(dim)
    base = g.node(np.zeros(dim), axis)
    middle = g.grow(base, axis, [ell] * round(half), strand=0)
    top = g.grow(middle, axis, [ell] * round(half), strand=0)
    g.pinned.append(top)
    t_d = np.cos(phi) * axis + np.sin(phi) * side
    length = min(Ld, reach)
    daughter = g.node(g.pos[middle], t_d)
    g.attach.append((middle, daughter))
    tip = g.grow(daughter, t_d, _pieces(length, ell), strand=1)
    if Ld >= reach - 1e-12:
        g.pos[tip][-1] = L  # exactly on the surface
        g.pinned.append(tip)
    return g.build(EI, perturbation, 0)


def _check_outcrop(generations, gap, growth, segment_length, EI, seed, max_redraws, perturbation):
    if isinstance(generations, bool) or not isinstance(generations, numbers.Integral) or generations < 1:
        raise ValueError(f"generations must be a positive integer, got {generations!r}")
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise TypeError(f"seed must be an integer, got {seed!r}")
    if isinstance(max_redraws, bool) or not isinstance(max_redraws, numbers.Integral) or max_redraws < 1:
        raise ValueError(f"max_redraws must be a positive integer, got {max_redraws!r}")
    gap, growth, ell = (_positive(n, v, "µm") for n, v in (("gap", gap), ("growth", growth), ("segment_length", segment_length)))
    if ell > growth:
        raise ValueError(f"segment_length ({ell} µm) must not exceed growth ({growth} µm) per generation")
    if not np.isfinite(perturbation) or perturbation < 0:
        raise ValueError(f"perturbation must be a non-negative force (pN), got {perturbation!r}")
    return gap, growth, ell, _positive("EI", EI, "pN·µm²")


def dendritic_outcrop(
    *,
    generations: int = 8,
    gap: float = 6.0,
    growth: float = 1.0,
    segment_length: float = 0.5,
    branch_angle: float = 70.0,
    EI: float = 0.071,
    seed: int = 0,
    dim: int = 3,
    perturbation: float = 1e-4,
    max_redraws: int = 100,
) -> Network:
    """Paper Fig. 7a: a dendritic actin outcrop grown from one nucleation seed on the probe.

    Parameters (µm, pN·µm², degrees, pN): ``generations`` of branching and growth; ``gap``
    between probe (z = 0) and surface (z = gap); ``growth`` per generation;
    ``segment_length`` node spacing; ``branch_angle`` daughter–mother angle; ``EI``;
    ``seed`` of the azimuths (same seed, same network); ``dim`` 3 or 2; ``perturbation``
    lateral force per strand (default 1e-4 pN, well below thermal forces k_BT/ℓ ≈ 8e-3 pN);
    ``max_redraws`` per daughter.  See the module docstring for the growth rules.
    Strand ends on the surface are the pinned nodes other than the probe node 0.
    """
    dim = _dim(dim)
    gap, growth, ell, EI = _check_outcrop(generations, gap, growth, segment_length, EI, seed, max_redraws, perturbation)
    phi = _angle(branch_angle)
    rng = np.random.default_rng(seed)
    axis = np.eye(dim)[-1]
    g = _Grower(dim)
    strands = [dict(tip=g.node(np.zeros(dim), axis), direction=axis, stopped=False)]
    for generation in range(generations):
        if generation:
            for s in [s for s in strands if not s["stopped"]]:
                t_d = _rotate_away(s["direction"], phi, rng, dim, max_redraws)
                base = g.node(g.pos[s["tip"]], t_d)
                g.attach.append((s["tip"], base))
                strands.append(dict(tip=base, direction=t_d, stopped=False))
        for k, s in enumerate(strands):
            if s["stopped"]:
                continue
            height = g.pos[s["tip"]][-1]
            to_surface = (gap - height) / s["direction"][-1]
            # A filament that would stop within ¼ segment of the surface next time reaches it now
            # (no sliver segments at the surface).
            reaches = to_surface <= growth + 0.25 * ell
            length = to_surface if reaches else growth
            s["tip"] = g.grow(s["tip"], s["direction"], _pieces(length, ell), strand=k)
            if reaches:
                s["stopped"] = True
                g.pos[s["tip"]][-1] = gap  # exactly on the surface
                g.pinned.append(s["tip"])
    return g.build(EI, perturbation, seed)
