"""The data a fit compares with its model (:func:`fit_data`): the fitted window of a force curve,
averaged in compression bins when it is long, with each point's bin range, and the approach
cropped away before the window (for the noise estimate of the goodness of fit).

A binned point is the mean of the raw points in its bin of width w (µm).  Where the model's
force jumps at contact (inextensible filaments touch with a finite force), the bin that
straddles the contact point holds raw points before contact (force 0) and after it: its mean
force is the fraction in contact times the contact part's mean force, not the force at the
bin's mean compression.  :class:`FitData` keeps each point's bin range [lo, hi] so that the
residuals can say so (:func:`bin_mean_force`).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ._afm import ForceCurve

__all__ = ["FitData", "ApproachBaseline", "fit_data", "bin_mean_force", "bin_evaluation_points"]


@dataclasses.dataclass(frozen=True)
class ApproachBaseline:
    """The points of the fitted branch(es) before the fitted window (compression below its
    lower end), used only for the noise estimate of the goodness of fit: a real curve's long
    approach holds many more non-contact points than the window's quarter.  Where the window
    is averaged in bins (``max_points``), these are averaged in bins of the same width, so
    that their noise is that of a fitted point.

    compression, force : [k] (µm, pN), in increasing compression per branch; retract : [k] bool.
    """

    compression: np.ndarray
    force: np.ndarray
    retract: np.ndarray


@dataclasses.dataclass(frozen=True)
class FitData:
    """The fitted points of :func:`fit_data`.

    compression, force : [m] (µm, pN), bin means where binned; low, high : [m] (µm) each
    point's bin range (low = high = compression for a raw point); retract : [m] bool or None
    (approach only); baseline : :class:`ApproachBaseline` or None (nothing cropped).
    """

    compression: np.ndarray
    force: np.ndarray
    low: np.ndarray
    high: np.ndarray
    retract: np.ndarray | None
    baseline: ApproachBaseline | None


def fit_data(curve, branch: str, max_points: int, min_compression) -> FitData:
    """The fitted branch(es) of ``curve`` (a :class:`socbjax.ForceCurve` or (compression µm,
    force pN) arrays): ``branch`` "loading", "unloading" or "both" (a ForceCurve with both
    segments: approach points first); a ForceCurve's window starts at ``min_compression``
    (default −¼ of its largest compression) and is averaged in ``max_points`` bins when longer."""
    if branch != "both":
        c, F, bins, extra = _branch_data(curve, branch, max_points, min_compression)
        retract = np.ones(c.size, bool) if branch == "unloading" else None
        return FitData(c, F, *bins, retract, _baseline([extra], [branch == "unloading"]))
    if not isinstance(curve, ForceCurve):
        raise ValueError("branch='both' needs a socbjax.ForceCurve with approach and retract (socbjax.load_curve); "
                         "for (compression, force) arrays fit one branch")
    if len(curve.approach) == 0 or len(curve.retract) == 0:
        raise ValueError("branch='both': the curve has no retract segment (an approach only); fit branch='loading'")
    parts = [_branch_data(curve, b, max_points, min_compression) for b in ("loading", "unloading")]
    (c1, F1, (lo1, hi1), extra1), (c2, F2, (lo2, hi2), extra2) = parts
    return FitData(np.concatenate([c1, c2]), np.concatenate([F1, F2]), np.concatenate([lo1, lo2]),
                   np.concatenate([hi1, hi2]), np.concatenate([np.zeros(c1.size, bool), np.ones(c2.size, bool)]),
                   _baseline([extra1, extra2], [False, True]))


def bin_evaluation_points(data: FitData, shift):
    """Probe travel u [m] (µm) at which the model is evaluated for each point, for a contact
    shift ``shift`` (µm, traced): c + shift, except in a bin that straddles contact
    (low + shift < 0 < high + shift), where it is the middle of the bin's part in contact."""
    c, lo, hi = (jnp.asarray(a) for a in (data.compression, data.low, data.high))
    straddle = (lo + shift < 0) & (hi + shift > 0)
    return jnp.where(straddle, 0.5 * (hi + shift), c + shift)


