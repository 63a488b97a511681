"""Static equilibrium under nodal loads: :func:`solve`.

The loads (nodal forces and couples) are ramped by a load factor λ: 0 → 1 with the path
engine (:func:`socbjax._path.follow_path`, natural parameter, Euler tangent predictor,
Newton corrector, automatic cut-back, critical-point detection).  The equilibrium at the end
is differentiated by the implicit function theorem (:class:`socbjax.ImplicitAdjoint`: one linear
solve per direction at the converged state, never through the ramp or the Newton
iterations), so :func:`solve` works under ``jax.jit``, ``jax.grad``/``jax.jacrev``,
``jax.jacfwd`` and ``jax.vmap`` with respect to every value of the network (EI, lengths,
positions, loads, couples) and of the applied loads.
"""

from __future__ import annotations

from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.flatten_util import ravel_pytree

from ._adjoint import ImplicitAdjoint
from ._checks import check_array, check_bool, check_int, check_real, describe
from ._contact import Contact
from ._contact_model import contact_setup
from ._equilibrium import Solution, node_angles_and_curvatures
from ._jointed import JointedModel
from ._network import Network, is_traced
from ._path import NoRecorder, PathProblem, follow_path, position_weights, start_path, state_template
from ._path_settings import LOAD_RAMP, MAX_QUADRATURE_ORDER, PathSettings
from ._quadrature import get_quadrature
from ._residual import Control, SOCBModel, net_nodal_force, support_reactions
from ._solution import RESULTS, ConvergenceError, result_message
from ._sparsity import linear_solver_for

__all__ = ["solve", "default_atol", "make_model", "nodal_forces", "nodal_couples", "MODELS", "implicit_adjoint"]

MODELS = ("socb", "jointed")


def make_model(network: Network, model: str = "socb", *, quadrature_order: int = 8, contact: Contact | None = None):
    """The discretisation of ``network``: "socb" (:class:`SOCBModel`, with ``contact``: a
    :class:`socbjax.Contact` or None) or "jointed" (no contact)."""
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network (e.g. socbjax.cantilever(...)), got {type(network).__name__}")
    if not isinstance(model, str):
        raise TypeError(f"model must be one of {MODELS} (a string), got {describe(model)}")
    quadrature_order = check_int("quadrature_order", quadrature_order, minimum=2, maximum=MAX_QUADRATURE_ORDER)
    if model == "socb":
        return SOCBModel(network, get_quadrature(quadrature_order), contact_setup(network, contact))
    if contact is not None:
        raise ValueError(f"contact is built for model='socb' only, got model={model!r} with contact")
    if model == "jointed":
        if network.n_junctions or network.has_probe:
            raise ValueError("the jointed baseline supports single filaments only (no branch junctions or probe); "
                             "use model='socb'")
        if network.twisting:
            raise ValueError("the jointed baseline is torsion-free; a network built with GJ= needs model='socb'")
        return JointedModel(network)
    raise ValueError(f"unknown model {model!r}; use one of {MODELS}")


def _node_key(key, n: int, what: str) -> int:
    if isinstance(key, bool) or not isinstance(key, (int, np.integer)):
        raise TypeError(f"{what} keys must be integer node indices, got {key!r}")
    if not -n <= key < n:
        raise ValueError(f"{what} applied to node {key}, but the network has {n} nodes (valid: {-n}..{n - 1})")
    return int(key)


def _nodal(values, shape: tuple, what: str, unit: str, dim: int):
    """A {node: value} mapping or an array of ``shape``: a numpy array for concrete values
    (no device dispatch on the host path of a solve), a jax array where any is traced."""
    n = shape[0]
    width = shape[1:]
    if values is None:
        return np.zeros(shape)
    entries = values.values() if isinstance(values, Mapping) else [values]
    xp = jnp if any(is_traced(v) or isinstance(v, jax.Array) for v in entries) else np
    if isinstance(values, Mapping):
        out = xp.zeros(shape)
        for key, vec in values.items():
            node = _node_key(key, n, what)
            v = xp.asarray(vec, np.float64) if xp is jnp else check_array(f"{what}[{key}]", vec, unit)
            if v.size != int(np.prod(width, dtype=int)) or (v.ndim > 1 if width else v.ndim > 0):
                expected = "a scalar" if not width else f"{width[0]} components"
                raise ValueError(f"{what} on node {key} must be {expected} (dim={dim}), got shape {np.shape(vec)}")
            out = out.at[node].add(v.reshape(width)) if xp is jnp else _add_at(out, node, v.reshape(width))
    else:
        out = xp.asarray(values, np.float64) if xp is jnp else check_array(what, values, unit)
        if out.shape != shape:
            raise ValueError(f"{what} array must have shape {shape} ({unit}), got {out.shape}")
    if not is_traced(out) and not bool(np.all(np.isfinite(np.asarray(out)))):
        raise ValueError(f"{what} contain NaN or infinite values; give finite {unit}")
    return out


