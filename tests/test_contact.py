"""Contact with rigid obstacles (socbjax.Contact, Plane, Sphere): an interior point force
carried exactly (against an independent shooting solution), the channel column against the
elliptic-integral elastica, derivatives against finite differences, and the contract that
contact=None keeps the contact-free model."""

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import ellipe, ellipk

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree
import socbjax as sj
from conftest import two_filaments
from socbjax.testing import clamped_elastica_lobe_gap, elastica_end_shortening, elastica_on_point_obstacle

L, EI, D = 1.0, 1.0, 0.01
TIP = np.array([0.0, -3.0])  # pN, pushes the cantilever onto the obstacle
OBSTACLE = np.array([0.6, -0.12])  # µm, a point obstacle below the cantilever


def _obstacle_contact(**kw):
    return sj.Contact(diameter=D, obstacles=(sj.Sphere(OBSTACLE, 0.0),), self_contact=False, surfaces=False, **kw)


def _solve_on_obstacle(n_segments, EI=EI, **kw):
    net = sj.cantilever(n_segments + 1, length=L, EI=EI, dim=2)
    return sj.solve(net, forces={-1: TIP}, contact=_obstacle_contact(**kw))


def _shooting(guess):
    """Independent reference (socbjax.testing): the elastica integrated across the force jump
    at the contact point, with the same contact law."""
    out = elastica_on_point_obstacle(TIP, OBSTACLE, D, _obstacle_contact().law(EI), guess, length=L, EI=EI)
    return (out["contact_s"], out["force"]), out["tip"]


@pytest.fixture(scope="module")
def reference():
    sol = _solve_on_obstacle(4)
    slots = np.asarray(sol.state.contacts)[:, 0]
    j = int(np.argmax(np.linalg.norm(slots[:, 1:3], axis=1)))
    guess = [float(sol.moments[0]), (j + slots[j, 0]) / 4, np.linalg.norm(slots[j, 1:3]),
             np.arctan2(slots[j, 2], slots[j, 1])]
    return _shooting(guess)


def test_mid_segment_point_force_matches_shooting(reference):
    (sc, lam), tip = reference
    assert 0.05 < (sc * 4) % 1 < 0.95  # the contact lies inside a segment, not at a node
    sol = _solve_on_obstacle(4)
    assert np.abs(np.asarray(sol.positions[-1]) - tip[:2]).max() < 1e-6
    assert abs(float(sol.angles[-1]) - tip[2]) < 1e-6
    slots = np.asarray(sol.state.contacts)[:, 0]
    j = int(np.argmax(np.linalg.norm(slots[:, 1:3], axis=1)))
    assert abs((j + slots[j, 0]) / 4 - sc) < 1e-6
    assert abs(np.linalg.norm(slots[j, 1:3]) - lam) < 1e-6 * lam
    # global balance: clamp reaction + tip load + contact force = 0
    np.testing.assert_allclose(np.asarray(sol.reactions[0]) + TIP + slots[j, 1:3], 0.0, atol=1e-8)


def test_node_lumped_contact_is_much_worse(reference):
    _, tip = reference
    exact = np.abs(np.asarray(_solve_on_obstacle(4).positions[-1]) - tip[:2]).max()
    lumped = np.abs(np.asarray(_solve_on_obstacle(4, lumped=True).positions[-1]) - tip[:2]).max()
    assert lumped > 1e-3 and lumped > 1e4 * exact


def test_contact_gradient_matches_finite_differences():
    def tip_height(ei):
        return _solve_on_obstacle(4, EI=ei).positions[-1, 1]

    g = float(jax.grad(tip_height)(EI))
    h = 1e-5
    fd = (float(tip_height(EI + h)) - float(tip_height(EI - h))) / (2 * h)
    assert abs(g) > 1e-3
    assert abs(g - fd) < 1e-6 * max(1.0, abs(fd))


