"""Padding outcrops to one topology (socbjax.pad_outcrop, socbjax.Padding).

The reference is independent of the padding: each realisation compressed in its own
topology by socbjax.compress; the padded network must give the same equilibrium (forces,
positions of the real nodes, surface-crossing status) and realisations of different seeds
must share one topology (one compiled program), the universal tree of P (2^G − 1) segments.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import socbjax as sj

G = 4
AT = jnp.array([0.1, 0.3])


@pytest.mark.parametrize("gap", [3.0, 3.7])
def test_seeds_share_the_universal_topology(gap):
    padded = [sj.pad_outcrop(sj.dendritic_outcrop(generations=G, gap=gap, seed=s, dim=2), G)[0] for s in range(4)]
    assert len({p.topology for p in padded}) == 1
    assert padded[0].n_segments == 2 * (2**G - 1)
    assert len(sj.universal_strands(G)) == 2 ** (G - 1)


def assert_padding_changes_nothing(net, at, displacement):
    padded, nodes = sj.pad_outcrop(net, G)
    assert net.n_segments < padded.n_segments and np.asarray(padded.padding.active).sum() == net.n_nodes
    np.testing.assert_allclose(np.asarray(padded.positions)[nodes], np.asarray(net.positions))
    own = sj.compress(net, displacement, at=at, throw=False)
    pad = sj.compress(padded, displacement, at=at, throw=False)
    assert own.completed or own.result == sj.RESULTS.surface_crossed
    np.testing.assert_allclose(pad.force, own.force, rtol=1e-9)
    np.testing.assert_allclose(pad.positions[:, nodes], own.positions, atol=1e-9)
    np.testing.assert_allclose(pad.twists[:, nodes] if net.twisting else pad.twists, own.twists, atol=1e-9)
    assert int(pad.result._value) == int(own.result._value)
    return padded, nodes


@pytest.mark.parametrize("thermal", [False, True], ids=["straight", "thermal"])
def test_padding_changes_nothing_on_the_real_nodes(thermal):
    net = sj.dendritic_outcrop(generations=G, gap=3.0, seed=2, dim=2)  # 26 real segments of 30
    if thermal:  # naturally curved real strands; the inert pieces stay straight
        net = sj.thermal_network(net, seed=3)
    padded, nodes = assert_padding_changes_nothing(net, AT, 0.35)
    inert = np.ones(padded.n_segments, bool)
    inert[[list(map(tuple, np.asarray(padded.segments))).index((nodes[a], nodes[b]))
           for a, b in np.asarray(net.segments)]] = False
    assert np.all(np.asarray(padded.natural_curvature)[inert] == 0)
    np.testing.assert_array_equal(np.asarray(padded.natural_curvature)[~inert].sum(), np.asarray(net.natural_curvature).sum())
    with pytest.raises(ValueError, match="shape first"):  # inert pieces must stay straight
        sj.thermal_network(padded, seed=3)


@pytest.mark.slow
def test_padding_carries_twist_and_3d_natural_curvature():
    """A 3D Kirchhoff outcrop (actin GJ) with thermal shapes: the padded network keeps every
    real segment's GJ, rest Darboux vector and reference frame, and its equilibria and frame
    angles are those of the unpadded one."""
    net = sj.thermal_network(sj.dendritic_outcrop(generations=G, gap=3.0, seed=2, dim=3, GJ=sj.ACTIN_GJ), seed=3)
    padded, nodes = assert_padding_changes_nothing(net, jnp.array([0.1]), 0.1)
    assert padded.twisting
    np.testing.assert_allclose(np.asarray(padded.directors)[nodes], np.asarray(net.directors), atol=1e-15)


def test_crossing_status_counts_real_nodes_only():
    """A seed whose own path crosses the surface is flagged the same way when padded, while
    the inert tails (which point through the surface) are never counted."""
    net = sj.dendritic_outcrop(generations=G, gap=3.0, seed=0, dim=2)
    padded, _ = sj.pad_outcrop(net, G)
    own = sj.compress(net, 0.35, at=AT, throw=False)
    pad = sj.compress(padded, 0.35, at=AT, throw=False)
    assert own.result == sj.RESULTS.surface_crossed and pad.result == sj.RESULTS.surface_crossed
    np.testing.assert_allclose(pad.force, own.force, rtol=1e-9)
    untouched = sj.compress(padded, 0.05, at=jnp.array([0.02, 0.05]), throw=False)
    assert untouched.result == sj.RESULTS.successful


def test_lawn_runs_every_seed_in_one_program():
    lawn = sj.LawnModel(probe_area=10.0, generations=G, n_outcrops=4, film_height=3.7, dim=2)
    assert lawn.padded == (0, 1, 2, 3) and lawn.topology_groups == [(0, 1, 2, 3)]
    other = sj.LawnModel(probe_area=10.0, generations=G, n_outcrops=2, film_height=3.7, seed=50, dim=2)
    first = sj.pad_outcrop(lawn.members[0], G)[0]
    assert sj.pad_outcrop(other.members[1], G)[0].topology == first.topology


def test_outcrops_that_do_not_fit_are_refused():
    net = sj.dendritic_outcrop(generations=3, gap=3.0, seed=0, segment_length=0.3, dim=2)  # 3 pieces per growth
    with pytest.raises(ValueError, match="more than the 6 of its place in the universal tree"):
        sj.pad_outcrop(net, 3, pieces=2)
    with pytest.raises(ValueError, match="generations"):
        sj.pad_outcrop(net, 0)
    deep = sj.dendritic_outcrop(generations=4, gap=3.7, seed=1, dim=2)
    with pytest.raises(ValueError, match="generations"):
        sj.pad_outcrop(deep, 2)
    with pytest.raises(TypeError, match="network"):
        sj.pad_outcrop("outcrop", 3)
    with pytest.raises(TypeError, match="concrete"):
        jax.jit(lambda n: sj.pad_outcrop(n, 3)[0])(sj.dendritic_outcrop(generations=3, gap=3.0, dim=2))
