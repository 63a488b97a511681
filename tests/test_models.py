"""Fit models: the traced networks equal the builders' networks at the same values, the
branch angle rebuilds the unit mesh exactly, and stiffness groups cover the segments."""

import jax
import numpy as np
import pytest

import socbjax as sj
from socbjax import ColumnModel, OutcropModel, UnitMeshModel


@pytest.mark.parametrize("dim", [2, 3])
def test_unit_mesh_geometry_at_its_own_angle_equals_the_builder(dim):
    """Also the reference material frames of the 3D (twisting) mesh, which stay unit and ⊥
    the tangents when the branch angle moves."""
    model = UnitMeshModel(dim=dim, branch_angle=70.0)
    traced, built = model.network({"branch_angle": 70.0}), sj.unit_dendritic_mesh(branch_angle=70.0, dim=dim)
    assert traced.twisting == built.twisting == (dim == 3)
    for field in ("positions", "tangents", "lengths", "directors"):
        np.testing.assert_allclose(np.asarray(getattr(traced, field)), np.asarray(getattr(built, field)), atol=1e-12,
                                   err_msg=field)
    moved = model.network({"branch_angle": 55.0})
    if dim == 3:
        g, t = np.asarray(moved.directors), np.asarray(moved.tangents)
        np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(np.sum(g * t, axis=1), 0.0, atol=1e-12)
        other = sj.unit_dendritic_mesh(branch_angle=55.0)  # its daughter's reference frame
        np.testing.assert_allclose(g[-1], np.asarray(other.directors)[-1], atol=1e-12)


