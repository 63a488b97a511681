"""The probe protocol's inputs and outputs, shared by :func:`socbjax.compress`, its sampled
form and :func:`socbjax.compress_ensemble`: the probe of a network, the applied loads
(perturbation), the compression settings and input checks, the observations of a recorded
path (probe and strand-end forces) and its events (limit points).  Units: µm, pN.
"""

from __future__ import annotations

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._checks import check_bool, check_choice, check_real, describe
from ._network import Network, add_direction, is_traced
from ._path import state_unravel
from ._path_settings import PROBE_PATH, PathSettings
from ._perturbation import default_perturbation, perturbation_pattern, perturbation_plan, strand_segments
from ._residual import Control, net_nodal_force, route_to_mothers, state_tangents, support_reactions
from ._result import PHASES, CompressionResult, LimitPoint
from ._solution import RESULTS, result_name

__all__ = ["probe_network", "probe_gap", "probe_frame", "applied_loads", "observe", "observe_rows", "compress_settings", "end_nodes",
           "check_compress_inputs", "check_compress_options", "crossing_exempt", "package_path", "parameters_json",
           "surface_crossing"]


def _is_chain(network: Network) -> bool:
    seg = network.segments
    return network.n_junctions == 0 and np.array_equal(seg, np.stack([np.arange(len(seg)), np.arange(1, len(seg) + 1)], 1))


def probe_network(network: Network) -> Network:
    """``network`` itself if it has probe nodes; for a single filament (e.g.
    :func:`socbjax.column`) the last node becomes the probe, moving toward the first node."""
    if network.has_probe:
        return network
    if not _is_chain(network):
        raise ValueError("the network has no probe nodes; build it with make_network(..., probe=[...]) or a builder "
                         "such as socbjax.dendritic_outcrop")
    if is_traced(network.positions):
        raise TypeError("a network without probe nodes needs concrete positions to place its probe (the probe "
                        "direction is topology); call socbjax.probe_network on it outside jax transformations")
    pos = np.asarray(network.positions)
    direction = (pos[0] - pos[-1]) / np.linalg.norm(pos[0] - pos[-1])
    projector = np.array(network.position_projector)
    projector[-1] = add_direction(projector[-1:], direction)[0]
    probe = np.zeros(network.n_nodes, bool)
    probe[-1] = True
    return network.with_topology(position_projector=projector, probe=probe, probe_direction=direction)


def end_nodes(network: Network) -> np.ndarray:
    """Supported non-probe nodes that are not daughter bases (strand ends on the surface).
    A padded network's strand ends are values that differ between its realisations, so
    its end nodes are those of the topology (host side: a static index list)."""
    fixed = np.einsum("nii->n", network.topology.position_projector) > 0.5
    return np.flatnonzero(fixed & ~network.probe & ~network.attached)


def probe_frame(network: Network):
    """(origin, gap) of the probe's frame: the reference position of the probe face, the
    probe nodes' mean moved back along the probe direction to the rearmost probe node (the
    face touches every held tip; they are coplanar in straight outcrops, not in thermally
    curved ones), and the height of the farthest opposing support along the probe direction
    (µm; None if nothing opposes the probe).  numpy for concrete positions, traced with
    traced ones; a padded network's gap is traced (its supports are values) and counts its
    active nodes only."""
    traced = is_traced(network.positions)
    xp = jnp if traced else np
    pos = network.positions if traced else np.asarray(network.positions)
    axis = np.asarray(network.probe_direction)
    origin = pos[network.probe].mean(axis=0)
    origin = origin + xp.min((pos[network.probe] - origin) @ axis) * axis
    if network.padding is not None:
        fixed = (jnp.einsum("nii->n", network.padding.projector) > 0.5) & ~network.probe & (network.padding.active > 0.5)
        heights = (pos - origin) @ jnp.asarray(network.probe_direction)
        return origin, jnp.max(jnp.where(fixed, heights, -jnp.inf))
    fixed = (np.einsum("nii->n", network.position_projector) > 0.5) & ~network.probe
    gap = ((pos[fixed] - origin) @ np.asarray(network.probe_direction)).max() if fixed.any() else None
    return origin, gap


