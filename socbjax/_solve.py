"""Public entry points: :func:`solve` (static equilibrium under loads, by load continuation)
and :func:`buckling_load` (critical axial load of the straight state)."""

from __future__ import annotations

from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._continuation import ContinuationSettings, load_continuation
from ._jointed import JointedModel, JointedState, joint_moments
from ._network import Network
from ._newton import NewtonSolver, Status
from ._quadrature import get_quadrature
from ._residual import SOCBModel, SOCBState, net_nodal_force

__all__ = ["Solution", "ConvergenceError", "default_atol", "prepare_jacobian_solver", "solve", "buckling_load", "make_model", "forces_array", "MODELS"]

MODELS = ("socb", "jointed")


class ConvergenceError(RuntimeError):
    """Raised when a solve does not converge and ``throw=True``."""


class Solution(eqx.Module):
    """A static equilibrium (or the last accepted state of a failed solve: check ``converged``).

    positions : [N, d] node positions (µm).
    tangents : [N, d] unit tangents at nodes.
    angles : 2D [N] angle θ (rad); 3D [N, 2] in-plane θ = atan2(t_y, t_x) and out-plane
        φ = asin(t_z) (rad) — for reporting only, the solver itself uses no angles in 3D.
    moments : 2D [N] bending moment (pN·µm); 3D [N, 3] moment vector.
    curvatures : 2D [N] signed curvature dθ/ds (1/µm); 3D [N, 3] curvature vector t × t'.
    segment_forces : [S, d] internal force per segment (pN).
    reactions : [N, d] support reactions (pN), zero at free nodes.
    status : :class:`Status` code; ``converged`` is ``status == CONVERGED``.
    load_factor : fraction of the requested load reached (1.0 when converged).
    """

    positions: Float[Array, "N d"]
    tangents: Float[Array, "N d"]
    angles: Array
    moments: Array
    curvatures: Array
    segment_forces: Float[Array, "S d"]
    reactions: Float[Array, "N d"]
    status: Array
    iterations: Array
    steps: Array
    cutbacks: Array
    residual_norm: Array
    load_factor: Array
    state: object
    model: str = eqx.field(static=True)

    @property
    def converged(self) -> bool:
        return bool(self.status == Status.CONVERGED)

    @property
    def status_message(self) -> str:
        return Status(int(self.status)).message

    def __repr__(self) -> str:  # short, numbers a person wants first
        tip = np.asarray(self.positions[-1]).round(6).tolist()
        return (
            f"Solution(model={self.model!r}, converged={self.converged}, status={Status(int(self.status)).name}, "
            f"load_factor={float(self.load_factor):.4g}, steps={int(self.steps)}, iterations={int(self.iterations)}, "
            f"residual={float(self.residual_norm):.2e}, last_node={tip})"
        )


def make_model(network: Network, model: str = "socb", *, quadrature_order: int = 8):
    """The discretisation object for ``model`` ("socb" or "jointed")."""
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network (e.g. socbjax.cantilever(...)), got {type(network).__name__}")
    if model == "socb":
        return SOCBModel(network, get_quadrature(quadrature_order))
    if model == "jointed":
        if network.n_junctions or bool(np.any(np.asarray(network.probe))):
            raise ValueError(
                "the jointed baseline supports single filaments only (no branch junctions or probe); use model='socb'"
            )
        return JointedModel(network)
    raise ValueError(f"unknown model {model!r}; use one of {MODELS}")


def forces_array(network: Network, forces) -> np.ndarray:
    """Validate ``forces`` ({node index: vector} or array [N, d], pN) into an array [N, d]."""
    n, d = network.n_nodes, network.dim
    out = np.zeros((n, d))
    if isinstance(forces, Mapping):
        for key, vec in forces.items():
            if isinstance(key, bool) or not isinstance(key, (int, np.integer)):
                raise TypeError(f"force keys must be integer node indices, got {key!r}")
            if not -n <= key < n:
                raise ValueError(f"force applied to node {key}, but the network has {n} nodes (valid: {-n}..{n - 1})")
            v = np.asarray(vec, dtype=np.float64).ravel()
            if v.shape != (d,):
                raise ValueError(f"force on node {key} must have {d} components (dim={d}), got {v.shape[0]}")
            out[key] += v
    else:
        arr = np.asarray(forces, dtype=np.float64)
        if arr.shape != (n, d):
            raise ValueError(f"forces array must have shape ({n}, {d}), got {arr.shape}")
        out[:] = arr
    if not np.all(np.isfinite(out)):
        raise ValueError("forces contain NaN or infinite values")
    return out


