"""3D contact (socbjax.Contact on spatial networks): an interior point force carried exactly in
the log-chart quintic, against an independent 3D shooting solution across the force jump
(socbjax.testing.rod_on_sphere), also between two crossing filaments; the planar problem in
any plane equals the 2D solution; the twisting rod equals the torsion-free one (a point force
carries no twist); derivatives against finite differences; and an outcrop pressed between
the probe face and the substrate."""

import numpy as np
import pytest

import jax
import socbjax as sj
from socbjax.testing import rod_on_sphere

D, R = 0.01, 0.5  # filament diameter and sphere radius (µm)
TIP = np.array([0.0, -3.0, 1.0])  # pN: presses the cantilever onto the sphere and sideways
CENTER = np.array([0.6, -0.12 - R, 0.0])  # µm: the sphere touches y = −0.12 below x = 0.6


def _contact(center=CENTER, **kw):
    return sj.Contact(diameter=D, obstacles=(sj.Sphere(center, R),), self_contact=False, surfaces=False, **kw)


def _solve(n_segments=4, load=TIP, center=CENTER, direction=None, GJ=None, EI=1.0, **kw):
    net = sj.cantilever(n_segments + 1, dim=3, direction=direction, GJ=GJ, EI=EI)
    return sj.solve(net, forces={-1: load}, contact=_contact(center, **kw))


def _loaded_slot(sol):
    slots = np.asarray(sol.state.contacts)[:, 0]
    j = int(np.argmax(np.linalg.norm(slots[:, 1:4], axis=1)))
    return j, slots[j]


@pytest.fixture(scope="module")
def exact():
    sol = _solve(4)
    j, slot = _loaded_slot(sol)
    m0 = np.asarray(sol.moments)[0]
    ref = rod_on_sphere(TIP, CENTER, R, D, _contact().law(1.0), [m0[1], m0[2], (j + slot[0]) / 4, *slot[1:4]])
    return sol, ref


@pytest.mark.slow  # about 75 s (the 3D shooting reference and two 3D contact models compile)
def test_off_plane_contact_matches_3d_shooting(exact):
    sol, ref = exact
    j, slot = _loaded_slot(sol)
    assert 0.05 < (ref["contact_s"] * 4) % 1 < 0.95  # inside a segment
    assert abs(ref["force"][2]) > 0.5  # the contact force leaves the load plane: a 3D contact
    assert np.abs(np.asarray(sol.positions[-1]) - ref["tip"]).max() < 1e-6
    assert abs((j + slot[0]) / 4 - ref["contact_s"]) < 1e-6
    np.testing.assert_allclose(slot[1:4], ref["force"], atol=1e-5)
    # global balance: clamp reaction + tip load + contact force = 0
    np.testing.assert_allclose(np.asarray(sol.reactions[0]) + TIP + slot[1:4], 0.0, atol=1e-8)


@pytest.mark.slow
def test_node_lumped_3d_contact_is_much_worse_and_twist_changes_nothing(exact):
    _, ref = exact
    lumped = np.abs(np.asarray(_solve(4, lumped=True).positions[-1]) - ref["tip"]).max()
    assert lumped > 1e-4 and lumped > 1e3 * np.abs(np.asarray(exact[0].positions[-1]) - ref["tip"]).max()
    # a point force carries no twisting moment: the Kirchhoff rod (GJ) is the torsion-free one
    twisting = _solve(4, GJ=0.7)
    assert np.abs(np.asarray(twisting.positions[-1]) - ref["tip"]).max() < 1e-6


def test_a_planar_contact_problem_in_any_plane_is_the_2d_solution():
    load2, center2 = TIP[:2], CENTER[:2]
    planar = sj.solve(sj.cantilever(5, dim=2), forces={-1: load2},
                      contact=sj.Contact(diameter=D, obstacles=(sj.Sphere(center2, R),), self_contact=False,
                                         surfaces=False))
    rotation = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0]
    lift = lambda v: rotation @ np.append(v, 0.0)  # noqa: E731
    sol = _solve(4, load=lift(load2), center=lift(center2), direction=rotation[:, 0])
    back = np.asarray(sol.positions) @ rotation  # into the planar frame
    np.testing.assert_allclose(back[:, :2], np.asarray(planar.positions), atol=1e-9)
    np.testing.assert_allclose(back[:, 2], 0.0, atol=1e-9)


@pytest.mark.slow
def test_3d_contact_gradient_matches_finite_differences():
    def tip_height(ei):
        return _solve(4, EI=ei).positions[-1, 2]

    g = float(jax.grad(tip_height)(1.0))
    h = 1e-5
    fd = (float(tip_height(1.0 + h)) - float(tip_height(1.0 - h))) / (2 * h)
    assert abs(g) > 1e-3
    assert abs(g - fd) < 1e-6 * max(1.0, abs(fd))