def probe_gap(network: Network) -> float:
    """Largest probe travel (µm) before the probe meets the farthest opposing support (inf if
    none; host side, concrete positions)."""
    gap = probe_frame(network)[1]
    gap = np.inf if gap is None else float(gap)
    return np.inf if gap == -np.inf else gap  # -inf: a padded network without pins


# Nodes may sit this far beyond a plane before the crossing is flagged (µm, plus the same
# fraction of the gap): round-off of the equilibrium, never a visible penetration.
CROSSING_TOLERANCE = 1e-9


def surface_crossing(network: Network, positions, displacement):
    """[K] bool: row k has a node beyond the surface or behind the probe plane.

    Heights h are measured from the probe's reference position along the probe direction;
    the surface is the plane h = gap of the farthest opposing support (:func:`probe_gap`),
    the probe plane h = u (probe displacement of the row).  ``positions`` [K, N, d] (µm),
    ``displacement`` [K] (µm); numpy in, numpy out; JAX arrays (traced) in, JAX out.
    Computed without contact (``contact=None``) a crossing is a flagged status, never success
    (with contact it is the contact law's business: :func:`crossing_exempt`)."""
    padded = network.padding is not None
    xp = jnp if padded or is_traced(positions, displacement) or isinstance(positions, jax.Array) else np
    origin, gap = probe_frame(network)
    if gap is None:
        return xp.zeros(np.shape(displacement), bool)
    tol = CROSSING_TOLERANCE * (1.0 + xp.abs(gap))
    heights = (positions - origin) @ np.asarray(network.probe_direction)  # [K, N]
    active = network.padding.active > 0.5 if padded else True  # padding nodes may lie anywhere
    beyond_surface = xp.any((heights > gap + tol) & active, axis=-1)
    behind_probe = xp.any((heights < xp.asarray(displacement)[..., None] - tol) & active, axis=-1)
    return beyond_surface | behind_probe


def applied_loads(network: Network, perturbation) -> jax.Array:
    """The loads [N, d] (pN) compressions apply: the network's loads plus ``perturbation``
    (pN) on every strand's middle; with ``perturbation=None`` the network's loads, or, if it
    has none, the default 1e-4 EI/L² per strand.  Traced in all values (the choice between
    "has loads" and "default" is a traced select)."""
    if perturbation is not None and not is_traced(perturbation):
        value = np.asarray(perturbation, dtype=float)
        if value.shape != () or not np.isfinite(value) or value < 0:
            raise ValueError(f"perturbation must be a non-negative lateral force (pN), got {perturbation!r}")
    plan = perturbation_plan(network)
    pattern = perturbation_pattern(network.positions, plan, network.probe_direction, network.n_nodes)
    if perturbation is not None:
        return network.loads + jnp.asarray(perturbation, jnp.float64) * pattern
    default = default_perturbation(network.EI, network.lengths, strand_segments(network)) * pattern
    return jnp.where(jnp.any(network.loads != 0), network.loads, default)


def compress_settings(settings, method, displacement) -> PathSettings:
    """``settings`` (a PathSettings, or None) filled with the compression defaults; ``method``
    overrides; steps capped at a quarter of ``displacement``."""
    settings = PathSettings() if settings is None else settings
    if not isinstance(settings, PathSettings):
        raise TypeError(f"settings must be a socbjax.PathSettings, got {type(settings).__name__}")
    if method is not None:
        settings = settings.replace(method=method)
        if method not in ("displacement", "arclength"):
            raise ValueError(f"method must be 'displacement' or 'arclength', got {method!r}")
    if settings.initial_step is None and settings.max_step is not None and not is_traced(settings.max_step):
        # a max_step below the default first step: start at max_step (not an error about a value never given)
        settings = settings.replace(initial_step=min(float(PROBE_PATH["initial_step"]), float(settings.max_step)))
    if settings.corner_step is None and settings.method != "arclength":
        # corners only by default under arclength, whose corrector plane crosses the outgoing
        # path; at fixed displacement a corner step may land on another branch (a near-perfect
        # column's buckling is a corner at that scale: a fit's path then stopped with a fold)
        settings = settings.replace(corner_step=0.0)
    settings = settings.filled(**PROBE_PATH)
    if settings.method not in ("displacement", "arclength"):
        raise ValueError(f"method must be 'displacement' or 'arclength', got {settings.method!r}")
    if not is_traced(displacement) and settings.max_step > 0.25 * float(displacement):
        cap = 0.25 * float(displacement)
        initial = min(settings.initial_step, cap)
        settings = settings.replace(max_step=cap, initial_step=initial, min_step=min(settings.min_step, initial),
                                    corner_step=min(settings.corner_step, 1e-3 * cap))
    return settings


