"""Displacement-controlled compression (paper Fig. 5d): a single column against the exact
elastica through and past buckling, load–unload reversibility, the two path-following
methods, checkpoint/resume and input errors."""

import numpy as np
import pytest

import socbjax as sj
from socbjax import testing as _reference


def _loading(result):
    mask = (result.phase == 1) & (result.displacement > 0.02 * result.displacement.max())
    return result.displacement[mask], result.force[mask]


def _pinned_pinned_force(shortening, L=1.0, EI=1.0):
    """Closed-form elastica (first mode): Δ/L = 2(1 − E(k)/K(k)), P = 4 K(k)² EI/L²."""
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipk

    out = []
    for d in np.atleast_1d(shortening):
        m = brentq(lambda m: 2 * (1 - ellipe(m) / ellipk(m)) - d / L, 1e-14, 0.999)
        out.append(4 * ellipk(m) ** 2 * EI / L**2)
    return np.asarray(out)


# Classical reductions of the first-mode elastica to the pinned–pinned one (same P):
# clamped–free (frictionless push on the free end) is half of a pinned–pinned column of 2L;
# clamped–clamped is two pinned–pinned half-waves of L/2 between its inflection points.
_EQUIVALENT_PINNED = {("pinned", "pinned"): 1.0, ("clamped", "free"): 2.0, ("clamped", "clamped"): 0.5}


@pytest.mark.parametrize(
    ("supports", "dim", "nodes"),
    [(("pinned", "pinned"), 2, 5), (("clamped", "free"), 2, 5), pytest.param(("clamped", "clamped"), 3, 7, marks=pytest.mark.slow)],
)
def test_column_force_follows_the_elastica_past_buckling(supports, dim, nodes):
    """Fig. 5d under displacement control: probe force vs end shortening equals the exact
    elastica (elliptic integrals) from buckling to 30 % shortening."""
    L, EI = 1.0, 0.071
    result = sj.compress(sj.column(nodes, supports=supports, dim=dim, length=L, EI=EI), 0.3)
    assert result.completed and result.converged.all() and result.stable.all()
    u, F = _loading(result)
    k = _EQUIVALENT_PINNED[supports]
    exact = _pinned_pinned_force(k * u, L=k * L, EI=EI)
    np.testing.assert_allclose(F, exact, rtol=5e-4)
    assert F[-1] > F[0]  # stable, rising post-buckling branch


@pytest.mark.parametrize("supports", [("clamped", "pinned"), ("pinned", "clamped")])
def test_clamped_pinned_column_matches_the_shooting_elastica(supports):
    """No closed form past buckling: compare with the independent diffrax shooting solver,
    through the force maximum at ~45 % shortening and the drop after it.  Both are contact-free:
    past u ≈ 0.39 the column bulges through its supports' plane, which compress flags."""
    result = sj.compress(sj.column(9, supports=supports, dim=2), 0.7, method="arclength", throw=False)
    assert result.result == sj.RESULTS.surface_crossed and len(result.force) > 20
    u, F = _loading(result)
    exact = _reference.elastica_column_force(u, supports=supports)
    np.testing.assert_allclose(F, exact, rtol=2e-3, atol=1e-3 * exact.max())
    onset = result.force[(result.phase == 1) & (result.displacement > 1e-5)][0]  # past the imperfection
    assert onset == pytest.approx(20.1907, rel=3e-3)  # tan x = x
    assert any(p.kind == "force_maximum" for p in result.limit_points)


def test_arclength_starts_on_the_buckled_branch_of_a_near_straight_column():
    """A straight column under the probe is a near-bifurcation: its path rises almost vertically
    in force at fixed geometry, where the arclength hyperplane (blind to forces) holds the
    unbuckled branch at every force.  The first step once landed there at 26.6 pN (Euler load
    4π²EI/L² = 2.8 pN), every step reported stable; it must follow the exact elastica."""
    L, EI = 1.0, 0.071
    result = sj.compress(sj.column(5, supports=("clamped", "clamped"), dim=2, length=L, EI=EI), 0.3, method="arclength")
    assert result.completed and result.stable.all()
    u, F = _loading(result)
    np.testing.assert_allclose(F, _pinned_pinned_force(0.5 * u, L=0.5 * L, EI=EI), rtol=1e-3)


