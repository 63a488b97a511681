"""Dendritic builders (paper Figs 6a, 7a): geometry rules, determinism, validation."""

import hashlib
import os
import subprocess
import sys

import numpy as np
import pytest

import socbjax as sj


def _arrays(net):
    return {k: np.asarray(getattr(net, k)) for k in ("positions", "tangents", "segments", "lengths", "attach", "loads")}


def _pinned(net):
    return np.flatnonzero((np.einsum("nii->n", np.asarray(net.position_projector)) > 0.5) & ~np.asarray(net.probe))


@pytest.mark.parametrize("dim", [2, 3])
def test_outcrop_follows_the_growth_rules(dim):
    gap, ell, angle = 6.0, 0.5, 70.0
    net = sj.dendritic_outcrop(generations=8, gap=gap, segment_length=ell, branch_angle=angle, dim=dim, seed=3)
    a = _arrays(net)
    pos, seg, tan = a["positions"], a["segments"], a["tangents"]
    chord = np.linalg.norm(pos[seg[:, 1]] - pos[seg[:, 0]], axis=1)
    np.testing.assert_allclose(chord, a["lengths"], atol=1e-12)  # straight segments
    assert a["lengths"].min() >= 0.25 * ell - 1e-12 and a["lengths"].max() <= 1.25 * ell + 1e-12
    assert pos[:, -1].min() >= -1e-12 and pos[:, -1].max() <= gap + 1e-12
    daughters = np.flatnonzero(a["attach"] != np.arange(net.n_nodes))
    mothers = a["attach"][daughters]
    cosines = np.sum(tan[daughters] * tan[mothers], axis=1)
    np.testing.assert_allclose(np.degrees(np.arccos(cosines)), angle, atol=1e-9)
    assert np.all(tan[:, -1] > 0)  # nothing grows back toward the probe
    np.testing.assert_allclose(pos[daughters], pos[mothers], atol=1e-12)
    ends = _pinned(net)
    np.testing.assert_allclose(pos[ends, -1], gap, atol=1e-12)  # hinged on the surface
    assert not np.asarray(net.clamped)[ends].any() and np.asarray(net.moment_free)[ends].all()
    assert np.asarray(net.probe)[0] and np.asarray(net.clamped)[0]
    assert net.n_junctions == len(np.unique(np.asarray(net.strand))) - 1  # one junction per daughter strand


def test_outcrop_is_deterministic_for_a_seed():
    a, b = _arrays(sj.dendritic_outcrop(seed=7)), _arrays(sj.dendritic_outcrop(seed=7))
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    c = _arrays(sj.dendritic_outcrop(seed=8))
    assert a["positions"].shape != c["positions"].shape or not np.array_equal(a["positions"], c["positions"])


@pytest.mark.parametrize("kernel", ["Prescott", "SkylakeX"])
def test_outcrop_of_a_seed_does_not_depend_on_the_blas_kernel(kernel):
    """The same seed grows the same outcrop under another OpenBLAS kernel (a fresh process with
    OPENBLAS_CORETYPE set): an SVD basis of the daughters' lateral plane gave seed 0 480, 487 or
    491 segments by kernel."""
    digest = "hashlib.sha256(np.ascontiguousarray(n.positions, dtype=np.float64).tobytes()).hexdigest()"
    script = ("import hashlib, numpy as np, socbjax as sj; n = sj.dendritic_outcrop(generations=8, gap=6.0, seed=0); "
              f"print(n.n_segments, {digest})")
    env = {**os.environ, "OPENBLAS_CORETYPE": kernel, "JAX_PLATFORMS": "cpu"}
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300, check=True)
    n = sj.dendritic_outcrop(generations=8, gap=6.0, seed=0)
    here = hashlib.sha256(np.ascontiguousarray(n.positions, dtype=np.float64).tobytes()).hexdigest()
    assert out.stdout.split() == [str(n.n_segments), here]  # the same nodes, bit for bit


def test_default_outcrop_size():
    net = sj.dendritic_outcrop()
    # Reported in the closing note; the paper quotes ~150 µm and ~300 segments.
    assert 300 <= net.n_segments <= 600 and len(_pinned(net)) >= 10
    assert np.abs(np.asarray(net.loads)).sum() > 0  # the default lateral perturbation