def test_the_newton_step_limit_stops_a_gap_at_its_stated_depth():
    """SOCBModel.newton_step_limit (IPC's step filter for the penalty): a straight segment
    moved rigidly toward a plane has the same gap at every point, linear along the step, so
    the admitted fraction is analytic: a gap g₀ outside the band may enter it by δ/4, one
    inside may at most double its depth 1 − g/δ (plus ¼), never below 1 % of the step."""
    net = sj.cantilever(2, length=L, EI=EI, dim=2)
    delta = D / 10

    def limit(g0, move):
        wall = sj.Plane([0.0, -(D / 2 + g0)], [0.0, 1.0])
        model = sj.make_model(net, contact=sj.Contact(diameter=D, planes=(wall,), self_contact=False,
                                                      surfaces=False))
        old = model.initial_state()
        new = eqx.tree_at(lambda s: s.positions, old, old.positions.at[:, 1].add(-move))
        return float(model.newton_step_limit(old, new, sj.Control.make(), sj.Control.make()))

    lower = lambda g0: min(2 * g0 - 1.25 * delta, 0.75 * delta)  # noqa: E731
    for g0, move in ((3 * delta, 5 * delta), (0.5 * delta, 1.5 * delta), (0.9 * delta, 0.5 * delta)):
        expected = min(1.0, (g0 - lower(g0)) / move)
        assert abs(limit(g0, move) - expected) < 1e-12, (g0, move)
    assert limit(3 * delta, -5 * delta) == 1.0  # moving away is never limited
    assert limit(3 * delta, 1000 * delta) == 0.01  # the floor


def test_newton_comes_out_of_a_deep_guess_in_a_few_steps():
    """A soft cantilever's free tip pressed lightly onto a wall (equilibrium depth 1 − g/δ of
    about 0.01–0.02), Newton started from the contact-free shape, whose tip lies 0.5 δ or
    3 δ into the band with no contact force: plain Newton on the residual (no line search)
    must land on the law's graph in a few steps.  With the force row F − f(g) it needed 14
    and 17 (the cube of the depth falls by 2/3 per iteration); the row is now linear in the
    gap where the law is stiffer than the structure (docs/equations.md, "The force row in the
    gap").  The answer obeys the law, and the beam carries the load and the push."""
    from jax.flatten_util import ravel_pytree

    net = sj.cantilever(3, length=L, EI=EI, dim=2)
    load = np.array([0.0, -0.03])  # pN: the free tip sags 0.01 µm
    delta = D / 10
    sag = float(sj.solve(net, forces={-1: load}).positions[-1, 1])
    loads = np.zeros(np.shape(net.loads))
    loads[-1] = load
    loaded = net.replace(loads=loads)

    def contact(y_wall):
        return sj.Contact(diameter=D, planes=(sj.Plane([0.0, y_wall], [0.0, 1.0]),), self_contact=False,
                          surfaces=False)

    start = sj.solve(net, forces={-1: load}, contact=contact(-1.0)).state  # the wall far away: no force
    delta_law, k = contact(-1.0).law(EI)
    for depth in (0.5, 3.0):
        y_wall = sag - D / 2 - delta * (1.0 - depth)
        model = sj.make_model(loaded, contact=contact(y_wall))
        control = sj.Control.make()
        frames = model.frames(start)
        flat, unravel = ravel_pytree(start)
        fn = jax.jit(lambda z: model.residual(unravel(z), control, frames))  # noqa: B023
        jac = jax.jit(jax.jacfwd(fn))
        z, iterations = flat, 0
        while np.abs(np.asarray(fn(z))).max() > 1e-10:
            assert iterations < 6, (depth, iterations, np.abs(np.asarray(fn(z))).max())
            z, iterations = z - np.linalg.solve(np.asarray(jac(z)), np.asarray(fn(z))), iterations + 1
        state = unravel(z)
        gap = float(state.positions[-1, 1]) - y_wall - D / 2
        force = np.asarray(state.contacts)[:, 0, 1:3].sum(axis=0)
        assert 0.0 < 1.0 - gap / delta < 0.05  # lightly pressed, inside the band
        # (the slot sits at the tip up to the length rows' tolerance, 1e-10 l: 1e-7 pN of law here)
        np.testing.assert_allclose(force[1], k * delta_law / 3 * (1 - gap / delta_law) ** 3, rtol=1e-6)
        # the clamp's segment carries the load and the wall's push (n = Σ of the forces beyond)
        np.testing.assert_allclose(np.asarray(state.forces)[0] - force, load, atol=1e-9)