@eqx.filter_jit
def _solve_jit(disc, name, loads, state0, solver, settings):
    # Packaging is compiled with the solve: host-side post-processing cost ~4 ms per call.
    result = load_continuation(disc, loads, state0, solver=solver, settings=settings)
    return _package(disc, name, result, loads)


def _node_EI(network: Network):
    seg = network.segments
    total = jax.ops.segment_sum(jnp.concatenate([network.EI, network.EI]), jnp.concatenate([seg[:, 0], seg[:, 1]]), network.n_nodes)
    count = jax.ops.segment_sum(jnp.ones(2 * network.n_segments), jnp.concatenate([seg[:, 0], seg[:, 1]]), network.n_nodes)
    return total / jnp.maximum(count, 1.0)


def _kinematics(model, state):
    """(tangents [N, d], moments) of a converged state of either model."""
    net = model.network
    if isinstance(state, SOCBState):
        if net.dim == 2:
            tangents = jnp.stack([jnp.cos(state.directors), jnp.sin(state.directors)], axis=-1)
        else:
            tangents = state.directors / jnp.linalg.norm(state.directors, axis=-1, keepdims=True)
        return tangents, state.moments
    assert isinstance(state, JointedState)
    d = state.directions
    d = jnp.stack([jnp.cos(d), jnp.sin(d)], axis=-1) if net.dim == 2 else d / jnp.linalg.norm(d, axis=-1, keepdims=True)
    summed = jax.ops.segment_sum(jnp.concatenate([d, d]), jnp.concatenate([net.segments[:, 0], net.segments[:, 1]]), net.n_nodes)
    tangents = summed / jnp.linalg.norm(summed, axis=-1, keepdims=True)
    return tangents, joint_moments(state, net)


def _package(model, name, result, loads) -> Solution:
    net = model.network
    state = result.state
    tangents, moments = _kinematics(model, state)
    EI = _node_EI(net)
    if net.dim == 2:
        angles = jnp.arctan2(tangents[:, 1], tangents[:, 0])
        if isinstance(state, SOCBState):
            angles = state.directors  # keeps the winding (angles beyond ±π)
        curvatures = moments / EI
    else:
        angles = jnp.stack([jnp.arctan2(tangents[:, 1], tangents[:, 0]), jnp.arcsin(jnp.clip(tangents[:, 2], -1, 1))], axis=-1)
        curvatures = moments / EI[:, None]
    reactions = net_nodal_force(state.forces, net, result.load_factor * loads)  # external force the support applies
    reactions = jnp.einsum("nij,nj->ni", net.position_projector, reactions)
    return Solution(
        positions=state.positions,
        tangents=tangents,
        angles=angles,
        moments=moments,
        curvatures=curvatures,
        segment_forces=state.forces,
        reactions=reactions,
        status=result.status,
        iterations=result.iterations,
        steps=result.steps,
        cutbacks=result.cutbacks,
        residual_norm=result.residual_norm,
        load_factor=result.load_factor,
        state=state,
        model=name,
    )