def check_compress_inputs(network, displacement, *, unload=False, method=None, perturbation=None, parameters=None,
                          throw=True, progress=False):
    """Validate the arguments of :func:`socbjax.compress` before any work (host side):
    (the network with its probe, the displacement as a float or a tracer).  ``TypeError``
    for a wrong type, ``ValueError`` for a wrong value, naming the argument.  The keyword
    arguments default to valid values, so callers that pass only the first two still work."""
    if not isinstance(network, Network):
        raise TypeError(f"network must be a socbjax Network (e.g. socbjax.column(...)), got {type(network).__name__}")
    check_compress_options(unload=unload, method=method, perturbation=perturbation, parameters=parameters, throw=throw,
                           progress=progress)
    network = probe_network(network)
    if is_traced(displacement):
        return network, displacement
    u = check_real("displacement", displacement, "µm of probe travel", low=0.0)
    if not is_traced(network.positions):
        gap = probe_gap(network)
        if not np.isfinite(gap):
            raise ValueError("nothing supports the network opposite the probe (no fixed node other than probe nodes): "
                             "compressing it would only translate it; e.g. grow the outcrop until strands reach the surface")
        if u >= gap:
            raise ValueError(f"displacement {u} µm reaches the opposing support (gap {gap:.4g} µm between probe and "
                             "surface); choose a smaller displacement")
    return network, u


def check_compress_options(*, unload=False, method=None, perturbation=None, parameters=None, throw=True, progress=False):
    """The protocol options of :func:`socbjax.compress`: ``unload``/``throw`` bools,
    ``method`` None/"displacement"/"arclength", ``perturbation`` None or a finite force
    >= 0 (pN; may be traced), ``progress`` a bool or a callable, ``parameters`` None or a
    dict with string keys whose values JSON can store (no NaN or infinity: the result's
    metadata must be valid JSON)."""
    check_bool("unload", unload)
    check_bool("throw", throw)
    check_choice("method", method, ("displacement", "arclength"), allow_none=True)
    if perturbation is not None:
        check_real("perturbation", perturbation, "pN", low=0.0, low_open=False)
    if not (isinstance(progress, (bool, np.bool_)) or callable(progress)):
        raise TypeError(f"progress must be True, False or a callable progress(phase, u, steps, done), got "
                        f"{describe(progress)}")
    if parameters is None:
        return
    if not isinstance(parameters, dict):
        raise TypeError(f"parameters must be a dict of JSON-able metadata (or None), got {describe(parameters)}")
    bad = [k for k in parameters if not isinstance(k, str)]
    if bad:
        raise TypeError(f"parameters keys must be strings (they become JSON object keys), got {bad[0]!r}")
    try:
        json.dumps(json.loads(parameters_json(parameters)), allow_nan=False)
    except (TypeError, ValueError, OverflowError) as err:
        raise ValueError(f"parameters must hold JSON-able values (numbers, strings, lists, dicts, None; no NaN or "
                         f"infinity): {err}") from None


