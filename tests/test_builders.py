"""Builders and bad input: every error names the problem."""

import numpy as np
import pytest

import socbjax as sj


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"n_nodes": 1}, "at least 2 nodes"),
        ({"n_nodes": 4, "length": 0.0}, "length must be positive"),
        ({"n_nodes": 4, "length": -1.0}, "length must be positive"),
        ({"n_nodes": 4, "EI": 0.0}, "EI must be positive"),
        ({"n_nodes": 4, "EI": float("nan")}, "EI must be finite"),
        ({"n_nodes": 4, "length": float("inf")}, "length must be finite"),
        ({"n_nodes": 4, "direction": (0, 0, 0)}, "non-zero"),
        ({"n_nodes": 4, "direction": (1, float("nan"), 0)}, "direction must be finite"),
        ({"n_nodes": 4, "direction": (1, 0)}, "3 components"),
        ({"n_nodes": 4, "dim": 4}, "dim must be 2 or 3"),
        ({"n_nodes": 4, "EI": [1.0, 2.0]}, "one value per segment"),
    ],
)
def test_cantilever_rejects_bad_input(kwargs, match):
    n = kwargs.pop("n_nodes")
    with pytest.raises(ValueError, match=match):
        sj.cantilever(n, **kwargs)


def test_n_nodes_must_be_integer():
    with pytest.raises(TypeError, match="integer"):
        sj.cantilever(3.5)


@pytest.mark.parametrize(
    "supports, match",
    [
        (("clamped", "glued"), r"supports\[1\] must be one of .*got 'glued'"),
        (("free", "clamped"), "mechanism"),
        (("pinned", "free"), "mechanism"),
    ],
)
def test_column_rejects_bad_supports(supports, match):
    with pytest.raises(ValueError, match=match):
        sj.column(4, supports=supports)


@pytest.mark.parametrize("supports", ["clamped", None, ("clamped",), ("clamped", "free", "free"), ("clamped", 3)])
def test_column_supports_must_be_a_pair_of_names(supports):
    with pytest.raises(TypeError, match="supports"):
        sj.column(4, supports=supports)


def test_cantilever_geometry_and_supports():
    net = sj.cantilever(5, length=2.0, EI=0.071, dim=3, direction=(0, 0, 3))
    np.testing.assert_allclose(net.positions[-1], [0, 0, 2.0])
    np.testing.assert_allclose(net.tangents, np.tile([0, 0, 1.0], (5, 1)))
    np.testing.assert_allclose(net.lengths, 0.5)
    np.testing.assert_allclose(net.EI, 0.071)
    assert net.segments.shape == (4, 2) and net.dim == 3
    assert bool(net.clamped[0]) and not bool(net.clamped[-1])
    np.testing.assert_allclose(net.position_projector[0], np.eye(3))
    np.testing.assert_allclose(net.position_projector[-1], 0.0)


def test_column_last_node_slides_along_axis_only():
    net = sj.column(4, supports=("pinned", "pinned"), dim=3, direction=(1, 1, 0))
    a = np.array([1, 1, 0]) / np.sqrt(2)
    P = np.asarray(net.position_projector[-1])
    np.testing.assert_allclose(P @ a, 0.0, atol=1e-14)
    np.testing.assert_allclose(P, np.eye(3) - np.outer(a, a), atol=1e-14)
    assert bool(net.moment_free[0]) and bool(net.moment_free[-1])


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("supports", [("clamped", "free"), ("pinned", "pinned"), ("clamped", "clamped"), ("clamped", "pinned"), ("pinned", "clamped")])
def test_systems_are_square(dim, supports):
    """Unknowns and equations balance for every support pair (the count in docs/equations.md)."""
    import jax

    for model in sj.MODELS:
        disc = sj.make_model(sj.column(4, supports=supports, dim=dim), model)
        state = disc.initial_state()
        x = jax.flatten_util.ravel_pytree(state)[0]
        r = disc.residual(state, sj.Control.make(), disc.frames(state))
        assert r.shape == x.shape
        np.testing.assert_allclose(r, 0.0, atol=1e-14)  # the unloaded straight state is exact