def solve(
    network: Network,
    forces,
    *,
    model: str = "socb",
    quadrature_order: int = 8,
    solver: NewtonSolver | None = None,
    continuation: ContinuationSettings | None = None,
    initial_state=None,
    linear_solver: str = "auto",
    throw: bool = True,
) -> Solution:
    """Static equilibrium of ``network`` under fixed-direction nodal ``forces``.

    Parameters
    ----------
    network : from :func:`socbjax.cantilever`, :func:`socbjax.column`, ...
    forces : {node index: force vector (pN)} (negative indices allowed) or array [N, d];
        added to the network's own ``loads`` and ramped together from zero.
    model : "socb" (the SOCB method) or "jointed" (the Eq. 4 baseline).
    quadrature_order : Gauss–Legendre points per segment for Eqs 7 and 9 (SOCB only).
    solver : Newton settings (:class:`NewtonSolver`); default atol :func:`default_atol`
        (1e-12 on the dimensionless residual, raised to the round-off floor of long chains).
    continuation : load-ramp settings (:class:`ContinuationSettings`).
    initial_state : a state of the same model to start from (default: the unloaded
        straight state); the load is still ramped from zero, so pass the state that is in
        equilibrium at zero load, or use ``continuation=ContinuationSettings(initial_step=1.0)``.
    linear_solver : "dense" (``jax.jacfwd`` + LU: O(n²) memory, O(n³) time), "sparse"
        (colour-compressed Jacobian + sparse LU: O(n) per Newton iteration on chains and
        trees, see ``docs/scaling.md``) or "auto" (sparse above
        ``socbjax._linear.SPARSE_THRESHOLD`` = 1500 unknowns).  Ignored when ``solver``
        already carries a ``jacobian_solver``.
    throw : raise :class:`ConvergenceError` if the full load is not reached (default);
        with ``throw=False`` check ``Solution.converged``.

    Returns
    -------
    :class:`Solution`.
    """
    disc = make_model(network, model, quadrature_order=quadrature_order)
    loads = jnp.asarray(forces_array(network, forces)) + network.loads
    # atol as an array: a traced leaf, so networks of new lengths never recompile the solver
    solver = NewtonSolver(atol=jnp.asarray(default_atol(network))) if solver is None else solver
    settings = ContinuationSettings() if continuation is None else continuation
    state0 = disc.initial_state() if initial_state is None else initial_state
    if solver.jacobian_solver is None:
        solver = eqx.tree_at(lambda s: s.jacobian_solver, solver, prepare_jacobian_solver(disc, linear_solver),
                             is_leaf=lambda x: x is None)
    solution = _solve_jit(disc, model, loads, state0, solver, settings)
    if throw and not solution.converged:
        raise ConvergenceError(
            f"solve did not converge: {solution.status_message}; reached load factor "
            f"{float(solution.load_factor):.4g} of 1 after {int(solution.steps)} steps "
            f"({int(solution.cutbacks)} cut-backs), residual {float(solution.residual_norm):.2e}. "
            "Try more nodes, a smaller ContinuationSettings.initial_step, or throw=False to inspect."
            + _atol_hint(solver, network)
        )
    return solution


def _atol_hint(solver: NewtonSolver, network: Network) -> str:
    floor = default_atol(network, 0.0)
    if float(solver.atol) >= floor:
        return ""
    return (f" The Newton atol {float(solver.atol):.1e} is below this network's round-off floor {floor:.1e} "
            "(long filaments; see socbjax.default_atol): use NewtonSolver(atol=socbjax.default_atol(network)).")


def default_atol(network: Network, atol: float = 1e-12) -> float:
    """Newton tolerance on the dimensionless residual: ``atol``, or the round-off floor of
    the residual when that is larger.  A segment's position rows are differences of absolute
    node positions divided by its length ℓ, so they cannot be evaluated better than
    ε max|r| / ℓ (ε = 2.2e-16): 1.2e-12 measured for a 10 µm, 10,000-segment chain at its
    exact straight state.  The floor used is 16 ε max|r| / min ℓ (the 16 covers the few
    additions per row), e.g. 3.6e-11 for that chain and below 1e-12 up to ~300 segments."""
    pos = np.abs(np.asarray(network.positions))
    min_length = float(np.min(np.asarray(network.lengths)))
    floor = 16 * np.finfo(np.float64).eps * max(float(pos.max()), min_length) / min_length
    return max(float(atol), floor)


def prepare_jacobian_solver(disc, kind: str = "auto"):
    """The Jacobian solver (``None`` = Newton's own dense path) for ``disc``'s residual.

    Sparse patterns come from the network graph for SOCB (:mod:`socbjax._sparsity`, O(n))
    and from probing for the jointed model; they are computed with random loads on every
    node, so they hold for any forces, and are cached by network structure, so repeated
    solves with new parameter values reuse the same compiled code."""
    from ._linear import SparseJacobianSolver, jacobian_solver
    from ._sparsity import prepare_structured, structure_key

    x0, unravel = jax.flatten_util.ravel_pytree(disc.initial_state())
    backend = jacobian_solver(kind, x0.size)
    if not isinstance(backend, SparseJacobianSolver):
        return None
    net = disc.network
    random_loads = jnp.asarray(np.random.default_rng(0).normal(size=np.shape(net.positions)))
    frames = eqx.filter_jit(lambda d: d.frames(d.initial_state()))(disc)

    def fn(y):
        return disc.residual(unravel(y), random_loads, frames)

    if isinstance(disc, SOCBModel):
        return prepare_structured([fn], x0, disc.structure(), cache_key=structure_key(net, "solve"))
    return backend.prepare(fn, x0)


