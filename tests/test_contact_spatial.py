"""3D contact (socbjax.Contact on spatial networks): an interior point force carried exactly in
the log-chart quintic, against an independent 3D shooting solution across the force jump
(socbjax.testing.rod_on_sphere); the planar problem in any plane equals the 2D solution; the
twisting rod equals the torsion-free one (a point force carries no twist); derivatives against
finite differences; and an outcrop pressed between the probe face and the substrate."""

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
