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
import math
from collections.abc import Callable

import jax.numpy as jnp
import numpy as np

from ._afm import ForceCurve
from ._compress import compress
from ._fit_data import FitData, fit_data
from ._fit_model import FitModel, contact_shift
from ._fit_residuals import FitResiduals, padded_touch
from ._goodness import estimate_noise
from ._models import make_fit_model
from ._parameters import NUISANCE_PARAMETERS, Parameter
from ._path_settings import PathSettings
from ._probe import compress_settings
from ._solution import RESULTS, ConvergenceError

__all__ = ["FitProblem", "fit_problem", "BRANCHES", "FitRangeError", "PYTHON_FIXES", "stiffness_sources", "check_start",
           "diagnose", "scaled_start", "parameter_table", "check_identifiable"]

BRANCHES = ("loading", "unloading", "both")

# How each front end spells the fixes a FitRangeError suggests ({value}, {name} filled in).
PYTHON_FIXES = {
    "crop": "crop the curve: curve.select(max_compression={value})",
    "size": "use a larger model: model_options={{'{name}': {value}}}",
    "method": "follow the fold with settings=socbjax.FitSettings(method='arclength')",
    "start": "start elsewhere (initial=...)",
}


class FitRangeError(ValueError):
    """The model cannot be evaluated over the data's compression range.

    cause : "gap" (the data reach past the probe–surface gap), "surface" (a node crosses the
        surface or the probe plane at ``limit`` µm: there is no contact model, the path is
        not physical beyond), "fold" (displacement control cannot follow the path past a fold
        at ``limit`` µm) or "path" (the solver failed otherwise; ``detail`` says how).
    reach : the largest probe travel the data need (µm; data compression + contact offset).
    compression : the data's largest compression (µm).
    size : (option name, value) of a model that would typically reach, or None.
    safe : probe travel (µm) the model can typically be followed to (default ``limit``): the
        suggested crop stays below it.
    :meth:`describe` words the message with another front end's fixes (the command line's).
    """

    def __init__(self, cause: str, *, model: str, reach: float, compression: float, limit: float | None = None,
                 size: tuple | None = None, detail: str = "", where: str = "", safe: float | None = None):
        self.cause, self.model, self.reach, self.compression = cause, model, float(reach), float(compression)
        self.limit, self.size, self.detail, self.where = limit, size, detail, where
        self.safe = limit if safe is None else safe
        super().__init__(self.describe(PYTHON_FIXES))

    def _crop(self) -> float:
        """A data compression (µm, 2 significant digits, rounded down) that stays below the limit."""
        room = self.reach - self.compression  # contact offset (and its room) on top of the data
        value = 0.9 * (self.safe if self.safe is not None else self.reach) - room
        digits = 10.0 ** (np.floor(np.log10(max(value, 1e-12))) - 1)
        return float(np.floor(value / digits) * digits)

    def describe(self, fixes: dict) -> str:
        crop = fixes["crop"].format(value=f"{self._crop():g}") if self._crop() > 0 else None
        size = fixes["size"].format(name=self.size[0], value=f"{self.size[1]:g}") if self.size else None
        data = f"the curve reaches {self.compression:.4g} µm of compression"
        if self.cause == "gap":
            text = (f"{data}, but the {self.model} model can be compressed by less than {self.limit:.4g} µm "
                    "(its probe–surface gap)")
        elif self.cause == "surface":
            text = (f"{data}, but {self.where}the {self.model} model's nodes cross the surface or the probe plane at "
                    f"{self.limit:.4g} µm of compression: socbjax has no contact model, the path beyond is not physical")
        elif self.cause == "fold":
            text = (f"{self.where}the {self.model} model's force path folds back (a snap-through) at {self.limit:.4g} µm "
                    f"of compression, within the data's {self.compression:.4g} µm; displacement control cannot follow it")
            return f"{text}; {fixes['method']}" + (f", or {crop}" if crop else "")
        else:
            text = f"{self.where}the {self.model} model cannot be followed to {self.reach:.4g} µm: {self.detail}"
            return f"{text}; " + (f"{crop}, or " if crop else "") + fixes["start"]
        return f"{text}; " + " or ".join(filter(None, (size, crop)))


