"""Dendritic actin builders: :func:`unit_dendritic_mesh` (paper Fig. 6a) and
:func:`dendritic_outcrop` (Fig. 7a).  Units µm, pN; EI in pN·µm² (actin ≈ 0.071,
persistence length ≈ 17 µm).  In 3D the filaments are Kirchhoff rods with actin's torsional
stiffness GJ = 8e-3 pN·µm² by default (``socbjax.ACTIN_GJ``); ``GJ=None`` builds the paper's
torsion-free model.

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

import math

import jax.numpy as jnp
import numpy as np

from ._checks import (
    MAX_SEGMENTS,
    MIN_BRANCH_ANGLE,
    check_dim,
    check_int,
    check_real,
    check_size,
)
from ._curved import ACTIN_GJ, with_natural_curvature
from ._network import Network, is_traced, make_network
from ._perturbation import strand_perturbation

__all__ = ["dendritic_outcrop", "unit_dendritic_mesh"]

MAX_REDRAWS = 100_000  # draws per daughter: a bound on the time an impossible branch angle can take


def _length(name, value):
    """A concrete positive length (µm); traced values are refused (they fix the topology)."""
    if is_traced(value):
        raise TypeError(f"{name} fixes the network's topology (number and placement of segments) and must be a "
                        "concrete number, not a traced JAX value; only EI and perturbation may be traced here")
    return check_real(name, value, "µm", low=0.0)


def _angle(branch_angle, *, traced_ok=False, high=180.0, why=""):
    """The branch angle (degrees) in radians, checked to lie in [MIN_BRANCH_ANGLE,
    high − MIN_BRANCH_ANGLE]; a traced angle is passed on when ``traced_ok``."""
    if is_traced(branch_angle):
        if not traced_ok:
            raise TypeError("branch_angle shapes the random growth (which strands reach the surface) and must be "
                            "concrete here; fit it with socbjax.UnitMeshModel")
        return jnp.deg2rad(jnp.asarray(branch_angle, jnp.float64))
    angle = check_real("branch_angle", branch_angle, "degrees")
    lo, hi = MIN_BRANCH_ANGLE, high - MIN_BRANCH_ANGLE
    if not lo <= angle <= hi:
        raise ValueError(f"branch_angle must be in (0°, {high:g}°) exclusive and at least {lo:g}° away from both ends, "
                         f"i.e. in [{lo:g}°, {hi:g}°]; got {angle:g}{why}")
    return np.deg2rad(angle)


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

    def build(self, EI, perturbation, seed, GJ=None, natural_curvature=None) -> Network:
        n, d = len(self.pos), self.dim
        fixed = [np.zeros((0, d)) for _ in range(n)]
        for i in [0, *self.pinned]:
            fixed[i] = np.eye(d)
        clamped = np.zeros(n, bool)
        clamped[0] = True
        net = make_network(
            np.array(self.pos), np.array(self.tan), np.array(self.segs), np.array(self.lengths), EI,
            fixed_directions=fixed, clamped=clamped, attach=self.attach or None, probe=[0],
            probe_direction=np.eye(d)[-1], strand=np.array(self.strand), GJ=GJ,
        )
        return _finish(net if natural_curvature is None else with_natural_curvature(net, natural_curvature),
                       perturbation, seed)


def _finish(net: Network, perturbation, seed) -> Network:
    """The network with the lateral perturbation loads (pN, possibly traced) applied."""
    if is_traced(perturbation) or perturbation:
        return net.replace(loads=strand_perturbation(net, perturbation, seed=seed))
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


def _rotate_away(direction, angle, rng, dim, max_redraws, basis=None):
    """A unit vector at ``angle`` to ``direction`` with random azimuth, with positive last
    component (redrawn otherwise).  ``basis`` [3, 2]: :func:`_lateral_basis` of
    ``direction``, if already known (3D).  Scalar arithmetic and ``math``'s functions only (no
    BLAS, no SIMD-dispatched numpy ufuncs): the same seed grows the same outcrop on every
    machine."""
    c, s = math.cos(angle), math.sin(angle)
    d = [float(x) for x in direction]
    for _ in range(max_redraws):
        if dim == 2:
            side = float(rng.choice([-1.0, 1.0]))
            normal = [-side * d[1], side * d[0]]
        else:
            basis = _lateral_basis(direction) if basis is None else basis
            psi = float(rng.uniform(0.0, 2 * math.pi))
            cp, sp = math.cos(psi), math.sin(psi)
            normal = [float(basis[i, 0]) * cp + float(basis[i, 1]) * sp for i in range(3)]
        new = [c * a + s * b for a, b in zip(d, normal)]
        if new[-1] > 1e-6:
            norm = math.sqrt(sum(x * x for x in new))
            return np.array([x / norm for x in new])
    raise RuntimeError(
        f"no daughter direction at this branch angle points away from the probe after {max_redraws} draws; "
        "use a smaller branch_angle"
    )


def _lateral_basis(direction) -> np.ndarray:
    """[3, 2] orthonormal basis of the plane perpendicular to unit ``direction`` (the same
    for every branching of a strand: computed once per strand), in closed form (Duff et al.,
    J. Comput. Graph. Tech. 6(1), 2017, "Building an orthonormal basis, revisited"): a
    function of the direction alone.  (An SVD basis of the degenerate plane depends on the
    LAPACK kernel: outcrops of the same seed had 480, 487 or 491 segments by machine.)"""
    x, y, z = (float(v) for v in direction)
    sign = math.copysign(1.0, z)
    a = -1.0 / (sign + z)
    b = x * y * a
    return np.array([[1.0 + sign * x * x * a, b], [sign * b, sign + y * y * a], [-sign * x, -y]])


def unit_dendritic_mesh(
    *,
    EI: float = 0.071,
    branch_angle: float = 70.0,
    mother_length: float = 1.0,
    daughter_length: float | None = None,
    segment_length: float = 0.25,
    dim: int = 3,
    perturbation: float = 0.0,
    daughter_segments: int | None = None,
    GJ: float | None = ACTIN_GJ,
    natural_curvature=None,
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
    ``daughter_segments``: split the daughter into this many equal segments (default: pieces
    of ``segment_length``).  ``EI``, ``perturbation`` and ``branch_angle`` may be traced JAX
    values (``branch_angle`` then needs ``daughter_segments``: the count is topology).
    ``GJ`` (pN·µm², default actin's ``socbjax.ACTIN_GJ`` = 8e-3, Tsuda et al. 1996): in 3D
    a Kirchhoff rod with twist, the junction fixing the daughter's whole frame in the
    mother's and in full moment balance (see :func:`socbjax.make_network`); ``GJ=None``: the
    torsion-free model of the paper (no twist unknowns, the daughter's azimuth carried by
    parallel transport; about half the run time, but the junction drops the moment about the
    mother's axis).  Ignored in 2D (planar filaments do not twist).  ``natural_curvature``:
    the strands' rest shape, per segment or one for all
    (:func:`socbjax.with_natural_curvature`; the mesh is built in that shape).

    Limits (checked before anything is built or traced; ``TypeError`` for a wrong type,
    ``ValueError`` for a wrong value, naming the argument): ``EI``, ``mother_length``,
    ``segment_length``, ``daughter_length`` finite and positive; ``perturbation`` finite and
    ≥ 0; ``branch_angle`` in [0.1°, 179.9°] (a daughter parallel or antiparallel to the
    mother overlaps it), below 90° unless ``daughter_length`` or ``daughter_segments`` is
    given; ``dim`` the integer 2 or 3; ``daughter_segments`` an integer ≥ 1; at most 200,000
    segments in all (``socbjax._checks.MAX_SEGMENTS``: e.g. ``branch_angle=89.999999``, whose
    daughter would need 10⁸ segments to reach the surface, is refused).
    """
    dim = check_dim(dim)
    EI = check_real("EI", EI, "pN·µm²", low=0.0)
    perturbation = check_real("perturbation", perturbation, "pN", low=0.0, low_open=False)
    L, ell = _length("mother_length", mother_length), _length("segment_length", segment_length)
    phi = _angle(branch_angle, traced_ok=True)
    half = 0.5 * L / ell
    check_size("segment_length", segment_length, 2 * half, fix="use a larger segment_length or a shorter mother_length")
    if abs(half - round(half)) > 1e-9 or round(half) < 1:
        raise ValueError(f"segment_length must divide half the mother ({0.5 * L} µm) into whole segments, got {ell}")
    pieces, hinged = _daughter_pieces(phi, L, ell, daughter_length, daughter_segments, 2 * round(half))
    m, k = 2 * round(half), len(pieces)
    axis, side = np.eye(dim)[-1], np.eye(dim)[0]
    xp = jnp if is_traced(phi, pieces) else np
    t_d = xp.cos(phi) * axis + xp.sin(phi) * side
    s = xp.concatenate([xp.zeros(1), xp.cumsum(xp.asarray(pieces))])
    daughter = 0.5 * L * axis[None, :] + s[:, None] * t_d[None, :]  # base at the mother's middle node
    if hinged:  # the tip exactly on the surface
        daughter = xp.concatenate([daughter[:-1], xp.concatenate([daughter[-1, :-1], xp.full(1, L)])[None]])
    positions = xp.concatenate([xp.asarray(np.arange(m + 1)[:, None] * ell * axis[None, :]), daughter])
    tangents = xp.concatenate([xp.asarray(np.tile(axis, (m + 1, 1))), xp.broadcast_to(t_d, (k + 1, dim))])
    segments = np.concatenate([np.stack([np.arange(m), np.arange(1, m + 1)], 1),
                               np.stack([np.arange(m + 1, m + 1 + k), np.arange(m + 2, m + 2 + k)], 1)])
    fixed = [np.zeros((0, dim)) for _ in range(m + k + 2)]
    for i in [0, m] + ([m + 1 + k] if hinged else []):
        fixed[i] = np.eye(dim)
    clamped = np.zeros(m + k + 2, bool)
    clamped[0] = True
    net = make_network(positions, tangents, segments, xp.concatenate([xp.full(m, ell), xp.asarray(pieces)]), EI,
                       fixed_directions=fixed, clamped=clamped, attach=[(m // 2, m + 1)], probe=[0],
                       probe_direction=axis, strand=np.repeat([0, 1], [m, k]), GJ=GJ)
    if natural_curvature is not None:
        net = with_natural_curvature(net, natural_curvature)
    return _finish(net, perturbation, 0)


def _daughter_pieces(phi, L, ell, daughter_length, daughter_segments, mother_segments):
    """(segment lengths of the daughter, whether it is hinged on the surface); the size
    guard counts the segments before any list is built."""
    if daughter_segments is not None:
        daughter_segments = check_int("daughter_segments", daughter_segments, minimum=1, maximum=None)
        check_size("daughter_segments", daughter_segments, mother_segments + daughter_segments,
                   fix="use fewer daughter_segments")
    if daughter_length is not None:
        daughter_length = _length("daughter_length", daughter_length)
    if is_traced(phi):
        if daughter_segments is None or daughter_length is not None:
            raise TypeError("a traced branch_angle needs daughter_segments=<int> and daughter_length=None: the daughter "
                            "then grows to the surface in that many segments (the count is topology)")
        return jnp.full(daughter_segments, 0.5 * L / jnp.cos(phi) / daughter_segments), True
    reach = 0.5 * L / np.cos(phi) if np.cos(phi) > 1e-12 else np.inf
    if daughter_length is None:
        if not np.isfinite(reach) or np.cos(phi) <= 0:
            raise ValueError(f"a daughter at branch_angle={np.degrees(phi):g}° (>= 90°) never reaches the surface; "
                             "give daughter_length (µm) or a branch_angle below 90°")
        length, hinged = reach, True
    else:
        length, hinged = min(daughter_length, reach), bool(daughter_length >= reach - 1e-12)
    if daughter_segments is None:
        culprit = ("branch_angle", float(np.degrees(phi))) if daughter_length is None or reach < daughter_length else (
            "daughter_length", daughter_length)
        check_size(*culprit, mother_segments + np.ceil(length / ell), fix=(
            f"the daughter is {length:.4g} µm long (it grows to the surface at z = {L:g} µm unless daughter_length is "
            "shorter); use a smaller branch_angle, a shorter daughter_length, a larger segment_length or "
            "daughter_segments=<int>"))
    return ([length / daughter_segments] * daughter_segments if daughter_segments else _pieces(length, ell)), hinged


def _check_outcrop(generations, gap, growth, segment_length, EI, seed, max_redraws, perturbation):
    generations = check_int("generations", generations, minimum=1, maximum=None)
    check_int("seed", seed, minimum=0, maximum=None, hint=" (numpy's random generator needs a non-negative seed)")
    max_redraws = check_int("max_redraws", max_redraws, minimum=1, maximum=MAX_REDRAWS)
    gap, growth, ell = (_length(n, v) for n, v in (("gap", gap), ("growth", growth), ("segment_length", segment_length)))
    if ell > growth:
        raise ValueError(f"segment_length ({ell} µm) must not exceed growth ({growth} µm) per generation")
    check_size("segment_length", segment_length, np.ceil(growth / ell) + 1,
               fix="use a larger segment_length or a smaller growth per generation")
    EI = check_real("EI", EI, "pN·µm²", low=0.0)
    perturbation = check_real("perturbation", perturbation, "pN", low=0.0, low_open=False)
    return generations, gap, growth, ell, EI, perturbation, max_redraws


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
    GJ: float | None = ACTIN_GJ,
    natural_curvature=None,
    clearance: float = 0.0,
) -> Network:
    """Paper Fig. 7a: a dendritic actin outcrop grown from one nucleation seed on the probe.

    Parameters (µm, pN·µm², degrees, pN): ``generations`` of branching and growth; ``gap``
    between probe (z = 0) and surface (z = gap); ``growth`` per generation;
    ``segment_length`` node spacing; ``branch_angle`` daughter–mother angle; ``EI``;
    ``seed`` of the azimuths (same seed, same network); ``dim`` 3 or 2; ``perturbation``
    lateral force per strand (default 1e-4 pN, well below thermal forces k_BT/ℓ ≈ 8e-3 pN);
    ``max_redraws`` per daughter; ``GJ`` torsional stiffness (pN·µm², default actin's 8e-3;
    None: the paper's torsion-free model; see :func:`unit_dendritic_mesh`);
    ``natural_curvature`` the strands' rest shape (as for :func:`unit_dendritic_mesh`).  See
    the module docstring for the growth rules.  Strand ends on the surface are the pinned
    nodes other than the probe node 0.

    ``clearance`` (µm, 3D): the least distance between the centre lines of two strands, away
    from their shared branch node.  A daughter whose straight path to the surface would pass
    closer than that to another strand's (that strand's path to the surface: strands grow
    straight) is redrawn, within ``max_redraws``; pass the filament diameter (actin: 0.007)
    for runs with self-contact.  The default 0 keeps strands as drawn (and every network the
    same as before the option): two of them may pass closer than a filament diameter (the
    8-generation outcrop, seed 0, has the centre lines of segments 162 and 487 1.2 nm apart),
    and ``compress`` with self-contact (``Contact()``) refuses such a network at its start,
    naming the pair.  A clearance draws more random azimuths, so it grows another network
    from the same seed.  2D strands cross in their plane: ``clearance`` is 3D only.

    Limits (checked before growing; ``TypeError`` for a wrong type, ``ValueError`` for a
    wrong value, naming the argument): ``generations`` an integer ≥ 1; ``gap``, ``growth``,
    ``segment_length`` (≤ ``growth``), ``EI`` finite and positive; ``perturbation`` finite
    and ≥ 0; ``branch_angle`` in [0.1°, 89.9°] (the first daughter of the mother, which grows
    along +z, must head toward the surface); ``seed`` an integer ≥ 0; ``max_redraws`` an
    integer in 1..100,000; ``dim`` the integer 2 or 3; ``clearance`` finite, ≥ 0 and below
    ``segment_length``, 0 in 2D.  At most 200,000 segments
    (``socbjax._checks.MAX_SEGMENTS``): the growth stops with a ``ValueError`` naming
    ``generations`` as soon as it passes the limit (growth ends early, and costs nothing
    more, once every strand has reached the surface).
    """
    dim = check_dim(dim)
    generations, gap, growth, ell, EI, perturbation, max_redraws = _check_outcrop(
        generations, gap, growth, segment_length, EI, seed, max_redraws, perturbation)
    phi = _angle(branch_angle, high=90.0, why=": the first daughter branches off the mother, which grows along +z, and "
                 "must head toward the surface")
    clearance = check_real("clearance", clearance, "µm", low=0.0, low_open=False)
    if clearance and dim == 2:
        raise ValueError(f"clearance={clearance!r} µm applies to 3D outcrops: 2D strands cross each other in their plane; "
                         "use clearance=0 (the default) or dim=3")
    if clearance >= ell:
        raise ValueError(f"clearance={clearance!r} µm must be below segment_length ({ell} µm): a daughter's first segment "
                         "must clear its mother; use the filament diameter (actin: 0.007 µm)")
    g = _grow_outcrop(generations, gap, growth, ell, phi, np.random.default_rng(seed), dim, max_redraws, clearance)
    return g.build(EI, perturbation, seed, GJ, natural_curvature)


def _surface_path(origin, direction, gap):
    """(start, end) of the straight path from ``origin`` along unit ``direction`` to the
    surface (last coordinate ``gap``), as Python floats."""
    start = [float(x) for x in origin]
    reach = (gap - start[-1]) / float(direction[-1])
    return start, [a + reach * float(t) for a, t in zip(start, direction)]


def _segment_distance(p0, p1, q0, q1) -> float:
    """Least distance (µm) between the segments p0–p1 and q0–q1 (3D, exact: the clamped
    closest points of Ericson, Real-Time Collision Detection, §5.1.9), in scalar arithmetic
    (the same decision on every machine, as :func:`_rotate_away`)."""
    dot = lambda a, b: a[0] * b[0] + a[1] * b[1] + a[2] * b[2]  # noqa: E731
    d1, d2 = [b - a for a, b in zip(p0, p1)], [b - a for a, b in zip(q0, q1)]
    r = [a - b for a, b in zip(p0, q0)]
    a, e, f, c = dot(d1, d1), dot(d2, d2), dot(d2, r), dot(d1, r)
    b = dot(d1, d2)
    denom = a * e - b * b
    s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > 1e-18 * a * e else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, min(max(-c / a, 0.0), 1.0)
    elif t > 1.0:
        t, s = 1.0, min(max((b - c) / a, 0.0), 1.0)
    gap = [p + s * u - q - t * v for p, u, q, v in zip(p0, d1, q0, d2)]
    return math.sqrt(dot(gap, gap))


def _clear_daughter(mother, strands, paths, origin, phi, rng, max_redraws, clearance, gap, ell):
    """A daughter direction (as :func:`_rotate_away`) whose straight path to the surface stays
    ``clearance`` µm from every other strand's path; against its mother only beyond its first
    segment (they share the branch node).  ValueError after ``max_redraws`` draws."""
    mother_index = next(k for k, s in enumerate(strands) if s is mother)
    for _ in range(max_redraws):
        t_d = _rotate_away(mother["direction"], phi, rng, 3, max_redraws, mother["basis"])
        start, end = _surface_path(origin, t_d, gap)
        beyond = [a + ell * float(t) for a, t in zip(start, t_d)]
        short = beyond[-1] >= gap  # no second segment: nothing but the shared node near the mother
        if all((short and k == mother_index)
               or _segment_distance(beyond if k == mother_index else start, end, *path) >= clearance
               for k, path in enumerate(paths)):
            return t_d
    raise ValueError(f"clearance={clearance!r} µm: no daughter direction keeps that distance from the other strands "
                     f"after max_redraws={max_redraws} draws (a daughter at {[round(float(x), 3) for x in origin]} µm); use a "
                     "smaller clearance, a larger max_redraws, fewer generations or another seed")


def _future_segments(growing, g, gap, growth, ell, remaining, first) -> int:
    """A lower bound on the segments that the ``growing`` strands and their daughters still
    add in the ``remaining`` generations: a strand whose path to the surface is longer than
    ``growth`` + ¼ ``segment_length`` cannot reach it this generation, so it adds its
    ``growth`` pieces (and, after the first generation, a daughter with at least one
    segment) every generation until it can; granddaughters are not counted."""
    reach = growth + 0.25 * ell
    per_growth = len(_pieces(growth, ell))
    total = 0
    for s in growing:
        to_surface = (gap - g.pos[s["tip"]][-1]) / s["direction"][-1]
        r = min(max(int(np.ceil((to_surface - reach) / growth)) - 1, 0), remaining)  # − 1: round-off margin
        total += r * per_growth + (r < remaining) + max(min(r, remaining - 1) - first, 0)
    return total


def _grow_outcrop(generations, gap, growth, ell, phi, rng, dim, max_redraws, clearance=0.0) -> _Grower:
    """The growth rules of the module docstring, stopped by the size guard; with a
    ``clearance``, daughters redrawn as :func:`_clear_daughter` says."""
    axis = np.eye(dim)[-1]
    g = _Grower(dim)
    strands = [{"tip": g.node(np.zeros(dim), axis), "direction": axis, "stopped": False, "basis": None}]
    paths = [_surface_path(np.zeros(dim), axis, gap)]  # each strand's straight path to the surface
    for generation in range(generations):
        growing = [s for s in strands if not s["stopped"]]
        if not growing:  # every strand has reached the surface: later generations change nothing
            break
        bound = len(g.segs) + _future_segments(growing, g, gap, growth, ell, generations - generation, generation == 0)
        check_size("generations", generations, bound, what="segments at least", fix=(
            f"a lower bound at generation {generation + 1}, from the {len(growing)} strand{'' if len(growing) == 1 else 's'} still below the surface and "
            "their distances to it; use fewer generations, a smaller gap, a smaller branch_angle, or a larger growth "
            "or segment_length"))
        if generation:
            for s in growing:
                if dim == 3 and s["basis"] is None:
                    s["basis"] = _lateral_basis(s["direction"])
                origin = g.pos[s["tip"]]
                if clearance:
                    t_d = _clear_daughter(s, strands, paths, origin, phi, rng, max_redraws, clearance, gap, ell)
                else:
                    t_d = _rotate_away(s["direction"], phi, rng, dim, max_redraws, s["basis"])
                base = g.node(origin, t_d)
                g.attach.append((s["tip"], base))
                strands.append({"tip": base, "direction": t_d, "stopped": False, "basis": None})
                paths.append(_surface_path(origin, t_d, gap))
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
            if len(g.segs) > MAX_SEGMENTS:  # checked per strand: one generation can add many
                check_size("generations", generations, len(g.segs), what="segments at least", fix=(
                    f"the outcrop passed the limit while growing generation {generation + 1} with "
                    f"{sum(not s['stopped'] for s in strands)} strand(s) still below the surface: use fewer generations, "
                    "a smaller gap, or a larger growth or segment_length"))
    return g