def test_unloading_retraces_loading_and_methods_agree():
    net = sj.column(5, supports=("pinned", "pinned"), dim=2)
    disp = sj.compress(net, 0.25, unload=True)
    arc = sj.compress(net, 0.25, unload=True, method="arclength")
    for result in (disp, arc):
        assert result.completed and (result.phase == 2).sum() > 5
        far = result.displacement > 0.01
        exact = _pinned_pinned_force(result.displacement[far])
        np.testing.assert_allclose(result.force[far], exact, rtol=2e-4)  # loading and unloading
        assert result.displacement[-1] < 1e-4 * 0.25 + 1e-9  # withdrawn to (almost) the start
    # Same request twice: the same curve, bit for bit.
    again = sj.compress(net, 0.25, unload=True)
    np.testing.assert_array_equal(again.force, disp.force)


def test_probe_force_balances_the_support_reactions():
    result = sj.compress(sj.column(5, supports=("clamped", "pinned"), dim=2), 0.2)
    # Axial equilibrium of the whole column: probe force = force on the far end (node 0).
    np.testing.assert_allclose(result.end_forces[:, 0], result.force, rtol=1e-8, atol=1e-10)


def test_checkpoint_resume_gives_the_same_curve(tmp_path):
    net = sj.column(5, supports=("pinned", "pinned"), dim=2)
    reference = sj.compress(net, 0.25, unload=True)
    ckpt = tmp_path / "run.ckpt.h5"
    calls = []

    def interrupt(phase, u, steps, done):  # the public progress hook, called between chunks
        calls.append((phase, steps))
        if len(calls) == 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        sj.compress(net, 0.25, unload=True, checkpoint=sj.Checkpoint(ckpt, every=3), progress=interrupt)
    assert ckpt.exists() and calls[-1][1] >= 3
    resumed = sj.compress(net, 0.25, unload=True, checkpoint=sj.Checkpoint(ckpt, every=3, resume=True))
    np.testing.assert_array_equal(resumed.displacement, reference.displacement)
    np.testing.assert_array_equal(resumed.force, reference.force)
    with pytest.raises(ValueError, match="different run"):
        sj.compress(net, 0.2, unload=True, checkpoint=sj.Checkpoint(ckpt, resume=True))
    # a checkpoint of an earlier version, without the step-size memory of the path state,
    # resumes as well; its later steps may differ, not its equilibria (the force at the
    # deepest point and at the end of the withdrawal)
    ckpt.unlink()
    with pytest.raises(KeyboardInterrupt):
        calls.clear()
        sj.compress(net, 0.25, unload=True, checkpoint=sj.Checkpoint(ckpt, every=3), progress=interrupt)
    arrays, meta = sj.load_checkpoint(ckpt)
    later = ("carry/.recover", "carry/.streak")
    assert set(later) <= set(arrays)
    sj.save_checkpoint(ckpt, {k: v for k, v in arrays.items() if k not in later}, meta)
    older = sj.compress(net, 0.25, unload=True, checkpoint=sj.Checkpoint(ckpt, every=3, resume=True))
    assert older.completed
    deepest = lambda r: float(np.asarray(r.force)[np.argmax(np.asarray(r.displacement))])  # noqa: E731
    assert deepest(older) == pytest.approx(deepest(reference), rel=1e-8)
    assert float(older.force[-1]) == pytest.approx(float(reference.force[-1]), rel=1e-8, abs=1e-12)


def test_compress_input_errors():
    net = sj.column(4, supports=("pinned", "pinned"), dim=2, length=1.0)
    with pytest.raises(ValueError, match="gap"):
        sj.compress(net, 1.5)
    with pytest.raises(ValueError, match="positive"):
        sj.compress(net, -0.1)
    with pytest.raises(ValueError, match="every"):
        sj.compress(net, 0.1, checkpoint=sj.Checkpoint("run.h5", every=0))
    with pytest.raises(ValueError, match="method"):
        sj.compress(net, 0.1, method="newton")
    with pytest.raises(TypeError, match="Network"):
        sj.compress("column", 0.1)