@dataclasses.dataclass(frozen=True)
class FitProblem:
    """Everything :func:`socbjax.fit` optimises (see :func:`fit_problem`).

    residuals : a :class:`socbjax.FitResiduals`, z [p] -> r [m] = (model − data)/σ, traced
        and differentiable; NaN where the path cannot be followed (``throw=True``: raise
        instead, untraced).  A pytree with the data as arrays: ``eqx.filter_jit`` functions
        of it (:func:`socbjax.fit`'s Jacobian) compile once for every curve of a model.
    to_values : z -> {name: value} (free and fixed parameters, in their units).
    z0 : [p] the unconstrained start; free : the free names, in the order of z.
    compression, force, sigma : [m] the data fitted (µm, pN, pN).
    table : name -> :class:`socbjax.Parameter` (with the fit's bounds); fixed : fixed values.
    model : the :class:`socbjax.FitModel`; reach : the largest probe travel needed (µm).
    path : z -> the adaptive :func:`socbjax.compress` path (untraced, ``throw=False``) over
        the data's range at those values: what to inspect when ``residuals`` fails.
    retract : [m] bool, the points on the retract (unloading) branch; None when only the
        approach is fitted (``branch="both"``: approach points first, then retract points).
    data : the :class:`socbjax.FitData` fitted: the points with their bin ranges, and the
        approach cropped away before the window (``data.baseline``, for the noise estimate).
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
    path: Callable | None = None
    retract: np.ndarray | None = None
    data: FitData | None = None


def parameter_table(model: FitModel, free, fixed, initial, bounds) -> tuple[dict[str, Parameter], tuple, dict, dict]:
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


_CONTACT_RUN = 3  # points above the threshold in a row that mark contact (not a noise spike)


def _contact_start(data: FitData, parameter: Parameter) -> float:
    """A start for a free ``contact_point`` (µm): the first approach compression where the force
    leaves the baseline (median of the points before c = 0) by more than 5 × its noise
    (:func:`socbjax.estimate_noise`) and 5 % of the force range, and stays above that for the
    next ``_CONTACT_RUN`` − 1 points (those there are): a lone noise spike in the baseline is
    not contact; 0 when the curve has fewer than 5 points before contact or never leaves it.
    A gradient cannot find the contact of a network whose force rises within 10⁻⁴ µm of
    contact (the residuals are flat in it between data points), so the start must be close.
    Binned points: the first point above is the bin astride contact, and the start is where
    its share of the next point's force puts contact within its range [low, high]."""
    approach = np.ones(data.compression.size, bool) if data.retract is None else ~data.retract
    c, F, low, high = (a[approach] for a in (data.compression, data.force, data.low, data.high))
    before = c < 0
    if before.sum() < 5:
        return 0.0
    base = float(np.median(F[before]))
    noise = estimate_noise(F[before])
    threshold = max(5 * noise, 0.05 * float(np.ptp(F)))
    above = F - base > threshold
    # the first point of a run of _CONTACT_RUN points above (shorter at the end of the curve)
    leaves = [k for k in np.flatnonzero(above) if above[k:k + _CONTACT_RUN].all()]
    if not leaves:
        return 0.0
    k = int(leaves[0])
    guess = 0.5 * (c[k] + c[k - 1]) if k > 0 else float(c[k])
    if high[k] > low[k]:  # a bin: the fraction of it in contact from the next point's force
        share = (F[k] - base) / (F[k + 1] - base) if k + 1 < c.size and F[k + 1] - base > 0 else 0.5
        guess = float(high[k] - np.clip(share, 0.05, 0.95) * (high[k] - low[k]))
    lo, hi = parameter.lower, parameter.upper
    span = (hi - lo) if lo is not None and hi is not None else 1.0
    return float(np.clip(guess, (lo if lo is not None else -np.inf) + 1e-3 * span,
                         (hi if hi is not None else np.inf) - 1e-3 * span))


def stiffness_sources(model: FitModel, free, fixed) -> set:
    """The parameters the segments' EI values come from (a group's when it is free or fixed,
    else the global ``EI``)."""
    source = np.full(model.base.n_segments, "EI", dtype=object)
    for name, mask in model.groups.items():
        if name in free or name in fixed:
            source[mask] = name
    return set(source)