def test_contact_none_and_no_obstacles_keep_the_contact_free_model():
    net = sj.cantilever(5, length=L, EI=EI, dim=2)
    free = sj.solve(net, forces={-1: TIP})
    none = sj.solve(net, forces={-1: TIP}, contact=None)
    np.testing.assert_array_equal(np.asarray(free.positions), np.asarray(none.positions))
    # the contact kernel (composite quadrature, jump corrections) with no obstacle at all
    empty = sj.solve(net, forces={-1: TIP}, contact=sj.Contact(self_contact=False, surfaces=False))
    np.testing.assert_allclose(np.asarray(empty.positions), np.asarray(free.positions), atol=1e-12)


def test_channel_column_departs_from_the_elastica_at_the_wall(tmp_path):
    h, delta = 0.1, 1e-4
    net = sj.column(9, length=L, EI=EI, dim=2, supports=("pinned", "pinned"))
    walls = (sj.Plane([0, -h], [0, 1]), sj.Plane([0, h], [0, -1]))
    con = sj.Contact(diameter=D, planes=walls, self_contact=False, surfaces=False, activation=delta)
    res = sj.compress(net, 0.03, contact=con, throw=False)
    free = sj.compress(net, 0.03)
    U, gap, F = np.asarray(res.displacement), np.asarray(res.min_gap), np.asarray(res.force)
    assert np.all(gap > -0.01 * D)  # no penetration beyond 1 % of the diameter
    # elastica (pinned–pinned, elliptic integrals): the contact force starts where the maximum
    # deflection reaches h − d/2 − δ
    y = h - D / 2 - delta
    k = brentq(lambda k: k * L / ellipk(k**2) - y, 1e-6, 0.99)
    onset = 2 * L * (1 - ellipe(k**2) / ellipk(k**2))
    i = int(np.flatnonzero(gap < delta)[0])
    found = np.interp(delta, [gap[i], gap[i - 1]], [U[i], U[i - 1]])
    assert abs(found - onset) / L < 1e-3
    # before: the contact-free curve; after: stiffer
    before = U < onset - 1e-3
    np.testing.assert_allclose(F[before], np.interp(U[before], np.asarray(free.displacement), np.asarray(free.force)),
                               rtol=1e-6)
    after = U > onset + 2e-3
    assert after.any() and np.all(F[after] > np.interp(U[after], np.asarray(free.displacement), np.asarray(free.force)) + 1)
    assert np.all(np.asarray(res.contact_count)[after] >= 1)
    assert np.all(np.asarray(res.contact_count)[before] == 0) and np.all(np.asarray(res.contact_force)[before] == 0)
    # every step: the support reactions, the walls' forces and the loads balance the column
    # (the walls' lateral push is carried by the two pinned ends), and the probe's reaction
    # along the compression axis is the probe force
    R, on_walls = np.asarray(res.reactions), res.obstacle_forces
    assert res.parameters["contact"]["obstacles"] == ["plane 0", "plane 1"] and on_walls.shape == (len(U), 2, 2)
    np.testing.assert_allclose(R.sum(axis=1) + np.asarray(res.network.loads).sum(axis=0), on_walls.sum(axis=1),
                               atol=1e-9 * F.max())
    assert np.abs(on_walls[after].sum(axis=1)[:, 1]).min() > 1.0  # the walls are pushed, sideways
    normals = np.array([[0.0, 1.0], [0.0, -1.0]])
    along = np.einsum("kcd,cd->kc", on_walls, normals)
    assert np.all(along <= 1e-12)  # each wall pushed into itself, never pulled
    np.testing.assert_allclose(on_walls, along[..., None] * normals, atol=1e-9 * F.max())  # frictionless: normal only
    probe, axis = np.asarray(res.network.probe), np.asarray(res.network.probe_direction)
    np.testing.assert_allclose((R[:, probe] @ axis).sum(axis=1), F, rtol=1e-9, atol=1e-9 * F.max())
    # the contact outputs survive the file, and the figures mark the contacts and draw the walls
    back = sj.load(sj.save(res, tmp_path / "channel.h5"))
    for name in ("contact_count", "min_gap", "contact_force", "contact_points", "contact_forces", "reactions",
                 "obstacle_forces"):
        np.testing.assert_array_equal(np.asarray(getattr(back, name)), np.asarray(getattr(res, name)))
    assert back.parameters["contact"]["planes"][1]["normal"] == [0.0, -1.0]
    with pytest.raises(ValueError, match="contact slots"):
        back.solution(1)
    fig = sj.plot_force_curve(back)
    assert any(a.get_ylabel() == "contacts carrying force" for a in fig.axes)
    assert "contacts" in [t.get_text() for t in sj.plot_snapshots(back).legends[0].get_texts()]


