"""Branch junctions: an unloaded daughter changes nothing; a kinked cantilever matches the
shooting elastica with a rigid corner; the junction system is square and well posed."""

import jax
import numpy as np
import pytest

import socbjax as sj
from socbjax import testing as _reference


def branched_cantilever(dim, *, n_mother=4, mother_length=1.0, branch_node=1, angle_deg=70.0, daughter_length=0.5, n_daughter=2, EI=1.0, at_tip=False):
    """Mother along +x clamped at node 0; a daughter from ``branch_node`` (or from the tip)."""
    axis = np.eye(dim)[0]
    side = np.eye(dim)[1]
    s = np.linspace(0.0, mother_length, n_mother)
    pos = [si * axis for si in s]
    tan = [axis] * n_mother
    segs = [(k, k + 1) for k in range(n_mother - 1)]
    J = n_mother - 1 if at_tip else branch_node
    phi = np.deg2rad(angle_deg)
    t_d = np.cos(phi) * axis + np.sin(phi) * side
    base = len(pos)
    for k, sk in enumerate(np.linspace(0.0, daughter_length, n_daughter + 1)):
        pos.append(pos[J] + sk * t_d)
        tan.append(t_d)
        if k:
            segs.append((base + k - 1, base + k))
    lengths = [mother_length / (n_mother - 1)] * (n_mother - 1) + [daughter_length / n_daughter] * n_daughter
    fixed = [np.eye(dim)] + [np.zeros((0, dim))] * (len(pos) - 1)
    clamped = np.zeros(len(pos), bool)
    clamped[0] = True
    net = sj.make_network(pos, tan, segs, lengths, EI, fixed_directions=fixed, clamped=clamped, attach=[(J, base)])
    return net, J, base


@pytest.mark.parametrize("dim", [2, pytest.param(3, marks=pytest.mark.slow)])
def test_unloaded_daughter_leaves_the_mother_unchanged(dim):
    force = np.zeros(dim)
    force[1] = -2.0
    force[0] = 0.3
    plain = sj.solve(sj.cantilever(4, dim=dim), {3: force})
    net, J, D = branched_cantilever(dim)
    branched = sj.solve(net, {3: force})
    np.testing.assert_allclose(branched.positions[:4], plain.positions, atol=1e-10)
    np.testing.assert_allclose(branched.moments[:4], plain.moments, atol=1e-10)
    # The daughter rides rigidly: straight, unstressed, at 70° to the mother's tangent at J.
    t_J, t_D = np.asarray(branched.tangents[J]), np.asarray(branched.tangents[D])
    assert np.degrees(np.arccos(np.clip(t_J @ t_D, -1, 1))) == pytest.approx(70.0, abs=1e-9)
    tip = np.asarray(branched.positions[-1] - branched.positions[D])
    np.testing.assert_allclose(tip, 0.5 * t_D, atol=1e-10)
    np.testing.assert_allclose(branched.segment_forces[3:], 0.0, atol=1e-10)


@pytest.mark.parametrize("dim", [2, pytest.param(3, marks=pytest.mark.slow)])
def test_junction_system_is_square(dim):
    net, _, _ = branched_cantilever(dim)
    model = sj.make_model(net)
    state = model.initial_state()
    x, unravel = jax.flatten_util.ravel_pytree(state)
    r = model.residual(unravel(x), sj.Control.make(), model.frames(state))
    assert r.shape == x.shape
    jac = np.asarray(jax.jacfwd(lambda y: model.residual(unravel(y), sj.Control.make(), model.frames(state)))(x))
    assert np.linalg.matrix_rank(jac) == x.size  # no zero modes: the azimuth is fixed


@pytest.mark.parametrize("dim", [2, pytest.param(3, marks=pytest.mark.slow)])
@pytest.mark.parametrize("kink_deg", [30.0, -50.0])
def test_kinked_cantilever_matches_the_elastica_with_a_corner(dim, kink_deg):
    L1, L2, EI = 1.0, 0.6, 1.0
    net, _J, _D = branched_cantilever(dim, n_mother=4, mother_length=L1, angle_deg=kink_deg, daughter_length=L2, n_daughter=3, EI=EI, at_tip=True)
    force2 = np.array([0.4, -1.5])
    force = np.zeros(dim)
    force[:2] = force2
    sol = sj.solve(net, {len(np.asarray(net.positions)) - 1: force})
    ref = _reference.elastica_kinked_cantilever(force2, lengths=(L1, L2), kink_angle=np.deg2rad(kink_deg), EI=EI)
    assert ref.converged
    tip = np.asarray(sol.positions[-1])[:2]
    np.testing.assert_allclose(tip, np.asarray(ref.tip_position), atol=2e-5 * (L1 + L2))
    # Base moment: the clamp reaction moment = m at node 0.
    m0 = float(sol.moments[0]) if dim == 2 else float(sol.moments[0][2])
    assert m0 == pytest.approx(float(ref.base_moment), abs=1e-4)