def check_identifiable(model: FitModel, free, fixed) -> None:
    if "contact_point" in (*free, *fixed) and "contact_offset" in (*free, *fixed):
        raise ValueError("contact_point and contact_offset are the same shift (contact_offset = −contact_point); "
                         "use one of them")
    scales = [n for n in ("force_scale", *getattr(model, "force_scales", ())) if n in free]
    if not scales:
        return
    source = stiffness_sources(model, free, fixed)
    ei_free = sorted(source & set(free))
    if len(scales) > 1 or all(name in free for name in source):
        names = ", ".join(scales + ei_free)
        raise ValueError(
            f"{names} are not separately identifiable from one curve: at fixed geometry the force scales with EI "
            "(exactly with the default perturbation, which scales with EI) and with each of "
            f"{', '.join(scales)}, so only their product is determined. Fix all but one of them, e.g. "
            f"fixed={{'{scales[0]}': ...}} (a value measured independently) or fix EI"
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


def _largest_shift(table, free, fixed) -> float:
    """The largest contact shift contact_offset − contact_point (µm) that the bounds of the free
    contact terms and the fixed values allow; inf when a free one is unbounded on that side."""
    shift = 0.0
    for name, sign, side in (("contact_offset", 1.0, "upper"), ("contact_point", -1.0, "lower")):
        if name in free:
            bound = getattr(table[name], side)
            shift += math.inf if bound is None else sign * float(bound)
        elif name in fixed:
            shift += sign * float(fixed[name])
    return shift


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
    data = fit_data(curve, branch, int(max_points), min_compression)
    c, F, retract = data.compression, data.force, data.retract
    bounds = dict(bounds or {})
    # a free contact shift moves the contact point within the data's own range: beyond it the
    # model would be sampled past the data (or entirely before contact) and the fit is degenerate
    if "contact_offset" in free and "contact_offset" not in bounds:
        bounds["contact_offset"] = (-0.5 * float(c.max()), 0.1 * float(c.max()))
    if "contact_point" in free and "contact_point" not in bounds:
        bounds["contact_point"] = (-0.1 * float(c.max()), 0.5 * float(c.max()))
    table, free, fixed, start = parameter_table(model, free, fixed, initial, bounds)
    if "contact_point" in free and "contact_point" not in (initial or {}):
        start["contact_point"] = _contact_start(data, table["contact_point"])
    check_identifiable(model, free, fixed)
    shift = contact_shift({**start, **fixed})
    room = max(0.0, table["contact_offset"].upper or 0.0) if "contact_offset" in free else 0.0
    room += max(0.0, -(table["contact_point"].lower or 0.0)) if "contact_point" in free else 0.0
    reach = float(c.max()) + max(float(shift), 0.0) + room
    if reach >= model.gap:
        size = model.size_for(reach)
        raise FitRangeError("gap", model=model.name, reach=reach, compression=float(c.max()), limit=model.gap,
                            size=None if size is None else (model.size_option, size),
                            safe=model.reach_fraction * model.gap if model.size_option else None)
    physical = [n for n in (*free, *fixed) if n in model.parameters]
    sigma = _sigma(sigma, c.size, curve)
    # Points before contact at every allowed contact shift have model force 0 whatever the
    # values: only the others are sent to the model (a real curve's long approach costs no
    # equilibria).  All points when a free contact term has an open bound.
    touch = np.flatnonzero(data.high + _largest_shift(table, free, fixed) > 0)
    touch = padded_touch(touch if touch.size else np.arange(c.size))
    bound = lambda value: None if value is None else np.asarray(float(value))  # noqa: E731
    residuals = FitResiduals(
        model=model, free=free, lower=tuple(bound(table[n].lower) for n in free),
        upper=tuple(bound(table[n].upper) for n in free), fixed={n: float(v) for n, v in fixed.items()},
        compression=c, force=F, sigma=sigma, low=data.low, high=data.high, touch=touch, reach=np.asarray(reach),
        retract=None if retract is None else tuple(np.asarray(retract, bool)[touch].tolist()), method=method,
        # filled and capped at the concrete reach here (as compress would), traced in the program
        settings=compress_settings(path, method, reach).traced())

    def full_path(z):
        values = residuals.to_values(z)
        network = model.network({n: values[n] for n in physical})
        return compress(network, reach, unload=retract is not None, method=method, settings=path,
                        perturbation=values.get("perturbation"), throw=False)

    z0 = jnp.asarray([table[n].to_z(start[n]) for n in free])
    return FitProblem(residuals=residuals, to_values=residuals.to_values, z0=z0, free=free, fixed=fixed, compression=c, force=F,
                      sigma=sigma, table=table, model=model, reach=reach, path=full_path, retract=retract,
                      data=data)


# ----------------------------------------------------------------- the start of a fit
def check_start(problem: FitProblem, z, residuals: Callable | None = None,
                where: str = "at the initial values ") -> np.ndarray:
    """The residuals at ``z`` (``residuals(z)``, default ``problem.residuals``), checked: a
    model that cannot be followed over the data's range there raises :class:`FitRangeError`
    with the reason (:func:`diagnose`)."""
    try:
        r = np.asarray(residuals(z) if residuals is not None else problem.residuals(z, throw=True))
    except ConvergenceError as err:
        raise diagnose(problem, z, str(err), where) from None
    if not np.all(np.isfinite(r)):
        raise diagnose(problem, z, None, where)
    return r


def diagnose(problem: FitProblem, z, message: str | None, where: str) -> FitRangeError:
    """Why the model cannot be evaluated over the data's range at ``z``: the adaptive path
    (untraced) says where nodes cross the surface (no contact model) or where a fold stops
    displacement control; otherwise the solver's ``message`` (found if None)."""
    common = {"model": problem.model.name, "reach": problem.reach, "compression": float(np.max(problem.compression)),
              "where": where}
    try:
        path = problem.path(z)
    except (ConvergenceError, ValueError) as err:
        return FitRangeError("path", detail=" ".join(str(err).split()), **common)
    crossing = path.first_crossing
    if crossing is not None and crossing.displacement < problem.reach:
        size = problem.model.size_for(problem.reach)
        return FitRangeError("surface", limit=crossing.displacement,
                             size=None if size is None else (problem.model.size_option, size), **common)
    if path.result == RESULTS.fold:
        return FitRangeError("fold", limit=float(np.max(np.asarray(path.displacement))), **common)
    if message is None:
        try:
            problem.residuals(z, throw=True)
            message = "the model's forces are not finite"
        except ConvergenceError as err:
            message = str(err)
    return FitRangeError("path", detail=" ".join(message.split()), **common)


def scaled_start(problem: FitProblem, r: np.ndarray, initial: dict, residuals: Callable | None = None) -> tuple:
    """(problem, note): scale the start to the data's force level with one least-squares
    factor (from the first evaluation), exact because at fixed geometry the force is
    proportional to EI and to a force scale (``force_scale``, a lawn's ``density``):

    * when every segment's EI comes from free parameters without a starting value (and
      neither ``force_scale`` nor ``perturbation`` is set), those EI values;
    * else a free force scale without a starting value (the EI values fixed or set).

    Without it a fit that starts a factor off the data's force level (e.g. a lawn's density
    at its default) moves the contact point first, where the force jumps at contact and the
    Gauss–Newton model is poor, and Levenberg–Marquardt stalls at a large damping."""
    free, fixed, table = problem.free, problem.fixed, problem.table
    sources = stiffness_sources(problem.model, free, fixed)
    scales = [n for n in ("force_scale", *getattr(problem.model, "force_scales", ()))
              if n in free and n not in initial]
    settled = {"force_scale", "perturbation"} & {*free, *fixed}
    if sources <= set(free) and not sources & set(initial) and not settled:
        scaled = sources
    elif len(scales) == 1:
        scaled = set(scales)
    else:
        return problem, None
    values = {k: float(v) for k, v in problem.to_values(problem.z0).items()}
    w = 1.0 / problem.sigma
    model_part = (r / w + problem.force - values.get("baseline", 0.0)) * w  # the model's force (without baseline) / σ
    data_part = (problem.force - values.get("baseline", 0.0)) * w
    denominator = float(model_part @ model_part)
    factor = float(model_part @ data_part) / denominator if denominator > 0 else math.nan
    if not (math.isfinite(factor) and factor > 0) or abs(factor - 1.0) < 1e-3:
        return problem, None
    z = np.asarray(problem.z0, float).copy()
    for i, name in enumerate(free):
        if name in scaled:
            try:
                z[i] = float(table[name].to_z(table[name].check(values[name] * factor, "scaled start")))
            except ValueError:
                return problem, None
    start = dataclasses.replace(problem, z0=jnp.asarray(z))
    check_start(start, start.z0, residuals, "at the start scaled to the data's force level ")
    shown = ", ".join(f"{n} = {values[n] * factor:.4g} {table[n].unit}" for n in free if n in scaled)
    return start, f"start {shown}: the default scaled ×{factor:.4g} to the data's force level"