def test_unit_mesh_buckles_collapses_and_recovers():
    """Fig. 6b: with the daughter hinged on the surface the mesh buckles at a higher force
    than the bare clamped–pinned mother, the force then drops sharply, and withdrawing the
    probe retraces the loading curve (a reversible collapse)."""
    mesh = sj.unit_dendritic_mesh(dim=2)
    result = sj.compress(mesh, 0.35, unload=True, method="arclength")  # the mother crosses the surface at u ≈ 0.40 µm
    assert result.completed and result.converged.all() and result.stable.all()
    # the branch that displacement control follows (the path does not depend on its
    # parametrisation): the arclength path's first step once landed on another, peaking at 199 pN
    peak = sj.compress(mesh, 0.05, throw=False).force.max()
    assert result.force.max() == pytest.approx(peak, rel=1e-3)  # the largest recorded step of each
    bare_mother = 20.1907 * 0.071 / 1.0**2  # clamped–pinned Euler load of the 1 µm mother
    load = result.phase == 1
    u, F = result.displacement[load], result.force[load]
    assert F.max() > 2.0 * bare_mother
    assert any(p.kind == "force_maximum" and p.phase == "loading" for p in result.limit_points)
    assert F[np.argmin(np.abs(u - 0.15))] < 0.6 * F.max()  # the collapse
    back = result.phase == 2
    order = np.argsort(result.displacement[back])
    window = (u > 0.1) & (u < 0.33)
    F_back = np.interp(u[window], result.displacement[back][order], result.force[back][order])
    np.testing.assert_allclose(F_back, F[window], rtol=1e-2)


@pytest.mark.slow  # suite time; in the default suite: sparse = dense solves and Newton: tests/test_linear.py
def test_outcrop_sparse_and_dense_paths_agree_and_balance():
    net = sj.dendritic_outcrop(generations=5, gap=3.0, dim=2, seed=2)
    assert len(np.asarray(net.position_projector)) == net.n_nodes
    dense = sj.compress(net, 0.5, method="arclength", settings=sj.PathSettings(linear_solver="dense"))
    sparse = sj.compress(net, 0.5, method="arclength", settings=sj.PathSettings(linear_solver="sparse"))
    assert dense.completed and sparse.completed and dense.n_steps == sparse.n_steps
    np.testing.assert_allclose(sparse.force, dense.force, rtol=1e-8, atol=1e-12)
    np.testing.assert_array_equal(sparse.stable, dense.stable)
    # Global axial equilibrium: probe force = strand-end forces − loads along the axis.
    axis = np.asarray(net.probe_direction)
    applied = float(np.asarray(net.loads).sum(axis=0) @ axis)
    np.testing.assert_allclose(dense.force, dense.end_forces.sum(axis=1) - applied, atol=1e-9)
    assert dense.end_forces.shape[1] >= 3


@pytest.mark.slow
def test_unit_mesh_in_3d_equals_the_planar_mesh():
    """With the same in-plane perturbation the 3D mesh follows the planar curve (with a
    random, out-of-plane perturbation it buckles out of the branch plane, at lower force)."""
    mesh2, mesh3 = sj.unit_dendritic_mesh(dim=2), sj.unit_dendritic_mesh(dim=3)
    loads2 = np.asarray(sj.strand_perturbation(mesh2, 1e-4))
    loads3 = np.zeros((mesh3.n_nodes, 3))
    loads3[:, [0, 2]] = loads2  # planar (x, y) -> spatial (x, z)
    mesh3 = mesh3.replace(loads=loads3)
    planar = sj.compress(mesh2, 0.4, method="arclength", perturbation=1e-4)
    spatial = sj.compress(mesh3, 0.4, method="arclength")
    assert spatial.completed
    u = planar.displacement[(planar.phase == 1) & (planar.displacement > 0.1)]
    F2 = np.interp(u, planar.displacement[planar.phase == 1], planar.force[planar.phase == 1])
    F3 = np.interp(u, spatial.displacement[spatial.phase == 1], spatial.force[spatial.phase == 1])
    np.testing.assert_allclose(F3, F2, rtol=2e-3)
    np.testing.assert_allclose(spatial.positions[-1][:, 1], 0.0, atol=1e-7)  # stays in its plane