def test_a_start_inside_the_contact_range_is_refused_naming_the_pieces():
    """A path starts from a force-free state: filaments built closer than the diameter (two
    filaments 0.12 µm apart with d = 0.3 µm: −180 nm surface to surface), or a column δ/2 from
    a wall, are refused before the path with the two pieces and their gap named."""
    net, tip = two_filaments()
    with pytest.raises(ValueError, match="segments 0 and 4 are -180 nm apart .* overlapping"):
        sj.solve(net, forces={tip: np.array([0.0, -0.01])}, contact=sj.Contact(diameter=0.3, surfaces=False))
    delta = 1e-4
    column = sj.column(5, length=L, EI=EI, dim=2, supports=("pinned", "pinned"))
    wall = sj.Plane([0.0, -(D / 2 + delta / 2)], [0.0, 1.0])
    contact = sj.Contact(diameter=D, planes=(wall,), self_contact=False, surfaces=False, activation=delta)
    with pytest.raises(ValueError, match=r"segment \d and plane 0 are 0.05 nm apart .* δ = 0.1 nm"):
        sj.compress(column, 0.01, contact=contact)


def test_contact_input_errors_name_the_argument():
    with pytest.raises(ValueError, match="normal"):
        sj.Plane([0, 0], [0, 0])
    with pytest.raises(ValueError, match="diameter"):
        sj.Contact(diameter=-1.0)
    with pytest.raises(TypeError, match="planes"):
        sj.Contact(planes=[(0, 1)])
    net2 = sj.cantilever(3, dim=2)
    assert sj.Contact().self_contact and sj.Contact().surfaces  # the contract's defaults
    with pytest.raises(ValueError, match="per_segment"):
        sj.Contact(per_segment=0)
    with pytest.raises(ValueError, match="capacity"):
        sj.Contact(capacity=0)
    with pytest.raises(ValueError, match="self_contact=False"):
        sj.Contact(lumped=True)
    curved = sj.cantilever(3, GJ=1.0, natural_curvature=[0.5, 0.0, 0.0])
    with pytest.raises(NotImplementedError, match="natural curvature"):
        sj.solve(curved, forces={-1: [0, -1.0, 0]}, contact=sj.Contact(self_contact=False))
    with pytest.raises(ValueError, match="3D but the network is 2D"):
        sj.solve(net2, contact=sj.Contact(planes=(sj.Plane([0, 0, 0], [0, 0, 1]),), self_contact=False))


def test_a_tip_pressed_onto_a_wall_rests_on_it_and_the_forces_balance():
    """The lowest point of an inclined end segment is its tip, far from the segment's middle:
    the contact must be found there (the plane would otherwise be crossed unseen)."""
    net = sj.cantilever(5, length=L, EI=EI, dim=2)
    load = np.array([0.0, -2.0])
    wall = sj.Plane([0.0, -0.3], [0.0, 1.0])
    free = sj.solve(net, forces={-1: load})
    assert float(free.positions[-1, 1]) < -0.35  # without the wall the tip goes through it
    sol = sj.solve(net, forces={-1: load}, contact=sj.Contact(diameter=D, planes=(wall,), self_contact=False,
                                                                surfaces=False))
    delta = D / 10
    tip_gap = float(sol.positions[-1, 1]) + 0.3 - D / 2
    assert -0.01 * D < tip_gap < delta
    slots = np.asarray(sol.state.contacts)[:, 0]
    assert slots[-1, 0] == 1.0 and slots[-1, 2] > 0.5  # at the tip (σ = 1), pushing up
    np.testing.assert_allclose(np.asarray(sol.reactions[0]) + load + slots[:, 1:3].sum(axis=0), 0.0, atol=1e-8)


