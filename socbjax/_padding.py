"""Padding dendritic outcrops to one common topology: :func:`pad_outcrop`.

Random outcrops (:func:`socbjax.dendritic_outcrop`) of different seeds have different
topologies (which strands reach the surface, in how many segments), and every topology is a
compiled program of its own.  Padding embeds each realisation in the *universal tree* of its
growth rules, whose topology depends only on the number of generations G, the segments per
generation's growth P and the dimension:

* generation 1 grows the mother (strand 0) by P segments from the probe node 0;
* in every later generation every strand sends out one daughter from its current tip, then
  every strand grows by P segments — the real rule, except that no strand ever stops;
* so there are 2^(G−1) strands and P (2^G − 1) segments (G = 6, P = 2: 126).

A realisation occupies the first segments of the strands it has.  What it does not have is
*inert*: the tail that continues a strand beyond its pinned end on the surface, and the
daughters (with their subtrees) that a strand stopped at the surface never sends out.
Inert pieces carry no load and end free, so their force and moment vanish identically and
the realisation's equilibrium is unchanged (a pinned end becomes an interior pinned node
whose moment the free tail keeps at zero, as the hinge did).  Which nodes are pinned is a
value of the padded network (:class:`socbjax.Padding`), so realisations of any seed are one
batch of one topology: ``jax.vmap`` of one compiled program.  Inert nodes are marked
``active = 0`` and ignored by the surface checks (a tail points through the surface).

A realisation fits the tree when every strand grows P segments per generation until it
reaches the surface and reaches it within its generation's P slots; the growth rule
guarantees the first, and the second fails only when the last growth needs more than P
pieces (e.g. growth 1 µm, segment 0.3 µm: P = 3, but up to 4 pieces reach the surface),
which :func:`pad_outcrop` refuses with a ``ValueError`` (:class:`socbjax.LawnModel` then
solves that realisation in its own topology).

Curved (e.g. :func:`socbjax.thermal_network`) and twisting (``GJ=``) outcrops pad the same
way: real segments keep their natural curvature, torsional stiffness and reference frames;
an inert tail continues straight from its strand's last real node, in that node's tangent
and frame, so it is stress-free as built.

Units: µm, pN (the padded network keeps the realisation's values).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ._checks import check_int
from ._network import Network, Padding, is_traced, make_network
from ._network_checks import default_directors
from ._probe import end_nodes

__all__ = ["pad_outcrop", "universal_strands"]

_INERT_ANGLE = np.radians(45.0)  # any angle in (0°, 180°) works: inert daughters carry nothing


def universal_strands(generations: int) -> list[tuple[int, int]]:
    """(parent strand, birth generation) of every strand of the universal tree, in creation
    order (strand 0: the mother, parent −1, born in generation 1)."""
    strands = [(-1, 1)]
    for g in range(2, generations + 1):
        strands += [(s, g) for s in range(len(strands))]
    return strands


def _chains(net: Network):
    """Per real strand: (base node, chain nodes after the base) in growth order."""
    seg, strand = np.asarray(net.segments), np.asarray(net.strand)
    out = []
    for k in range(int(strand.max()) + 1):
        idx = np.sort(np.flatnonzero(strand == k))
        out.append((int(seg[idx[0], 0]), seg[idx, 1].astype(int)))
    return out


def _real_to_universal(net: Network, generations: int, pieces: int, strands) -> tuple[list[int], list]:
    """Universal strand id of every real strand (genealogy and birth generation), or
    ValueError when a realisation does not fit the tree."""
    chains = _chains(net)
    attach = np.asarray(net.attach)
    position = {}  # real node -> (real strand, slot on its chain)
    for k, (_, nodes) in enumerate(chains):
        for j, n in enumerate(nodes, start=1):
            position[int(n)] = (k, j)
    lookup = {key: u for u, key in enumerate(strands)}
    birth, uid = [1], [0]
    for k, (base, nodes) in enumerate(chains):
        if k:
            mother, slot = position[int(attach[base])]
            if slot % pieces:
                raise ValueError(f"strand {k} branches off after {slot} segments of its mother, not a whole number of "
                                 f"generations of {pieces}")
            birth.append(birth[mother] + slot // pieces)
            if (uid[mother], birth[k]) not in lookup:
                raise ValueError(f"strand {k} is born in generation {birth[k]}, beyond generations={generations}; "
                                 "pad with the outcrop's own number of generations")
            uid.append(lookup[(uid[mother], birth[k])])
        capacity = (generations - birth[k] + 1) * pieces
        if len(nodes) > capacity:
            raise ValueError(f"strand {k} has {len(nodes)} segments, more than the {capacity} of its place in the "
                             f"universal tree ({generations} generations of {pieces} segments): generations must be the "
                             "outcrop's own, pieces the segments of one generation's growth, and the strand's last "
                             "growth (onto the surface) must need no more")
    return uid, chains


def _lateral(t: np.ndarray) -> np.ndarray:
    if t.shape[0] == 2:
        return np.array([-t[1], t[0]])
    e = np.cross(t, [1.0, 0.0, 0.0])
    if np.linalg.norm(e) < 1e-6:
        e = np.cross(t, [0.0, 1.0, 0.0])
    return e / np.linalg.norm(e)


def pad_outcrop(network: Network, generations: int, *, pieces: int = 2) -> tuple[Network, np.ndarray]:
    """Embed a dendritic outcrop in the universal tree of ``generations`` generations of
    ``pieces`` segments each (see the module docstring).

    Returns ``(padded, nodes)``: the padded network (same values on the realisation's
    nodes and segments, inert padding elsewhere, :class:`socbjax.Padding` with its pins and
    active nodes) and ``nodes`` [N_real] int, the padded index of every real node.  Padded
    networks of the same ``generations``, ``pieces`` and dimension share one topology.
    ``ValueError`` when the outcrop does not fit (more generations, or a strand whose last
    growth needs more than ``pieces`` segments)."""
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network (a dendritic_outcrop), got {type(network).__name__}")
    generations = check_int("generations", generations, minimum=1, maximum=12)
    pieces = check_int("pieces", pieces, minimum=1, maximum=16)
    strands = universal_strands(generations)
    uid, chains = _real_to_universal(network, generations, pieces, strands)
    if is_traced(network.positions) or is_traced(network.natural_curvature) or is_traced(network.directors):
        raise TypeError("pad_outcrop needs a concrete network (its shape decides the padding); call it outside "
                        "jax transformations")
    pos, tan, lengths, dirs = (np.asarray(a, float) for a in (network.positions, network.tangents, network.lengths,
                                                               network.directors))
    ell = float(np.median(lengths))
    real_segment = {int(b): s for s, (a, b) in enumerate(np.asarray(network.segments))}  # by its end node
    real_of = {u: k for k, u in enumerate(uid)}
    P = _Pieces(pos[0], tan[0], dirs[0])
    nodes = np.full(network.n_nodes, -1)
    nodes[0] = 0
    chain_nodes = []  # universal strand -> its padded nodes (base first)
    for u, (parent, born) in enumerate(strands):
        k = real_of.get(u)
        base = 0
        if u:
            at = chain_nodes[parent][(born - strands[parent][1]) * pieces]
            if k is not None:
                t, director = tan[chains[k][0]], dirs[chains[k][0]]
                nodes[chains[k][0]] = len(P.pos)
            else:
                tm = P.tan[at]
                t = np.cos(_INERT_ANGLE) * tm + np.sin(_INERT_ANGLE) * _lateral(tm)
                director = default_directors(t[None])[0] if t.shape[0] == 3 else dirs[0]
            base = P.node(P.pos[at], t, director)
            P.attach.append((at, base))
        chain = [base]
        real = chains[k][1] if k is not None else np.zeros(0, int)
        for j in range((generations - born + 1) * pieces):
            if j < len(real):
                s = real_segment[int(real[j])]
                nodes[real[j]] = i = P.node(pos[real[j]], tan[real[j]], dirs[real[j]])
                P.segment(chain[-1], i, lengths[s], u, s)
            else:  # inert: straight on from the chain's last node, in its frame (stress-free)
                end = chain[-1]
                i = P.node(P.pos[end] + ell * P.tan[end], P.tan[end], P.dir[end])
                P.segment(end, i, ell, u, -1)
            chain.append(i)
        chain_nodes.append(chain)
    if np.any(nodes < 0):
        raise ValueError("the outcrop has nodes outside its strands' chains; it is not a dendritic_outcrop")
    return _assemble(network, nodes, P), nodes


class _Pieces:
    """The padded network's nodes (position, tangent, reference director) and segments (ends,
    length, universal strand, real segment index or −1 for inert ones), in creation order."""

    def __init__(self, position, tangent, director):
        self.pos, self.tan, self.dir = [position], [tangent], [director]
        self.seg, self.len, self.strand, self.source, self.attach = [], [], [], [], []

    def node(self, position, tangent, director) -> int:
        self.pos.append(position)
        self.tan.append(tangent)
        self.dir.append(director)
        return len(self.pos) - 1

    def segment(self, a, b, length, strand, source) -> None:
        self.seg.append((a, b))
        self.len.append(length)
        self.strand.append(strand)
        self.source.append(source)


def _assemble(network, nodes, P: _Pieces) -> Network:
    """The padded network: the real values on real nodes and segments (EI, GJ, natural
    curvature, loads, couples), inert ones elsewhere (mean EI and GJ, naturally straight)."""
    d, n = network.dim, len(P.pos)
    fixed = [np.zeros((0, d)) for _ in range(n)]
    fixed[0] = np.eye(d)
    clamped = np.zeros(n, bool)
    clamped[0] = True
    source = np.array(P.source)
    real = source >= 0

    def per_segment(values, inert):
        out = np.full((len(source),) + np.shape(values)[1:], inert, float)
        out[real] = np.asarray(values)[source[real]]
        return out

    EI = per_segment(network.EI, float(np.mean(np.asarray(network.EI))))
    GJ = per_segment(network.GJ, float(np.mean(np.asarray(network.GJ)))) if network.twisting else None
    net = make_network(np.array(P.pos), np.array(P.tan), np.array(P.seg), np.array(P.len), EI,
                       fixed_directions=fixed, clamped=clamped, attach=P.attach, probe=[0],
                       probe_direction=np.asarray(network.probe_direction), strand=np.array(P.strand),
                       natural_curvature=per_segment(network.natural_curvature, 0.0), GJ=GJ,
                       directors=np.array(P.dir) if network.twisting else None)
    projector = np.array(net.position_projector)
    for i in end_nodes(network):
        projector[nodes[i]] = np.eye(d)
    active = np.zeros(n)
    active[nodes] = 1.0
    loads = np.zeros((n, d))
    loads[nodes] = np.asarray(network.loads)
    couples = np.zeros((n,) if d == 2 else (n, 3))
    couples[nodes] = np.asarray(network.couples)
    net = net.replace(loads=loads, couples=couples)
    return Network(positions=net.positions, tangents=net.tangents, lengths=net.lengths, EI=net.EI, loads=net.loads,
                   couples=net.couples, natural_curvature=net.natural_curvature, GJ=net.GJ, directors=net.directors,
                   topology=net.topology,
                   padding=Padding(projector=jnp.asarray(projector), active=jnp.asarray(active)))