def _add_at(out: np.ndarray, node: int, value: np.ndarray) -> np.ndarray:
    out[node] += value
    return out


def nodal_forces(network: Network, forces) -> jax.Array:
    """``forces`` ({node index: vector} or array [N, d], pN) as an array [N, d]."""
    return _nodal(forces, (network.n_nodes, network.dim), "forces", "pN", network.dim)


def nodal_couples(network: Network, couples) -> jax.Array:
    """``couples`` ({node: moment}: a scalar in 2D, a vector in 3D; or an array [N] / [N, 3],
    pN·µm) as an array of the network's ``couples`` shape."""
    return _nodal(couples, network.couples.shape, "couples", "pN·µm", network.dim)


def default_atol(network: Network, atol: float = 1e-12):
    """Newton tolerance on the dimensionless residual: ``atol``, or the round-off floor of
    the residual when that is larger.  A segment's position rows are differences of absolute
    node positions divided by its length ℓ, so they cannot be evaluated better than
    ε max|r| / ℓ (ε = 2.2e-16): 1.2e-12 measured for a 10 µm, 10,000-segment chain at its
    exact straight state.  The floor used is 16 ε max|r| / min ℓ (the 16 covers the few
    additions per row), e.g. 3.6e-11 for that chain and below 1e-12 up to ~300 segments.
    A float for concrete networks, a JAX scalar where positions or lengths are traced."""
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network (e.g. socbjax.cantilever(...)), got {type(network).__name__}")
    atol = check_real("atol", atol, "dimensionless residual", low=0.0, low_open=False)
    xp = jnp if is_traced(network.positions, network.lengths, atol) else np  # concrete: no device dispatch
    min_length = xp.min(network.lengths)
    scale = xp.maximum(xp.max(xp.abs(network.positions)), min_length)
    floor = xp.maximum(atol, 16 * np.finfo(np.float64).eps * scale / min_length)
    return jax.lax.stop_gradient(floor) if xp is jnp else floor


def implicit_adjoint(adjoint, inner) -> ImplicitAdjoint:
    """The adjoint of an entry point: ``adjoint`` with the forward solver ``inner`` where it
    names none (an ``optx.ImplicitAdjoint`` is taken as socbjax's, with ``inner``)."""
    if isinstance(adjoint, optx.ImplicitAdjoint):
        return ImplicitAdjoint(inner)
    if not isinstance(adjoint, ImplicitAdjoint):
        raise TypeError(f"adjoint must be a socbjax.ImplicitAdjoint (socbjax differentiates equilibria by the implicit "
                        f"function theorem, never through the iterations), got {type(adjoint).__name__}")
    return adjoint.with_solver(inner)


def _ramp_primal(inputs):
    model, state0, settings, inner, _while_loop = inputs
    x0, _ = ravel_pytree(state0)
    problem = PathProblem(model, Control.make(0.0), Control.make(1.0), jnp.zeros(x0.size + 1).at[-1].set(1.0),
                          position_weights(model))
    final = follow_path(problem, start_path(x0, 0.0, settings, NoRecorder()), settings, inner, NoRecorder())
    stats = (final.result, final.p, final.steps, final.cutbacks, final.iterations, final.residual_norm)
    return final.x, stats


def _ramp_rewrite(x, stats, inputs):
    model, state0, _, _, _ = inputs
    _, unravel = ravel_pytree(state0)
    state = unravel(x)
    frames = jax.lax.stop_gradient(model.frames(state))
    return model.residual(state, Control.make(stats[1]), frames)  # F(x; λ reached) = 0


def _package(model, x, stats, state0) -> Solution:
    net = model.network
    state = ravel_pytree(state0)[1](x)
    result, load_factor, steps, cutbacks, iterations, residual_norm = stats
    tangents, moments = model.tangents(state), model.node_moments(state)
    angles, curvatures = node_angles_and_curvatures(net, tangents, moments)
    if net.dim == 2 and isinstance(model, SOCBModel):
        angles = state.directors  # the unknowns themselves: unwrapped beyond ±π where the filament turns
    end_forces, contact_loads = model.contact_ends(state) if isinstance(model, SOCBModel) else (None, 0.0)
    reactions = support_reactions(net_nodal_force(state.forces, net, load_factor * net.loads + contact_loads, end_forces),
                                  net)
    return Solution(positions=state.positions, tangents=tangents, angles=angles, moments=moments, curvatures=curvatures,
                    segment_forces=state.forces, reactions=reactions, result=result, iterations=iterations, steps=steps,
                    cutbacks=cutbacks, residual_norm=residual_norm, load_factor=load_factor, state=state, network=net,
                    model=model.name)


@eqx.filter_jit
def _solve(model, state0, settings, inner, adjoint):
    state0 = model.initial_state() if state0 is None else state0
    x, stats = adjoint.apply(_ramp_primal, _ramp_rewrite, (model, state0, settings, inner), tags=frozenset())
    return _package(model, x, stats, state0)