def test_the_contact_point_rule_is_continuous_where_a_straight_segment_lies_flat():
    """A straight segment parallel to a plane inside its band: both ends are equally far and
    d²φ/ds² = 0 (a strand end lying flat on the substrate, as on the 8-generation outcrop).
    The slot rows must not jump when rounding tilts the segment or bends it by 1e-12 either
    way: a jump made Newton chatter there (docs/equations.md, "flat-lying strand ends")."""
    net = sj.cantilever(2, length=L, EI=EI, dim=2)
    delta = D / 10
    wall = sj.Plane([0.0, -(D / 2 + delta / 2)], [0.0, 1.0])
    model = sj.make_model(net, contact=sj.Contact(diameter=D, planes=(wall,), self_contact=False, surfaces=False))
    state = model.initial_state()
    frames = model.frames(state)

    def rows(tilt, kappa):
        moved = eqx.tree_at(lambda s: (s.positions, s.contacts), state,
                            (state.positions.at[-1, 1].add(tilt), state.contacts.at[0, 0, 4].set(kappa)))
        return np.asarray(model.residual(moved, sj.Control.make(), frames))

    for eps in (1e-9, 1e-12):
        assert np.max(np.abs(rows(eps, 0.0) - rows(-eps, 0.0))) < 1e-4  # the tip a hair higher / lower
        assert np.max(np.abs(rows(0.0, eps) - rows(0.0, -eps))) < 1e-4  # bent a hair away / toward
    # away from the blends the rule is the nearer end: raising the tip by 2δ changes the rows
    # by O(1) (the slot at σ = ½ is then half a segment from its root at the start)
    assert np.max(np.abs(rows(2 * delta, 0.0) - rows(-2 * delta, 0.0))) > 0.5


def test_the_nearer_end_rule_of_a_straight_segment_misses_little_depth():
    """A straight segment's slot takes the nearer end, blended where the ends are almost
    equally far; the blend widens with the ends' mean height above the surface (a strand end
    lying flat above it did flip between Newton iterates on the 8-generation outcrop).  Swept
    over tilts and heights, the slot's gap exceeds the nearer end's by at most
    0.005 δ + 0.1 × the mean height (so an end penetrating the surface is seen to 0.005 δ),
    a clear tilt in the band puts the slot on the lower end, a tilt of ±δ/10 does not flip it
    from one end to the other where the segment lies δ/2 or more above the surface (the
    narrow blend alone flips it there), and a tilt step of δ/200 moves it by less than 0.1."""
    net = sj.cantilever(2, length=L, EI=EI, dim=2)
    delta = D / 10
    tilts = np.linspace(-3 * delta, 3 * delta, 1201)
    wall = sj.Plane([0.0, -D / 2], [0.0, 1.0])  # the segment's axis at y = 0 touches it
    model = sj.make_model(net, contact=sj.Contact(diameter=D, planes=(wall,), self_contact=False, surfaces=False))
    state = model.initial_state()
    state = eqx.tree_at(lambda s: s.contacts, state, state.contacts.at[0, 0, 0].set(0.0))
    frames = model.frames(state)
    n_slot = state.contacts.size

    @jax.jit
    def location(height, tilt):  # the row at σ = 0 is −(the rule's σ)
        lifted = state.positions.at[:, 1].add(height).at[-1, 1].add(tilt)
        return -model.residual(eqx.tree_at(lambda s: s.positions, state, lifted), sj.Control.make(), frames)[-n_slot]

    for height in (-0.2 * delta, 0.0, 0.5 * delta, 3 * delta, 10 * delta):
        sigma = np.asarray(jax.vmap(location, (None, 0))(height, tilts))
        assert np.all((sigma > -1e-12) & (sigma < 1 + 1e-12))
        assert np.max(np.abs(np.diff(sigma))) < 0.1, height
        near = height + np.minimum(tilts, 0.0)  # the nearer end's gap
        seen = height + sigma * tilts  # the slot's gap (a straight segment)
        mean = height + tilts / 2
        assert np.all(seen - near <= 0.005 * delta + 0.1 * np.maximum(mean, 0.0) + 1e-15), height
        if height >= delta / 2:  # lying flat above the surface: a tilt of ±δ/10 does not flip the rule
            assert abs(float(location(height, 0.1 * delta)) - float(location(height, -0.1 * delta))) < 0.5, height
        if height <= delta / 2:  # in the band, a clear tilt puts the slot on the end
            clear = np.abs(tilts) > 1.5 * delta
            assert np.all(seen[clear] - near[clear] < 1e-3 * delta), height