def test_junction_validation_errors():
    net, J, D = branched_cantilever(2)
    pos, tan = np.asarray(net.positions), np.asarray(net.tangents)
    segs, lengths = np.asarray(net.segments), np.asarray(net.lengths)
    fixed = [np.eye(2)] + [np.zeros((0, 2))] * (len(pos) - 1)
    clamped = np.zeros(len(pos), bool)
    clamped[0] = True
    kw = {"fixed_directions": fixed, "clamped": clamped}
    with pytest.raises(ValueError, match="attach has the node index 99, outside the valid range"):
        sj.make_network(pos, tan, segs, lengths, 1.0, attach=[(J, 99)], **kw)
    with pytest.raises(ValueError, match="duplicate junction"):
        sj.make_network(pos, tan, segs, lengths, 1.0, attach=[(J, D), (2, D)], **kw)
    with pytest.raises(ValueError, match="daughter base node"):
        sj.make_network(pos, tan, segs, lengths, 1.0, attach=[(J, D + 1)], **kw)
    with pytest.raises(ValueError, match="rigid-body"):
        sj.make_network(pos, tan, segs, lengths, 1.0, fixed_directions=fixed, clamped=clamped)  # daughter detached
    with pytest.raises(ValueError, match="rigid-body"):
        sj.make_network(pos, tan, segs, lengths, 1.0, attach=[(J, D)])  # nothing supported
    bad = pos.copy()
    bad[2] = bad[1]
    with pytest.raises(ValueError, match="zero-length"):
        sj.make_network(bad, tan, segs, lengths, 1.0, attach=[(J, D)], **kw)
    with pytest.raises(ValueError, match="more than two segments"):
        sj.make_network(pos, tan, np.vstack([segs, [[1, 5]]]), np.append(lengths, 0.5), 1.0, **kw)


@pytest.mark.slow  # suite time; in the default suite: 3D rotation invariance of filaments (tests/test_spatial.py)
def test_branched_network_is_rotation_equivariant(rng):
    """The 3D junction rule (minimal rotation of the reference pair) keeps the whole problem
    equivariant: rotating network and loads rotates the solution."""
    from conftest import random_rotation

    net, J, D = branched_cantilever(3, n_mother=4, daughter_length=0.6, angle_deg=50.0)
    n = net.n_nodes
    loads = {n - 1: [0.3, 1.2, -0.8], 2: [0.0, -0.4, 0.5]}
    base = sj.solve(net, loads)
    Q = random_rotation(rng)
    pos, tan = np.asarray(net.positions) @ Q.T, np.asarray(net.tangents) @ Q.T
    fixed = [np.eye(3)] + [np.zeros((0, 3))] * (n - 1)
    clamped = np.zeros(n, bool)
    clamped[0] = True
    rotated_net = sj.make_network(pos, tan, np.asarray(net.segments), np.asarray(net.lengths), 1.0, fixed_directions=fixed, clamped=clamped, attach=[(J, D)])
    rotated = sj.solve(rotated_net, {k: Q @ np.asarray(v) for k, v in loads.items()})
    np.testing.assert_allclose(np.asarray(rotated.positions), np.asarray(base.positions) @ Q.T, atol=1e-9)
    np.testing.assert_allclose(np.asarray(rotated.moments), np.asarray(base.moments) @ Q.T, atol=1e-9)
    # The daughter keeps its branch angle to the mother, however the mother turned.
    t = np.asarray(base.tangents)
    assert np.degrees(np.arccos(np.clip(t[J] @ t[D], -1, 1))) == pytest.approx(50.0, abs=1e-9)


@pytest.mark.parametrize("turn_deg", [150.0, 120.0])
def test_planar_branched_network_is_rotation_equivariant_across_the_angle_wrap(turn_deg):
    """Rotated so that the mother points at ``turn_deg`` and the 70° daughter past ±180°
    (arctan2 of its reference tangent wraps by 2π): the same solution, rotated."""
    net, J, D = branched_cantilever(2, n_mother=4, daughter_length=0.6)
    n = net.n_nodes
    loads = {n - 1: [0.3, 1.2], 2: [0.0, -0.4]}
    base = sj.solve(net, loads)
    c, s = np.cos(np.radians(turn_deg)), np.sin(np.radians(turn_deg))
    Q = np.array([[c, -s], [s, c]])
    pos, tan = np.asarray(net.positions) @ Q.T, np.asarray(net.tangents) @ Q.T
    angles = np.degrees(np.arctan2(tan[:, 1], tan[:, 0]))
    assert abs(angles[D] - angles[J]) > 180.0  # the daughter's reference angle wrapped
    fixed = [np.eye(2)] + [np.zeros((0, 2))] * (n - 1)
    rotated_net = sj.make_network(pos, tan, np.asarray(net.segments), np.asarray(net.lengths), 1.0,
                                  fixed_directions=fixed, clamped=np.arange(n) == 0, attach=[(J, D)])
    rotated = sj.solve(rotated_net, {k: Q @ np.asarray(v) for k, v in loads.items()})
    np.testing.assert_allclose(np.asarray(rotated.positions), np.asarray(base.positions) @ Q.T, atol=1e-9)
    np.testing.assert_allclose(np.asarray(rotated.moments), np.asarray(base.moments), atol=1e-9)