@eqx.filter_jit
def observe(model, X, loads, U=None):
    """Per row of flat states X [K, n] (probe displacements U [K] µm, for the moving probe
    face of contact): positions, tangents, moments, segment forces, probe force (compressive
    positive; with contact the probe face's contact forces included), the axial force at
    every node, the material-frame angles ψ [N] (rad) of a twisting network ([0] otherwise),
    and the contact outputs: count, minimum gap (µm; NaN without obstacles), total contact
    force (pN, the sum of the magnitudes), contact points [c, d] (µm) and forces [c, d] (pN)
    of the c = S·C slots (zero force: not in contact); last, the support reactions [N, d] (pN,
    the force each support exerts on its node; zero at free nodes)."""
    net = model.network
    unravel = state_unravel(model)
    U = jnp.zeros(X.shape[0]) if U is None else jnp.asarray(U)
    contact = getattr(model, "contact", None)
    axis = jnp.asarray(net.probe_direction)

    def one(x, u):
        st = unravel(x)
        twists = getattr(st, "twists", jnp.zeros(0))  # the jointed baseline has no frame angles
        face = jnp.zeros(())  # the probe face's contact forces along the axis
        if contact is None:
            imbalance = net_nodal_force(st.forces, net, loads)
            empty = jnp.zeros((0, net.dim))
            outputs = (jnp.zeros((), jnp.int32), jnp.asarray(jnp.nan), jnp.zeros(()), empty, empty)
        else:  # one evaluation of the contact kernel gives the slots and the segments' end forces
            points, gaps, F, counted, end_forces, extra = model.contact_geometry(st, Control.make(1.0, u))
            imbalance = net_nodal_force(st.forces, net, loads + extra, end_forces)
            # the law's force is on (and not handed over to a neighbouring segment's slot)
            touching = counted & (gaps < contact.activation) & (jnp.linalg.norm(F, axis=-1) > 1e-9 * contact.force_scale)
            F = jnp.where(touching[..., None], F, 0.0)  # not round-off of a zero force
            C = model.n_obstacles
            if C:
                on_slots = F[: net.n_segments * C].reshape(net.n_segments, C, -1) @ axis
                face = jnp.sum(jnp.where(contact.moving[None, :] > 0, on_slots, 0.0))
            lowest = jnp.min(jnp.where(counted, gaps, jnp.inf)) if gaps.size else jnp.asarray(jnp.nan)
            outputs = (jnp.sum(touching).astype(jnp.int32), lowest, jnp.sum(jnp.linalg.norm(F, axis=-1)), points, F)
        axial = route_to_mothers(imbalance, net) @ axis
        probe = jnp.sum(jnp.where(net.probe, axial, 0.0)) + face
        return (st.positions, state_tangents(st.directors, net.dim), st.moments, st.forces, probe, -axial, twists,
                *outputs, support_reactions(imbalance, net))

    return jax.vmap(one)(X, U)


def _limit_points(U, F, SIGN, PHASE) -> tuple[LimitPoint, ...]:
    """Events between consecutive recorded steps of each phase (see :class:`LimitPoint`)."""
    events = []
    for phase in (1, 2):
        idx = np.flatnonzero(PHASE == phase)
        if not idx.size or idx[0] == 0:
            continue
        idx = np.concatenate([[idx[0] - 1], idx])  # start from the phase's first point
        du, dF = np.diff(U[idx]), np.diff(F[idx])
        tiny = 1e-9 * max(float(np.abs(F[idx]).max()), 1e-300)
        su = np.sign(np.where(np.abs(du) > 1e-12, du, 0.0))
        sF = np.sign(np.where(np.abs(dF) > tiny, dF, 0.0))  # force rising or falling along the path
        folds = set()
        for j in range(1, len(du)):
            at = int(idx[j])
            if su[j] * su[j - 1] < 0:
                folds.add(at)
                events.append(LimitPoint("fold", at, float(U[at]), float(F[at]), PHASES[phase]))
            elif sF[j] * sF[j - 1] < 0:
                kind = "force_maximum" if sF[j - 1] > 0 else "force_minimum"
                events.append(LimitPoint(kind, at, float(U[at]), float(F[at]), PHASES[phase]))
        for j in range(len(du)):
            a, b = int(idx[j]), int(idx[j + 1])
            if SIGN[a] != SIGN[b] and not folds & {a, b}:
                events.append(LimitPoint("bifurcation", b, float(U[b]), float(F[b]), PHASES[phase]))
    return tuple(sorted(events, key=lambda e: e.step))


def parameters_json(params: dict) -> str:
    return json.dumps(params, default=lambda o: o.tolist() if hasattr(o, "tolist") else float(o), sort_keys=True)


