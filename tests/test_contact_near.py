"""The near list of obstacle contact (``Contact(slot_capacity=K)``): only the K segments
nearest to a plane carry the contact kernel, the others the contact-free one.  Checked
against the full model (every segment with its slots): a cantilever pressed onto a wall,
and (slow) a channel column's force curve through contact with forward-mode derivatives;
a list too short stops a solve and says so, and compress grows it; a step that brings an
unlisted segment near a plane is refused."""

import numpy as np
import pytest

import equinox as eqx
import jax
import socbjax as sj

L, EI, D, H, DELTA = 1.0, 1.0, 0.01, 0.1, 1e-4
N_SEGMENTS = 16


def _channel():
    net = sj.column(N_SEGMENTS + 1, length=L, EI=EI, dim=2, supports=("pinned", "pinned"))
    walls = (sj.Plane([0, -H], [0, 1]), sj.Plane([0, H], [0, -1]))
    return net, walls


def _contact(walls, capacity):
    return sj.Contact(diameter=D, planes=walls, self_contact=False, surfaces=False, activation=DELTA,
                      slot_capacity=capacity)


def _pressed(capacity, EI_scale=1.0, load=3.0, throw=True):
    """A 16-segment cantilever pressed tip-first by ``load`` pN onto a wall 0.3 µm below it."""
    net = sj.cantilever(N_SEGMENTS + 1, length=L, EI=EI, dim=2)
    wall = sj.Plane([0, -0.3], [0, 1])
    contact = sj.Contact(diameter=D, planes=(wall,), self_contact=False, surfaces=False, slot_capacity=capacity)
    return sj.solve(net.replace(EI=net.EI * EI_scale), forces={-1: np.array([0.0, -load])}, contact=contact,
                    throw=throw)


def _outputs(sol):
    """(tip height µm, positions [N, 2] µm, total wall force [2] pN, reactions [N, 2] pN)."""
    return sol.positions[-1, 1], sol.positions, sol.state.contacts[..., 1:3].sum(axis=(0, 1)), sol.reactions


def test_a_near_list_solves_a_pressed_cantilever_as_the_full_model():
    """4 of 16 segments listed (the ramp lists the 4 nearest the wall; the tip's 2 need it):
    the full model's shape, wall force and clamp reaction, and the same d(tip height)/dEI
    (central differences of both models)."""
    listed, full = _outputs(_pressed(4)), _outputs(_pressed(N_SEGMENTS))
    assert float(full[0]) < -0.29 and float(full[2][1]) > 1.0  # the tip rests on the wall, which carries most load
    for a, b in zip(listed, full):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=1e-10)
    h = 1e-5

    def slope(capacity):
        up, down = _pressed(capacity, 1 + h), _pressed(capacity, 1 - h)
        return (float(up.positions[-1, 1]) - float(down.positions[-1, 1])) / (2 * h)

    np.testing.assert_allclose(slope(4), slope(N_SEGMENTS), rtol=1e-6)


def test_a_near_list_too_short_stops_the_path_and_says_so():
    """Pressed 10× harder, the cantilever lies along the wall: more than 4 segments near it."""
    assert _pressed(4, load=30.0, throw=False).result == sj.RESULTS.contact_capacity
    with pytest.raises(sj.ConvergenceError, match="slot_capacity"):
        _pressed(4, load=30.0)


@pytest.mark.slow
def test_a_near_list_follows_the_full_model_through_the_channel():
    """13 of 16 segments listed: the same forces, gaps and contacts as every segment with its
    slots (capacity ≥ S), before and after the column meets the wall, and the same derivatives
    of the forces with respect to EI (one forward-mode pass each)."""
    net, walls = _channel()
    at = np.linspace(0.004, 0.03, 6)

    def outputs(EI_scale, capacity):
        res = sj.compress(net.replace(EI=net.EI * EI_scale), 0.03, at=at, contact=_contact(walls, capacity))
        return res.force, res.min_gap, res.contact_count.astype(float)

    (F_l, gap_l, count_l), (dF_l, _, _) = jax.jvp(lambda s: outputs(s, 13), (1.0,), (1.0,))
    (F_f, gap_f, count_f), (dF_f, _, _) = jax.jvp(lambda s: outputs(s, N_SEGMENTS), (1.0,), (1.0,))
    assert count_f[0] == 0 and count_f[-1] >= 1  # the column meets the wall on the way
    np.testing.assert_allclose(np.asarray(F_l), np.asarray(F_f), rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(np.asarray(gap_l), np.asarray(gap_f), rtol=1e-8, atol=1e-12)
    np.testing.assert_array_equal(np.asarray(count_l), np.asarray(count_f))
    np.testing.assert_allclose(np.asarray(dF_l), np.asarray(dF_f), rtol=1e-7, atol=1e-9)
    assert np.all(np.isfinite(np.asarray(dF_f))) and abs(float(dF_f[-1])) > 0


def test_compress_grows_a_near_list_that_overflows_and_ends_where_the_full_model_does():
    """An 8-segment channel column listed 2 at a time: compress (host-driven) doubles the list
    each time more segments come near a wall (2 → 4 → 8 = every segment), says so, and ends at
    the full model's equilibrium (every segment with its slots) past the first contact."""
    net = sj.column(9, length=L, EI=EI, dim=2, supports=("pinned", "pinned"))
    walls = (sj.Plane([0, -H], [0, 1]), sj.Plane([0, H], [0, -1]))
    U = 0.026  # past the contact at Δ/L ≈ 0.022, before the line contact's critical point
    with pytest.warns(UserWarning, match="segments came near a surface") as caught:
        grown = sj.compress(net, U, contact=_contact(walls, 2))
    assert [str(w.message).split("grows to ")[1].split()[0] for w in caught] == ["4", "8"]
    full = sj.compress(net, U, contact=_contact(walls, 8))
    assert grown.completed and int(grown.contact_count[-1]) >= 1
    np.testing.assert_allclose(float(grown.force[-1]), float(full.force[-1]), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(grown.positions[-1]), np.asarray(full.positions[-1]), atol=1e-10)


def test_a_step_that_brings_an_unlisted_segment_near_a_plane_is_refused():
    net, walls = _channel()
    model = sj.make_model(net, contact=_contact(walls, 4))
    state = model.initial_state()
    frames = model.frames(state)
    listed = np.asarray(frames[1].ids)
    outside = int(np.setdiff1d(np.arange(N_SEGMENTS), listed)[0])
    assert listed.size == 4

    def lifted(segment, height):
        nodes = np.asarray(net.segments)[segment]
        return eqx.tree_at(lambda s: s.positions, state, state.positions.at[nodes, 1].add(height))

    # the nodes of one segment lifted to within the contact band of the upper wall (gap 4δ)
    near = H - D / 2 - 4 * DELTA
    assert not bool(model.step_admissible(state, lifted(outside, near), frames)[0])
    assert bool(model.step_admissible(state, lifted(int(listed[0]), near), frames)[0])
    assert bool(model.step_admissible(state, lifted(outside, 0.2 * H), frames)[0])


def test_slot_capacity_errors_name_the_argument():
    with pytest.raises(ValueError, match="slot_capacity=5 .* self_contact=False"):
        sj.Contact(slot_capacity=5)
    with pytest.raises(ValueError, match="slot_capacity"):
        sj.Contact(self_contact=False, slot_capacity=0)