def test_filament_on_a_stiff_filament_matches_the_same_filament_on_a_wall():
    """Filament–filament contact (pair slots, broad phase) against the validated wall
    contact: a stiff filament under a cantilever acts as a plane d/2 above its axis."""
    net, tip = two_filaments()
    load = np.array([0.0, -3.0])
    pair = sj.solve(net, forces={tip: load}, contact=sj.Contact(diameter=D, surfaces=False, stiffness=1e6))
    wall = sj.Plane([0.0, -0.12 + D / 2], [0.0, 1.0])
    plane = sj.solve(sj.cantilever(5, length=L, EI=EI, dim=2), forces={-1: load},
                     contact=sj.Contact(diameter=D, planes=(wall,), self_contact=False, surfaces=False, stiffness=1e6))
    assert float(plane.positions[-1, 1]) > -0.12  # the wall holds the tip up
    np.testing.assert_allclose(np.asarray(pair.positions[tip]), np.asarray(plane.positions[-1]), atol=1e-6)


def test_clamped_column_self_contact_follows_the_elastica_then_departs():
    """Clamped–clamped column (16 segments, d = 0.01 L): until its lobes touch, the gap
    between them is the elliptic-integral elastica's (zero-thickness touch at Δ/L = 0.8487);
    then the force departs from the contact-free curve and nothing interpenetrates.
    Slow: about 25 s (dense solver, ~170 path steps)."""
    assert abs(elastica_end_shortening(brentq(lambda k: clamped_elastica_lobe_gap(k), 0.75, 0.9999)) - 0.8487) < 1e-4
    net = sj.column(17, length=L, EI=EI, dim=2, supports=("clamped", "clamped"))
    res = sj.compress(net, 0.86, contact=sj.Contact(diameter=D, surfaces=False), throw=False, method="arclength")
    free = sj.compress(net, 0.86, method="arclength", throw=False)  # without contact its lobes pass through
    U, gap, F = np.asarray(res.displacement), np.asarray(res.min_gap), np.asarray(res.force)
    assert res.completed and np.all(gap[np.isfinite(gap)] > -0.01 * D)
    onset = elastica_end_shortening(brentq(lambda k: clamped_elastica_lobe_gap(k) - D - D / 10, 0.75, 0.9999))
    close = (gap < 0.02) & (U < onset - 2e-3)
    assert close.sum() >= 2
    for u, g in zip(U[close], gap[close]):
        k = brentq(lambda k: elastica_end_shortening(k) - u, 0.5, 0.9999)
        assert abs(g - (clamped_elastica_lobe_gap(k) - D)) < 1e-3
    before = np.flatnonzero((U > 0.05) & (U < onset - 2e-3))[::10]
    exact = sj.compress(net, 0.86, at=U[before], method="arclength", throw=False)  # contact-free, at the same u
    np.testing.assert_allclose(F[before], np.asarray(exact.force), rtol=1e-6)
    f_free = np.interp(U, np.asarray(free.displacement), np.asarray(free.force))
    after = U > onset + 5e-3
    assert after.any() and np.all(F[after] > f_free[after] + 1.0) and np.all(np.asarray(res.contact_count)[after] >= 1)


@pytest.mark.slow  # 25–42 s in CI; the suite's 10-minute budget
def test_more_pairs_than_the_capacity_stop_the_path_and_say_so():
    net, tip = two_filaments()
    small = sj.Contact(diameter=D, surfaces=False, stiffness=1e6, capacity=1)
    sol = sj.solve(net, forces={tip: np.array([0.0, -3.0])}, contact=small, throw=False)
    assert sol.result == sj.RESULTS.contact_capacity
    with pytest.raises(sj.ConvergenceError, match="capacity"):
        sj.solve(net, forces={tip: np.array([0.0, -3.0])}, contact=small)