def test_any_step_is_a_solution_with_its_smooth_curve():
    """result.solution(i): the step as a Solution, its smooth curve through the step's nodes
    and its support reactions balancing the probe force along the axis."""
    result = sj.compress(sj.column(5, supports=("pinned", "pinned"), dim=2), 0.2)
    k = result.n_steps - 1
    sol = result.solution(k)
    assert bool(sol.converged)
    curve = sol.curve(12)
    rows = (result.positions[k], result.tangents[k], result.moments[k], result.segment_forces[k])
    np.testing.assert_allclose(np.asarray(sj.filament_curve(result.network, *rows, points_per_segment=12).positions),
                               np.asarray(curve.positions), rtol=0, atol=1e-14)  # the same curve from the recorded rows
    np.testing.assert_allclose(np.asarray(curve.positions[:, 0]), np.asarray(result.positions[k][:-1]), atol=1e-14)
    np.testing.assert_allclose(np.asarray(curve.positions[:, -1]), np.asarray(result.positions[k][1:]), atol=1e-8)
    axis = np.asarray(result.network.probe_direction)
    probe = np.flatnonzero(result.network.probe)[0]
    assert float(np.asarray(sol.reactions[probe]) @ axis) == pytest.approx(float(result.force[k]), rel=1e-10)
    # pinned–pinned: the buckled column's lateral deflection follows the elastica's own shape
    shape = _reference.elastica_column_shape(float(result.displacement[k]), supports=("pinned", "pinned"))
    assert float(sol.max_deflection()) == pytest.approx(float(np.max(np.abs(np.asarray(shape.positions)[:, 1]))), rel=2e-3)


def _heights(result):
    """Node heights along the probe direction from the probe's start (µm), and the surface
    height: the farthest support opposite the probe (recomputed here from the geometry)."""
    net = result.network
    d = np.asarray(net.probe_direction)
    origin = np.asarray(net.positions)[net.probe].mean(axis=0)
    h = (np.asarray(result.positions) - origin) @ d
    supports = (np.einsum("nii->n", np.asarray(net.position_projector)) > 0.5) & ~net.probe
    return h, float(((np.asarray(net.positions)[supports] - origin) @ d).max())


def test_crossing_the_surface_is_a_flagged_status_not_success():
    """A pinned–pinned column pushed past u/L = 1 − (2E(m)/K(m) − 1) = 0.543 (m = ½: the
    elastica's end tangents turn beyond 90°) bulges through the planes of its supports:
    without a contact model that is reported (RESULTS.surface_crossed, an event at the first
    such step), never 'completed'."""
    net = sj.column(5, supports=("pinned", "pinned"), dim=2)
    result = sj.compress(net, 0.8, throw=False)
    assert result.result == sj.RESULTS.surface_crossed and not result.completed
    (event,) = [p for p in result.limit_points if p.kind == "surface_crossing"]
    h, surface = _heights(result)
    beyond = (h.max(axis=1) > surface + 1e-9) | ((h - result.displacement[:, None]).min(axis=1) < -1e-9)
    assert event.step == int(np.argmax(beyond)) and beyond[event.step] and not beyond[: event.step].any()
    assert 0.543 <= event.displacement < 0.8
    assert "first crossing" in result.summary()
    with pytest.raises(sj.ConvergenceError, match="crossed the surface"):
        sj.compress(net, 0.8)
    assert sj.compress(net, 0.5).completed  # below the crossing: success


@pytest.mark.slow
def test_sampled_compressions_flag_surface_crossing_too():
    net = sj.column(5, supports=("pinned", "pinned"), dim=2)
    result = sj.compress(net, 0.8, at=[0.3, 0.7], throw=False)
    assert result.converged.all() and result.result == sj.RESULTS.surface_crossed
    with pytest.raises(sj.ConvergenceError, match="surface"):
        sj.compress(net, 0.8, at=[0.3, 0.7])