# Rows observed per compiled call: observe holds every row's contact kernel at once, and the
# whole step buffer (3,001 rows for a loading and unloading path) of the 8-generation outcrop
# with self-contact asked for 45.5 GB.
OBSERVE_CHUNK = 64


def observe_rows(model, X: np.ndarray, capacity: int, U: np.ndarray | None = None):
    """:func:`observe` of the K rows of X [K, n] (host; probe displacements U [K] µm), in
    chunks of min(``capacity``, OBSERVE_CHUNK) rows (the last one padded with the last row),
    so that paths of any length share one compiled program and the memory stays bounded."""
    K = X.shape[0]
    size = max(min(capacity, OBSERVE_CHUNK), 1)
    u = np.zeros(K) if U is None else np.asarray(U, float)
    parts = []
    for start in range(0, K, size):
        rows = np.arange(start, start + size).clip(max=K - 1)
        out = observe(model, jnp.asarray(X[rows]), model.network.loads, jnp.asarray(u[rows]))
        parts.append([np.asarray(a)[:min(size, K - start)] for a in out])
    return [np.concatenate(chunk) for chunk in zip(*parts)]


def crossing_exempt(model) -> bool:
    """Whether the path was computed with contact, so that a node beyond the probe plane or the
    substrate plane is no failure: with ``surfaces=False`` the user says there are no probe
    face and substrate; with ``surfaces=True`` the contact law keeps every filament out of them
    (they lie d/2 + δ beyond the anchored tips and bases, so an axis may come δ past those
    planes; ``min_gap`` reports any penetration)."""
    return getattr(model, "contact", None) is not None


def package_path(model, rec, extra, result, settings, u_max, unload, parameters) -> CompressionResult:
    net = model.network
    capacity = settings.max_steps * (3 if unload else 2) + 1  # settle point + every phase's buffer
    observed = observe_rows(model, rec["X"], capacity, np.asarray(rec["U"]))
    positions, tangents, moments, forces, probe_force, axial, twists = observed[:7]
    count, min_gap, contact_force, contact_points, contact_forces, reactions = observed[7:]
    ends = end_nodes(net)
    sign_ref = extra.get("sign_ref", rec["SIGN"][0])
    params = {"displacement_um": u_max, "unload": bool(unload), "method": settings.method, "sampled": False,
              "quadrature_order": settings.quadrature_order, "settled_displacement_um": float(extra.get("u0", 0.0)),
              "perturbation_pN": float(np.abs(np.asarray(net.loads)).sum(axis=-1).max()),
              "settings": {f: getattr(settings, f) for f in settings.__dataclass_fields__},
              "n_nodes": int(net.n_nodes), "n_segments": int(net.n_segments), "n_junctions": int(net.n_junctions),
              "gap_um": probe_gap(net) if np.isfinite(probe_gap(net)) else None, **(parameters or {})}
    crossed = np.flatnonzero(surface_crossing(net, positions, np.asarray(rec["U"])))
    if crossing_exempt(model):
        crossed = crossed[:0]
    events = _limit_points(np.asarray(rec["U"]), probe_force, rec["SIGN"], rec["PHASE"])
    if crossed.size:
        k = int(crossed[0])
        events = tuple(sorted(events + (LimitPoint("surface_crossing", k, float(rec["U"][k]), float(probe_force[k]),
                                                   PHASES[int(rec["PHASE"][k])]),), key=lambda e: e.step))
        if result_name(result) == "successful":
            result = RESULTS.surface_crossed
    return CompressionResult(
        displacement=np.asarray(rec["U"]), force=probe_force, converged=np.ones(len(rec["U"]), bool),
        stable=rec["SIGN"] == sign_ref, phase=rec["PHASE"].astype(np.int8), positions=positions, tangents=tangents,
        moments=moments, segment_forces=forces, twists=twists, end_nodes=ends, end_forces=axial[:, ends],
        iterations=rec["ITER"].astype(np.int32), contact_count=count, min_gap=min_gap, contact_force=contact_force,
        contact_points=contact_points, contact_forces=contact_forces, reactions=reactions, result=result, network=net,
        limit_points=events, parameters_json=parameters_json(params),
    )


