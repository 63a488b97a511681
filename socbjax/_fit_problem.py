"""The least-squares problem of a fit: data, parameters, model and residuals (:func:`fit_problem`).

For parameter values θ the predicted force at a data compression cᵢ (µm) is

    F̂ᵢ = force_scale · F(cᵢ + contact_offset; θ) + baseline,   F = 0 before contact,

where F(u; θ) is the probe force of the model (:mod:`socbjax._models`) at probe
displacement u, computed by :func:`socbjax.compress` with ``at=`` the data compressions: the
path is followed adaptively through buckling and collapse, and every data point is then
solved *exactly* (no interpolation across a sharp force drop), with derivatives by the
implicit function theorem.  The residuals (F̂ᵢ − Fᵢ)/σᵢ are a traced JAX function of the
unconstrained parameters z (bounds by transforms, :class:`socbjax.Parameter`), so ``jax.jit``,
``jax.grad``, ``jax.jacfwd`` and ``jax.vmap`` apply to any loss built from them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax.numpy as jnp
import numpy as np

from ._afm import ForceCurve
from ._compress import compress
from ._models import FitModel, make_fit_model
from ._parameters import NUISANCE_PARAMETERS, Parameter
from ._path import PathSettings

__all__ = ["FitProblem", "fit_problem", "BRANCHES"]

BRANCHES = ("loading", "unloading")


@dataclasses.dataclass(frozen=True)
class FitProblem:
    """Everything :func:`socbjax.fit` optimises (see :func:`fit_problem`).

    residuals : z [p] -> r [m] = (model − data)/σ, traced and differentiable; NaN where the
        path cannot be followed (``throw=True``: raise instead, untraced).
    to_values : z -> {name: value} (free and fixed parameters, in their units).
    z0 : [p] the unconstrained start; free : the free names, in the order of z.
    compression, force, sigma : [m] the data fitted (µm, pN, pN).
    table : name -> :class:`socbjax.Parameter` (with the fit's bounds); fixed : fixed values.
    model : the :class:`socbjax.FitModel`; reach : the largest probe travel needed (µm).
    """

    residuals: Callable
    to_values: Callable
    z0: jnp.ndarray
    free: tuple
    fixed: dict
    compression: np.ndarray
    force: np.ndarray
    sigma: np.ndarray
    table: dict
    model: FitModel
    reach: float


def _data(curve, branch: str, max_points: int, min_compression):
    if isinstance(curve, ForceCurve):
        segment = 0 if branch == "loading" else 1
        part = curve if np.all(curve.segment == segment) else (curve.approach if segment == 0 else curve.retract)
        if len(part) == 0 or part.compression.max() <= 0:
            raise ValueError(f"the {branch} branch never passes the contact point (no compression > 0): nothing to fit")
        low = -0.25 * part.compression.max() if min_compression is None else float(min_compression)
        part = part.select(min_compression=low)
        if len(part) > max_points:
            part = part.binned(max_points)
        c, F = np.asarray(part.compression, float), np.asarray(part.force, float)
    else:
        try:
            c, F = (np.asarray(a, float) for a in curve)
        except (TypeError, ValueError) as err:
            raise TypeError("curve must be a socbjax.ForceCurve or a pair (compression µm, force pN)") from err
        if c.ndim != 1 or c.shape != F.shape:
            raise ValueError(f"compression and force must be 1-D arrays of equal length, got {c.shape} and {F.shape}")
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(F))):
            bad = int(np.sum(~np.isfinite(c)) + np.sum(~np.isfinite(F)))
            raise ValueError(f"the curve contains {bad} NaN/inf values; drop those points before fitting")
        if c.size and np.any(np.diff(c) < 0):
            raise ValueError(
                "compression must be non-decreasing along the curve (one branch, sorted); sort the points, or load "
                "a measured curve with socbjax.load_curve, which separates approach and retract"
            )
        if min_compression is not None:
            keep = c >= float(min_compression)
            c, F = c[keep], F[keep]
    if c.size < 3:
        raise ValueError(f"the {branch} branch has {c.size} points; a fit needs at least 3")
    if c.max() <= 0:
        raise ValueError("the curve never passes the contact point (all compressions ≤ 0): nothing to fit")
    return c, F


def _parameter_table(model: FitModel, free, fixed, initial, bounds) -> tuple[dict[str, Parameter], tuple, dict, dict]:
    table = {**model.parameters, **NUISANCE_PARAMETERS}
    free = tuple(free.split(",")) if isinstance(free, str) else tuple(free)
    fixed, initial, bounds = dict(fixed or {}), dict(initial or {}), dict(bounds or {})
    for name in (*free, *fixed, *initial, *bounds):
        if name not in table:
            raise ValueError(f"unknown parameter {name!r} for model {model.name}; known: {sorted(table)}")
    if not free:
        raise ValueError("no free parameters: name at least one in free=, e.g. free=('EI',)")
    both = set(free) & set(fixed)
    if both or len(set(free)) != len(free):
        raise ValueError(f"parameters listed twice or both free and fixed: {sorted(both) or free}")
    for name, (lo, hi) in bounds.items():
        table[name] = table[name].with_bounds(lo, hi)
    for name in initial:
        if name not in free:
            raise ValueError(f"initial value given for {name!r}, which is not free; use fixed= for fixed values")
    fixed = {n: table[n].check(v, "fixed value") for n, v in fixed.items()}
    start = {n: table[n].check(initial.get(n, table[n].value), "initial value") for n in free}
    return table, free, fixed, start


def _check_identifiable(model: FitModel, free, fixed) -> None:
    if "force_scale" not in free:
        return
    source = np.full(model.base.n_segments, "EI", dtype=object)  # the parameter each segment's EI comes from
    for name, mask in model.groups.items():
        if name in free or name in fixed:
            source[mask] = name
    ei_free = sorted(set(source) & set(free))
    if all(name in free for name in source):
        raise ValueError(
            f"force_scale and {', '.join(ei_free)} are not separately identifiable from one curve: at fixed geometry "
            "the force scales with EI (exactly with the default perturbation, which scales with EI), "
            "F ∝ EI × force_scale, so only their product is determined. "
            "Fix one of them, e.g. fixed={'force_scale': 1.0} (one outcrop under the probe) or fix EI"
        )


# ----------------------------------------------------------------------- the residuals
def _sigma(sigma, m: int, curve) -> np.ndarray:
    """Per-point force uncertainty [m] (pN): 1 (unweighted), a scalar, or one per point."""
    if sigma is None:
        return np.ones(m)
    s = np.asarray(sigma, float)
    if s.ndim == 1 and isinstance(curve, ForceCurve) and s.size != m:
        raise ValueError("per-point sigma needs the curve as (compression, force) arrays (ForceCurves may be binned)")
    s = np.broadcast_to(s, (m,)) if s.ndim == 0 else s
    if s.shape != (m,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise ValueError(f"sigma must be positive and finite, a scalar or one value per point ({m}), got shape {s.shape}")
    return np.array(s)


def fit_problem(curve, model="unit-mesh", *, free=("EI",), fixed=None, initial=None, bounds=None, sigma=None,
                branch: str = "loading", max_points: int = 80, min_compression=None, method: str = "displacement",
                path: PathSettings | None = None, model_options=None) -> FitProblem:
    """Everything :func:`socbjax.fit` optimises, checked and assembled (no optimisation): a
    :class:`FitProblem`.  Useful to evaluate the loss or its gradient at chosen values (e.g.
    to check gradients).  ``branch``, ``max_points``, ``min_compression``, ``method`` and
    ``path`` are those of :class:`socbjax.FitSettings`; other arguments as for
    :func:`socbjax.fit`."""
    if branch not in BRANCHES:
        raise ValueError(f"branch must be one of {BRANCHES}, got {branch!r}")
    if isinstance(max_points, bool) or int(max_points) != max_points or max_points < 3:
        raise ValueError(f"max_points must be an integer of at least 3, got {max_points!r}")
    model = make_fit_model(model, **(model_options or {}))
    free = tuple(n.strip() for n in free.split(",")) if isinstance(free, str) else tuple(free)
    c, F = _data(curve, branch, int(max_points), min_compression)
    bounds = dict(bounds or {})
    if "contact_offset" in free and "contact_offset" not in bounds:
        # the offset moves the contact point within the data's own range: beyond it the model
        # would be sampled past the data (or entirely before contact) and the fit is degenerate
        bounds["contact_offset"] = (-0.5 * float(c.max()), 0.1 * float(c.max()))
    table, free, fixed, start = _parameter_table(model, free, fixed, initial, bounds)
    _check_identifiable(model, free, fixed)
    offset_room = max(0.0, table["contact_offset"].upper or 0.0) if "contact_offset" in free else 0.0
    reach = float(c.max()) + max(fixed.get("contact_offset", start.get("contact_offset", 0.0)), 0.0) + offset_room
    if reach >= model.gap:
        raise ValueError(
            f"the curve reaches {float(c.max()):.4g} µm of compression (plus contact offset), but the {model.name} model "
            f"can be compressed by less than {model.gap:.4g} µm (probe–surface gap); crop the curve, e.g. "
            f"curve.select(max_compression={0.9 * model.gap:.3g}), or use a model with a larger gap"
        )
    physical = [n for n in (*free, *fixed) if n in model.parameters]

    def to_values(z):
        values = {n: table[n].to_value(z[i]) for i, n in enumerate(free)}
        return {**fixed, **values}

    sigma = _sigma(sigma, c.size, curve)
    c_j, F_j, sigma_j = jnp.asarray(c), jnp.asarray(F), jnp.asarray(sigma)
    unload = branch == "unloading"
    floor = 1e-6 * reach

    def residuals(z, throw: bool = False):
        values = to_values(z)
        network = model.network({n: values[n] for n in physical})
        u = c_j + values.get("contact_offset", 0.0)
        result = compress(network, reach, at=jnp.clip(u, floor, reach), unload=unload, method=method,
                          settings=path, perturbation=values.get("perturbation"), throw=throw)
        force = result.force[c.size:][::-1] if unload else result.force
        predicted = values.get("force_scale", 1.0) * jnp.where(u > 0, force, 0.0) + values.get("baseline", 0.0)
        # a path that fails at these values gives NaN residuals: the optimiser rejects the step
        return jnp.where(jnp.all(result.converged), (predicted - F_j) / sigma_j, jnp.nan)

    z0 = jnp.asarray([table[n].to_z(start[n]) for n in free])
    return FitProblem(residuals=residuals, to_values=to_values, z0=z0, free=free, fixed=fixed, compression=c, force=F,
                      sigma=sigma, table=table, model=model, reach=reach)