def _crossing(n=4, EI_rod=1e8):
    """A cantilever along x (clamped at the origin, n segments, L = 1) above a much stiffer
    clamped–free rod crossing it along ``LINE`` through ``CROSS``: (network, tip node)."""
    xs = np.linspace(0.0, 1.0, n + 1)
    positions = np.concatenate([np.stack([xs, 0 * xs, 0 * xs], 1), CROSS + (xs - 0.5)[:, None] * LINE])
    tangents = np.concatenate([np.tile([1.0, 0.0, 0.0], (n + 1, 1)), np.tile(LINE, (n + 1, 1))])
    segments = [[i, i + 1] for i in range(n)] + [[n + 1 + i, n + 2 + i] for i in range(n)]
    fixed = [np.eye(3)] + [np.zeros((0, 3))] * n + [np.eye(3)] + [np.zeros((0, 3))] * n
    clamped = np.zeros(2 * n + 2, bool)
    clamped[[0, n + 1]] = True
    net = sj.make_network(positions, tangents, segments, 1.0 / n, [1.0] * n + [EI_rod] * n, fixed_directions=fixed,
                          clamped=clamped)
    return net, n


LINE = np.array([0.3, 0.0, 1.0]) / np.linalg.norm([0.3, 0.0, 1.0])  # the crossing rod's axis, oblique
CROSS = np.array([0.6, -0.12 - D, 0.0])  # µm: a point of that axis, D below the cantilever's touch height


@pytest.mark.slow
def test_crossing_filaments_in_3d_match_a_rod_pressed_onto_a_line():
    """3D filament–filament contact (pair slots in each segment's log chart) against an
    independent shooting solution: a cantilever pressed by (0, −3, 1) pN onto an oblique,
    10⁸ times stiffer rod is a rod pressed onto a rigid line (socbjax.testing.rod_on_sphere
    with ``line``); the contact force is interior to segments of both filaments.
    Slow: 1–3 min on 2 cores (the dense 3D model with pair slots compiles for long)."""
    net, tip = _crossing()
    contact = sj.Contact(diameter=D, surfaces=False, force_limit=0.1 / D**2)  # the law of EI = 1
    sol = sj.solve(net, forces={tip: TIP}, contact=contact)
    pairs = np.asarray(sol.state.pairs)
    k = int(np.argmax(np.linalg.norm(pairs[:, 4:7], axis=1)))
    i, j, s_i, s_j, F = int(pairs[k, 0]), int(pairs[k, 1]), pairs[k, 2], pairs[k, 3], pairs[k, 4:7]
    assert i < tip <= j and 0.05 < s_i < 0.95 and 0.05 < s_j < 0.95  # inside a segment of each filament
    m0 = np.asarray(sol.moments)[0]
    ref = rod_on_sphere(TIP, CROSS, D / 2, D, contact.law(1.0), [m0[1], m0[2], (i + s_i) / tip, *F], line=LINE)
    assert abs(F[2]) > 0.3 and abs(F @ LINE) < 1e-6 * np.linalg.norm(F)  # out of the load plane, normal to the rod
    assert np.abs(np.asarray(sol.positions[tip]) - ref["tip"]).max() < 1e-6
    assert abs((i + s_i) / tip - ref["contact_s"]) < 1e-6
    np.testing.assert_allclose(F, ref["force"], atol=1e-5)
    # each filament's clamp balances what acts on it: the load and +F, or −F
    np.testing.assert_allclose(np.asarray(sol.reactions[0]) + TIP + F, 0.0, atol=1e-8)
    np.testing.assert_allclose(np.asarray(sol.reactions[tip + 1]) - F, 0.0, atol=1e-8)


@pytest.mark.slow
def test_outcrop_between_probe_and_substrate_stays_out_of_both():
    net = sj.dendritic_outcrop(generations=4, gap=3.0, seed=0)
    contact = sj.Contact(self_contact=False)  # the probe face and the substrate
    res = sj.compress(net, 1.5, unload=True, method="arclength", contact=contact,
                      settings=sj.PathSettings(max_step=0.05, initial_step=0.02))
    assert res.completed and bool(np.all(res.converged))
    assert np.nanmin(res.min_gap) > -0.01 * contact.diameter  # the stated penetration bound
    assert np.max(res.contact_count) >= 1
    assert np.max(res.displacement) == pytest.approx(1.5)


@pytest.mark.slow  # 7 min 40 s on 2 cores (2026-12-06)
def test_a_larger_outcrop_passes_the_corners_where_free_strand_ends_meet_a_surface():
    """The 6-generation outcrop (126 segments): free strand ends reach the substrate at almost
    zero force, where the path turns by ~1 rad over a stretch shorter than any step (see
    docs/equations.md, "Two more defects"); it stopped at u = 1.034 µm before corner steps."""
    net = sj.dendritic_outcrop(generations=6, gap=6.0, seed=0)
    contact = sj.Contact(self_contact=False)
    res = sj.compress(net, 1.5, method="arclength", contact=contact,
                      settings=sj.PathSettings(max_step=0.05, initial_step=0.02))
    assert res.completed and bool(np.all(res.converged))
    assert np.max(res.displacement) == pytest.approx(1.5)
    assert np.nanmin(res.min_gap) > -0.01 * contact.diameter
    assert np.max(res.contact_count) >= 1