def bin_mean_force(data: FitData, shift, force):
    """Mean model force (pN) over each point's bin: ``force`` [m] is the model at
    :func:`bin_evaluation_points`, 0 before contact; in a bin the fraction in contact is
    clip((high + shift)/(high − low), 0, 1) for raw points spread evenly over [low, high]
    (exact for a force linear in the contact part, e.g. a jump to a plateau: a continuous,
    differentiable function of the contact point); raw points are in contact or not."""
    lo, hi = jnp.asarray(data.low), jnp.asarray(data.high)
    width = hi - lo
    binned = width > 0
    fraction = jnp.clip((hi + shift) / jnp.where(binned, width, 1.0), 0.0, 1.0)
    return jnp.where(binned, fraction, 1.0) * force


def _baseline(parts, retract_flags) -> ApproachBaseline | None:
    parts = [(c, F, np.full(c.size, flag)) for (c, F), flag in zip(parts, retract_flags, strict=True) if c.size]
    if not parts:
        return None
    return ApproachBaseline(*(np.concatenate(a) for a in zip(*parts, strict=True)))


def _bin_ranges(c_raw: np.ndarray, binned: ForceCurve):
    """(low, high) [m] (µm) of the points of ``binned`` (:meth:`ForceCurve.binned` of raw
    compressions ``c_raw``): the span of each bin's raw points widened by the half-spacing to
    the next raw point on each side (the compression each raw point stands for; an end point
    mirrors its one neighbour).  Local, not the median spacing: a simulated curve's adaptive
    steps grow from nanometres at contact, and the median would extend the first bin past its
    first point into the approach, where the model's force is 0."""
    span = np.asarray(binned.metadata["bin_span"], float)
    c = np.sort(c_raw)  # more than max_points ≥ 3 points (it was binned)
    gaps = np.diff(c)
    below = 0.5 * np.concatenate([gaps[:1], gaps])  # [n] half-spacing below each raw point
    above = 0.5 * np.concatenate([gaps, gaps[-1:]])
    first = np.searchsorted(c, span[:, 0], side="left")
    last = np.searchsorted(c, span[:, 1], side="right") - 1
    return span[:, 0] - below[first], span[:, 1] + above[last]


def _branch_data(curve, branch: str, max_points: int, min_compression):
    """(compression, force, (low, high), (compression, force) before the window) of one branch."""
    if isinstance(curve, ForceCurve):
        return _curve_branch(curve, branch, max_points, min_compression)
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
    c_out, F_out = c[:0], F[:0]
    if min_compression is not None:
        keep = c >= float(min_compression)
        c_out, F_out = c[~keep], F[~keep]
        c, F = c[keep], F[keep]
    _check_branch(c, branch)
    return c, F, (c, c), (c_out, F_out)


def _curve_branch(curve: ForceCurve, branch: str, max_points: int, min_compression):
    segment = 0 if branch == "loading" else 1
    part = curve if np.all(curve.segment == segment) else (curve.approach if segment == 0 else curve.retract)
    if len(part) == 0 or part.compression.max() <= 0:
        raise ValueError(f"the {branch} branch never passes the contact point (no compression > 0): nothing to fit")
    low = -0.25 * part.compression.max() if min_compression is None else float(min_compression)
    before = part.compression < low
    c_out, F_out = np.asarray(part.compression[before], float), np.asarray(part.force[before], float)
    part = part.select(min_compression=low)
    c_raw = np.asarray(part.compression, float)
    binned = len(part) > max_points
    if binned:
        part = part.binned(max_points)
        # the cropped approach in bins of (nearly) the fitted points' width; shorter than 3 bins,
        # it is dropped (its raw points would carry a raw point's noise, not a bin's)
        n_bins = round(float(np.ptp(c_out)) * max_points / (c_raw.max() - c_raw.min())) if c_out.size >= 3 else 0
        if n_bins >= 3:
            cropped = ForceCurve(c_out, F_out).binned(n_bins)
            c_out, F_out = np.asarray(cropped.compression, float), np.asarray(cropped.force, float)
        else:
            c_out, F_out = c_out[:0], F_out[:0]
    c, F = np.asarray(part.compression, float), np.asarray(part.force, float)
    _check_branch(c, branch)
    return c, F, (_bin_ranges(c_raw, part) if binned else (c, c)), (c_out, F_out)


def _check_branch(c: np.ndarray, branch: str) -> None:
    if c.size < 3:
        raise ValueError(f"the {branch} branch has {c.size} points; a fit needs at least 3")
    if c.max() <= 0:
        raise ValueError("the curve never passes the contact point (all compressions ≤ 0): nothing to fit")