def test_a_custom_geometry_keeps_the_twisting_reference_frames_orthonormal():
    """A FitModel whose geometry turns a twisting filament: the reference director turns with
    the tangent by the smallest rotation (the base director e_y is not ⊥ a tangent turned
    toward +y)."""
    import jax.numpy as jnp

    class Turned(sj.FitModel):
        name = "turned"

        def __init__(self):
            self.base = sj.probe_network(sj.cantilever(3, dim=3, GJ=0.5))  # along +x, director e_y
            self.parameters = {"EI": sj.Parameter("EI", 1.0, "pN·µm²", lower=0.0),
                               "angle": sj.Parameter("angle", 0.0, "deg")}
            self.groups = {}

        def geometry(self, values):
            a = jnp.deg2rad(values.get("angle", 0.0))
            t = jnp.array([jnp.cos(a), jnp.sin(a), 0.0])
            s = jnp.array([0.0, 0.5, 1.0])[:, None]
            return s * t, jnp.broadcast_to(t, (3, 3)), self.base.lengths

    net = Turned().network({"angle": 30.0})
    g, t = np.asarray(net.directors), np.asarray(net.tangents)
    np.testing.assert_allclose(np.sum(g * t, axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(g, np.broadcast_to([-0.5, np.sqrt(3) / 2, 0.0], (3, 3)), atol=1e-12)


@pytest.mark.parametrize("angle", [40.0, 55.0, 80.0])
def test_unit_mesh_daughter_grows_straight_to_the_surface_at_any_angle(angle):
    """At angle α the daughter is straight from the mother's middle at α to the mother's axis,
    (L/2)/cos α long, its tip on the surface (z = L): no pre-stress at any angle."""
    model = UnitMeshModel(dim=2, branch_angle=70.0)
    net = model.network({"branch_angle": angle})
    strand = np.asarray(net.strand)
    seg = np.asarray(net.segments)[strand == 1]
    pos, t = np.asarray(net.positions), np.asarray(net.tangents)
    a = np.deg2rad(angle)
    direction = np.array([np.sin(a), np.cos(a)])
    base = pos[seg[0, 0]]
    np.testing.assert_allclose(base, [0.0, 0.5], atol=1e-12)
    for node in seg[:, 1]:
        chord = pos[node] - base
        assert abs(chord[0] * direction[1] - chord[1] * direction[0]) < 1e-12  # on the line
        np.testing.assert_allclose(t[node], direction, atol=1e-12)
    assert float(np.asarray(net.lengths)[strand == 1].sum()) == pytest.approx(0.5 / np.cos(a), rel=1e-12)
    assert pos[seg[-1, 1], 1] == pytest.approx(1.0, abs=1e-12)


def test_branch_angle_derivative_of_the_geometry():
    """d(daughter tip x)/dα = d[(L/2) tan α]/dα = (L/2)/cos²α (hinge slides along the surface)."""
    model = UnitMeshModel(dim=2)
    tip_x = jax.grad(lambda a: model.network({"branch_angle": a}).positions[-1, 0])(60.0)
    assert float(tip_x) == pytest.approx(0.5 / np.cos(np.deg2rad(60.0)) ** 2 * np.pi / 180, rel=1e-12)


def test_stiffness_groups():
    model = UnitMeshModel(dim=2)
    EI = np.asarray(model.stiffness({"EI": 0.1, "EI_daughter": 0.3}))
    strand = np.asarray(model.base.strand)
    assert np.all(EI[strand == 0] == 0.1) and np.all(EI[strand == 1] == 0.3)
    outcrop = OutcropModel(generations=4, gap=3.0, dim=3, seed=0)
    masks = np.array(list(outcrop.groups.values()))
    assert np.all(masks.sum(axis=0) == 1)  # every segment in exactly one branching order
    strand = np.asarray(outcrop.base.strand)
    assert outcrop.groups["EI_gen0"][strand == 0].all() and not outcrop.groups["EI_gen0"][strand != 0].any()
    assert list(outcrop.groups) == [f"EI_gen{k}" for k in range(4)]  # 4 generations: orders 0..3


def test_column_model_and_errors():
    model = ColumnModel(4, supports=("pinned", "pinned"), length=2.0)
    assert model.gap == pytest.approx(2.0)
    assert np.all(np.asarray(model.network({"EI": 0.5}).EI) == 0.5)
    with pytest.raises(ValueError, match="no parameter"):
        model.network({"branch_angle": 50.0})
    with pytest.raises(ValueError, match="unknown model"):
        sj.make_fit_model("cube")
    assert sj.make_fit_model(model) is model


def test_unit_mesh_scales_with_its_mother_length():
    """mother_length sets the size only: segment_length defaults to a quarter of the mother, so
    a 12-µm mesh is the 1-µm mesh magnified 12× (same nodes, every length ×12), and its gap
    (the probe travel to the surface) is the mother's length."""
    small, large = UnitMeshModel(dim=2), UnitMeshModel(dim=2, mother_length=12.0)
    assert large.base.n_segments == small.base.n_segments and large.gap == pytest.approx(12.0)
    for values in ({}, {"branch_angle": 55.0}):
        a, b = small.network(values), large.network(values)
        np.testing.assert_allclose(np.asarray(b.positions), 12.0 * np.asarray(a.positions), atol=1e-12)
        np.testing.assert_allclose(np.asarray(b.lengths), 12.0 * np.asarray(a.lengths), rtol=1e-12)
        np.testing.assert_allclose(np.asarray(b.tangents), np.asarray(a.tangents), atol=1e-12)
    assert UnitMeshModel(dim=2, mother_length=2.0, segment_length=0.25).base.n_segments > small.base.n_segments


def test_size_suggestion_reaches_the_data():
    """size_for(reach): a model size whose typical followable range (0.3 × the mother, 0.35 ×
    the column, whose nodes cross a support plane at 0.39 L) covers the reach, rounded up to
    two significant digits."""
    mesh, col = UnitMeshModel(dim=2), ColumnModel(3)
    assert (mesh.size_option, col.size_option) == ("mother_length", "length")
    for reach in (0.05, 0.889, 3.365, 40.0):
        size = mesh.size_for(reach)
        assert 0.3 * size >= reach and 0.3 * size < 1.1 * reach
        assert 0.35 * col.size_for(reach) >= reach
    assert mesh.size_for(3.365) == 12.0 and mesh.size_for(0.889) == 3.0
    assert OutcropModel(generations=2, gap=3.0, dim=3).size_for(1.0) is None


def test_unknown_model_options_are_listed():
    with pytest.raises(ValueError, match=r"unknown option\(s\) 'mother' for the unit-mesh model; it takes .*mother_length"):
        sj.make_fit_model("unit-mesh", mother=2.0)
    with pytest.raises(ValueError, match=r"'n'.* it takes n_nodes, length, supports, dim"):
        sj.make_fit_model("column", n=3)
