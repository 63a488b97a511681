"""Padding outcrops to one topology (socbjax.pad_outcrop, socbjax.Padding).

The reference is independent of the padding: each realisation compressed in its own
topology by socbjax.compress; the padded network must give the same equilibrium (forces,
positions of the real nodes, surface-crossing status) and realisations of different seeds
must share one topology (one compiled program), the universal tree of P (2^G − 1) segments.
"""

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


def test_padding_changes_nothing_on_the_real_nodes():
    net = sj.dendritic_outcrop(generations=G, gap=3.0, seed=2, dim=2)  # 26 real segments of 30
    padded, nodes = sj.pad_outcrop(net, G)
    assert net.n_segments < padded.n_segments and np.asarray(padded.padding.active).sum() == net.n_nodes
    np.testing.assert_allclose(np.asarray(padded.positions)[nodes], np.asarray(net.positions))
    own = sj.compress(net, 0.35, at=AT, throw=False)
    pad = sj.compress(padded, 0.35, at=AT, throw=False)
    np.testing.assert_allclose(pad.force, own.force, rtol=1e-9)
    np.testing.assert_allclose(pad.positions[:, nodes], own.positions, atol=1e-9)
    assert int(pad.result._value) == int(own.result._value)


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