def test_unit_mesh_geometry():
    net = sj.unit_dendritic_mesh(dim=2)
    pos, tan = np.asarray(net.positions), np.asarray(net.tangents)
    assert net.n_junctions == 1
    daughter = int(np.flatnonzero(np.asarray(net.attach) != np.arange(net.n_nodes))[0])
    mother = int(np.asarray(net.attach)[daughter])
    np.testing.assert_allclose(pos[mother], [0.0, 0.5])  # the mother's middle
    assert np.degrees(np.arccos(tan[daughter] @ tan[mother])) == pytest.approx(70.0)
    reach = 0.5 / np.cos(np.radians(70.0))  # the daughter grows to the surface by default
    assert np.asarray(net.lengths)[np.asarray(net.strand) == 1].sum() == pytest.approx(reach)
    np.testing.assert_allclose(pos[_pinned(net)], [[0.0, 1.0], [reach * np.sin(np.radians(70.0)), 1.0]])
    short = sj.unit_dendritic_mesh(dim=2, daughter_length=0.5)  # free daughter tip
    assert len(_pinned(short)) == 1


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"generations": -1}, "generations"),
        ({"generations": 0}, "generations"),
        ({"seed": -1}, "seed"),
        ({"branch_angle": 90.0}, "branch_angle"),
        ({"branch_angle": 0.0}, "branch_angle"),
        ({"max_redraws": 0}, "max_redraws"),
        ({"perturbation": float("nan")}, "perturbation"),
        ({"segment_length": 1e-7}, "segment_length"),
        ({"gap": 0.0}, "gap"),
        ({"growth": -1.0}, "growth"),
        ({"segment_length": 2.0}, "segment_length"),
        ({"branch_angle": 190.0}, "branch_angle"),
        ({"EI": 0.0}, "EI"),
        ({"dim": 4}, "dim"),
        ({"perturbation": -1.0}, "perturbation"),
        ({"clearance": -0.007}, "clearance"),
        ({"clearance": float("nan")}, "clearance"),
        ({"clearance": 0.007, "dim": 2}, "clearance=0.007 µm applies to 3D"),
        ({"clearance": 0.5}, "clearance=0.5 µm must be below segment_length"),
        ({"clearance": 0.3, "generations": 6, "max_redraws": 20}, "clearance=0.3 µm: no daughter direction"),
    ],
)
def test_outcrop_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        sj.dendritic_outcrop(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"seed": 1.5}, "seed"),
        ({"seed": True}, "seed"),
        ({"generations": 2.5}, "generations"),
        ({"generations": 3.0}, "generations=3"),
        ({"dim": 3.0}, "dim"),
        ({"gap": "6"}, "gap"),
        ({"EI": None}, "EI"),
    ],
)
def test_outcrop_wrong_types(kwargs, match):
    with pytest.raises(TypeError, match=match):
        sj.dendritic_outcrop(**kwargs)


def test_outcrop_size_guard_stops_the_growth_and_names_generations():
    """Daughters at 89.9° barely climb: without the guard 10⁶ generations would grow forever."""
    with pytest.raises(ValueError, match="generations=1000000 would build .* segments at least, more than the limit of 200,000"):
        sj.dendritic_outcrop(generations=10**6, branch_angle=89.9, gap=50.0, growth=1.0, segment_length=1.0, dim=2)


def test_outcrop_growth_ends_once_every_strand_is_on_the_surface():
    """Later generations change nothing once all strands are hinged: 10⁹ of them are quick."""
    small = sj.dendritic_outcrop(generations=5, gap=2.0, perturbation=0.0)
    huge = sj.dendritic_outcrop(generations=10**9, gap=2.0, perturbation=0.0)
    np.testing.assert_array_equal(np.asarray(small.positions), np.asarray(huge.positions))


def _closest_pieces(net, within):
    """{(i, j): distance} for the segments i < j that share no node (a daughter's base is its
    mother's node) whose centre lines (straight as built) come within ``within`` µm, from
    points sampled every ≤ 0.25 nm on every segment and a k-d tree (not the builder's
    closest-point formula): each distance is within 0.25 nm of the exact one."""
    from scipy.spatial import cKDTree

    pos, seg = np.asarray(net.positions), np.asarray(net.segments)
    nodes = np.asarray(net.attach)[seg]
    n = int(np.ceil(np.asarray(net.lengths).max() / 2.5e-4)) + 1
    w = np.linspace(0.0, 1.0, n)
    points = (pos[seg[:, 0], None] * (1 - w)[:, None] + pos[seg[:, 1], None] * w[:, None]).reshape(-1, 3)
    owner = np.repeat(np.arange(len(seg)), n)
    pairs = cKDTree(points).query_pairs(within, output_type="ndarray")
    i, j = owner[pairs[:, 0]], owner[pairs[:, 1]]
    apart = (i != j) & ~np.any(nodes[i][:, :, None] == nodes[j][:, None, :], axis=(1, 2))
    found = {}
    for a, b, p, q in zip(i[apart], j[apart], *pairs[apart].T):
        key = (min(a, b), max(a, b))
        found[key] = min(found.get(key, np.inf), float(np.linalg.norm(points[p] - points[q])))
    return found


def test_a_clearance_keeps_the_strands_of_the_8_generation_outcrop_apart():
    """As drawn (clearance 0), the 8-generation outcrop of seed 0 has two strands whose centre
    lines pass 1.2 nm apart (segments 162 and 487), less than actin's 7 nm: a self-contact
    run would start in penetration.  With ``clearance=0.007`` no two segments that share no
    node come closer than 7 nm (to the sampling's 0.25 nm), and the growth rules still hold."""
    d = 0.007
    close = _closest_pieces(sj.dendritic_outcrop(generations=8, gap=6.0, seed=0), d)
    assert (162, 487) in close and close[(162, 487)] < 1.5e-3
    net = sj.dendritic_outcrop(generations=8, gap=6.0, seed=0, clearance=d)
    assert not _closest_pieces(net, d - 2.5e-4)
    lengths = np.asarray(net.lengths)
    assert net.n_segments > 400 and lengths.min() >= 0.125 - 1e-12 and lengths.max() <= 0.625 + 1e-12
    pos = np.asarray(net.positions)
    assert pos[:, 2].min() >= -1e-12 and pos[:, 2].max() <= 6.0 + 1e-12