def _settings(settings, network) -> PathSettings:
    settings = PathSettings() if settings is None else settings
    if not isinstance(settings, PathSettings):
        raise TypeError(f"settings must be a socbjax.PathSettings, got {type(settings).__name__}")
    if settings.method not in (None, "natural", "load"):
        raise ValueError(f"solve ramps the load with natural-parameter continuation; PathSettings.method must be "
                         f"None, 'natural' or 'load', got {settings.method!r}")
    return settings.filled(**LOAD_RAMP, atol=default_atol(network))


def solve(network: Network, forces=None, couples=None, *, model: str = "socb", settings: PathSettings | None = None,
          initial_state=None, adjoint: ImplicitAdjoint = ImplicitAdjoint(), throw: bool = True,
          contact: Contact | None = None) -> Solution:
    """Static equilibrium of ``network`` under fixed-direction nodal ``forces`` and ``couples``.

    Parameters
    ----------
    network : from :func:`socbjax.cantilever`, :func:`socbjax.column`, ... (values may be traced).
    forces : {node index: force vector (pN)} (negative indices allowed) or an array [N, d];
        added to the network's own ``loads``.
    couples : {node index: couple (pN·µm)} — a scalar in 2D, a vector in 3D (its component
        along the filament, a twist, is not carried by the torsion-free rod) — or an array
        [N] / [N, 3]; added to the network's own ``couples``.  Forces and couples are ramped
        together from zero.
    model : "socb" (the SOCB method) or "jointed" (the Eq. 4 baseline).
    settings : :class:`socbjax.PathSettings` of the load ramp (steps as load fractions:
        initial 0.25, max 1.0, ...), the Newton tolerance (default :func:`default_atol`),
        ``linear_solver`` ("auto": sparse above 1,500 unknowns) and ``quadrature_order``.
    initial_state : a state of the same model, in equilibrium at zero load, to start from
        (default: the unloaded straight state).
    adjoint : how derivatives are computed: :class:`socbjax.ImplicitAdjoint` (the implicit
        function theorem at the solution, with the dense or sparse solver of the solve).
    throw : raise :class:`socbjax.ConvergenceError` (an ``equinox`` runtime error under
        ``jax.jit``) if the full load is not reached (default); with ``throw=False`` check
        ``Solution.result`` / ``Solution.converged``.
    contact : None (no contact, the default) or a :class:`socbjax.Contact`: rigid frictionless
        planes and spheres that the filament's smooth curve may not cross (2D networks).

    Returns a :class:`socbjax.Solution` (an ``eqx.Module``: ``jax.jit`` can return it).
    """
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network (e.g. socbjax.cantilever(...)), got {type(network).__name__}")
    throw = check_bool("throw", throw)
    if not isinstance(model, str):
        raise TypeError(f"model must be one of {MODELS} (a string), got {describe(model)}")
    settings = _settings(settings, network)
    loaded = network.replace(loads=network.loads + nodal_forces(network, forces),
                             couples=network.couples + nodal_couples(network, couples))
    disc = make_model(loaded, model, quadrature_order=settings.quadrature_order, contact=contact)
    inner = linear_solver_for(disc, settings.linear_solver)
    if initial_state is not None and (jax.tree_util.tree_structure(initial_state)
                                      != jax.tree_util.tree_structure(state_template(disc))):
        raise TypeError(f"initial_state must be a state of the {model} model of this network "
                        f"(e.g. an earlier Solution.state), got {type(initial_state).__name__}")
    if initial_state is None and contact is not None and not is_traced(disc.network):
        # the contact start is checked on the host (initial_state(check=True) raises, naming
        # the two pieces, where they start inside the law's range); traced networks settle inside
        initial_state = disc.initial_state(check=True)
    solution = _solve(disc, initial_state, settings.traced(), inner, implicit_adjoint(adjoint, inner))
    if throw:
        return _check(solution, settings, network)
    return solution


def _check(solution: Solution, settings: PathSettings, network: Network) -> Solution:
    failed = solution.result != RESULTS.successful
    if is_traced(solution):
        return solution.result.error_if(solution, failed)
    if bool(failed):
        raise ConvergenceError(
            f"solve did not converge: {result_message(solution.result)}; reached load factor "
            f"{float(solution.load_factor):.4g} of 1 after {int(solution.steps)} step{'' if int(solution.steps) == 1 else 's'} "
            f"({int(solution.cutbacks)} cut-back{'' if int(solution.cutbacks) == 1 else 's'}), residual {float(solution.residual_norm):.2e}. "
            "Try more nodes, a smaller PathSettings(initial_step=...), or throw=False to inspect."
            + _atol_hint(settings, network)
        )
    return solution


def _atol_hint(settings: PathSettings, network: Network) -> str:
    floor = float(default_atol(network, 0.0))
    if float(settings.atol) >= floor:
        return ""
    return (f" The Newton atol {float(settings.atol):.1e} is below this network's round-off floor {floor:.1e} "
            "(long filaments; see socbjax.default_atol): use PathSettings(atol=socbjax.default_atol(network)).")