def test_the_state_template_has_the_settled_states_structure():
    """``SOCBModel.state_template`` (what callers that need only the structure use: unravel,
    path weights; no contact start) has the settled initial state's tree, shapes and dtypes,
    and without contact it is the initial state itself."""
    net = sj.cantilever(3, dim=2)
    wall = sj.Plane([0.0, -0.05], [0.0, 1.0])
    model = sj.make_model(net, contact=sj.Contact(diameter=0.01, planes=(wall,), self_contact=False, surfaces=False))
    template, settled = model.state_template(), model.initial_state()
    assert jax.tree_util.tree_structure(template) == jax.tree_util.tree_structure(settled)
    for a, b in zip(jax.tree_util.tree_leaves(template), jax.tree_util.tree_leaves(settled)):
        assert a.shape == b.shape and a.dtype == b.dtype
    free = sj.make_model(net)
    for a, b in zip(jax.tree_util.tree_leaves(free.state_template()), jax.tree_util.tree_leaves(free.initial_state())):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def _sigma_column(model, state, frames, put, sigma):
    """∂(residual)/∂σ [n] of the slot that ``put(state, σ)`` sets, at σ."""
    def rows(value):
        return ravel_pytree(model.residual(put(state, value), sj.Control.make(), frames))[0]
    return np.asarray(jax.jacfwd(rows)(jnp.asarray(sigma, jnp.float64)))


def test_a_slot_beyond_its_segment_end_keeps_a_regular_location_row():
    """Beyond [0, 1] (a predictor or Newton iterate past an end, or a slot resting exactly on
    an end) the curve is evaluated at the end, so nothing but the location row can depend on
    σ there: that row must change with σ, or J is singular.  It was flat (σ − P(σ − ∇φ·t) with
    ∇φ·t frozen at the end) and stalled the 6-generation outcrop with self-contact: a pair slot
    held at σ = 1 while its closest point moved back inside the segment failed every step size.
    Obstacle slot (a one-segment cantilever over a sphere, closest point σ = 0.45, where the
    row vanishes) and pair slot (the two filaments of test_paired)."""
    net = sj.cantilever(2, length=L, EI=EI, dim=2)
    R = 0.05
    sphere = sj.Sphere([0.45 * L, -(D / 2 + R + D / 20)], R)
    model = sj.make_model(net, contact=sj.Contact(diameter=D, obstacles=(sphere,), self_contact=False, surfaces=False))
    state = model.initial_state()
    frames = model.frames(state)
    put = lambda st, s: eqx.tree_at(lambda t: t.contacts, st, st.contacts.at[0, 0, 0].set(s))  # noqa: E731
    for sigma in (1.0, 1.05, 1.3, 0.0, -0.1):
        column = _sigma_column(model, state, frames, put, sigma)
        assert np.max(np.abs(column)) > 0.5, sigma
    row = int(np.argmax(np.abs(_sigma_column(model, state, frames, put, 1.05))))
    at = lambda s: float(ravel_pytree(model.residual(put(state, s), sj.Control.make(), frames))[0][row])  # noqa: E731
    assert abs(at(0.45)) < 1e-6 and abs(at(0.4)) > 1e-3  # the closest point, and only there

    net, _ = two_filaments()
    model = sj.make_model(net, contact=sj.Contact(diameter=D, surfaces=False, stiffness=1e6))
    state = model.initial_state()
    slots = state.pairs.at[0, :4].set(jnp.asarray([3.0, 9.0, 0.5, 0.5]))  # the tip segment (3) and the stiff one's 6th (9)
    state = eqx.tree_at(lambda t: t.pairs, state, slots)
    frames = (model.frames(state)[0], model.pair_list(state, rebuild=False))
    put = lambda st, s: eqx.tree_at(lambda t: t.pairs, st, st.pairs.at[0, 3].set(s))  # noqa: E731
    for sigma in (1.0, 1.05, -0.05):
        assert np.max(np.abs(_sigma_column(model, state, frames, put, sigma))) > 0.5, sigma