def _axial_jacobian(disc, axis, load):
    """Jacobian of the residual at the straight state under compressive axial ``load`` (pN)."""
    state = disc.initial_state()
    n_seg = disc.network.n_segments
    state = eqx.tree_at(lambda s: s.forces, state, jnp.tile(-load * axis, (n_seg, 1)))
    loads = jnp.zeros_like(disc.network.positions).at[-1].set(-load * axis)
    frames = disc.frames(state)
    x, unravel = jax.flatten_util.ravel_pytree(state)
    return jax.jacfwd(lambda y: disc.residual(unravel(y), loads, frames))(x)


_axial_jacobian_jit = eqx.filter_jit(_axial_jacobian)


def _smallest_positive(mu: np.ndarray) -> float | None:
    real = mu[(np.abs(mu.imag) <= 1e-7 * np.abs(mu)) & (mu.real > 0)].real
    return None if real.size == 0 else float(real.max())


def buckling_load(network: Network, *, model: str = "socb", quadrature_order: int = 8) -> float:
    """Smallest compressive axial force (pN) on the last node at which the straight state
    loses stability: the smallest P > 0 with a singular tangent stiffness J(P).

    The straight state is an exact solution of both models for any axial load P, and at it
    the Jacobian is a quadratic matrix polynomial J(P) = A + P B + P² C (the lever arm of
    Eq. 9 and the end curvature derivatives are each linear in the force).  A, B, C come from
    three evaluations; with μ = 1/P the quadratic eigenproblem μ² A + μ B + C is linearised
    (companion form) and solved densely; the largest real μ gives the smallest P.  A fourth
    evaluation checks the quadratic model, and a bisection on the sign of det J(P) polishes
    the root when it is not exact.  The axis is the line from the first to the last node.
    """
    disc = make_model(network, model, quadrature_order=quadrature_order)
    pos = np.asarray(network.positions)
    axis = pos[-1] - pos[0]
    if np.linalg.norm(axis) < 1e-12:
        raise ValueError("buckling_load needs a straight network whose first and last nodes differ")
    axis = jnp.asarray(axis / np.linalg.norm(axis))
    scale = float(np.mean(np.asarray(network.EI)) / network.total_length**2)

    def jac(load: float) -> np.ndarray:
        return np.asarray(_axial_jacobian_jit(disc, axis, jnp.asarray(load)))

    A, J1, J2, J3 = (jac(k * scale) for k in range(4))
    C = (J2 - 2 * J1 + A) / (2 * scale**2)
    B = (J1 - A) / scale - C * scale
    quadratic_error = np.abs(A + 3 * scale * B + 9 * scale**2 * C - J3).max() / np.abs(J3).max()
    n = A.shape[0]
    Ainv_B, Ainv_C = np.linalg.solve(A, B), np.linalg.solve(A, C)
    companion = np.block([[np.zeros((n, n)), np.eye(n)], [-Ainv_C, -Ainv_B]])
    mu = _smallest_positive(np.linalg.eigvals(companion))
    if mu is None:
        raise ValueError("no compressive buckling load found: the supports may not allow buckling")
    P = 1.0 / mu
    if quadratic_error > 1e-10:
        P = _bisect_singular(jac, P)
    return float(P)


def _bisect_singular(jac, P: float) -> float:
    """Polish a root of det J(P) by bisection in a bracket around the estimate ``P``."""

    def sign(load):
        return np.linalg.slogdet(jac(load))[0]

    for width in (1e-3, 1e-2, 1e-1):
        lo, hi = P * (1 - width), P * (1 + width)
        s_lo, s_hi = sign(lo), sign(hi)
        if s_lo != s_hi:
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if sign(mid) == s_lo:
                    lo = mid
                else:
                    hi = mid
                if hi - lo <= 1e-14 * hi:
                    break
            return 0.5 * (lo + hi)
    return P
