"""Goodness of fit: noise level, reduced χ², structure in the residuals, information criteria.

:func:`goodness_of_fit` judges a fitted force curve (points, data and model force in pN):

* **Noise** σ̂ (pN) of the fitted points, in this order of preference: the non-contact
  baseline (at least ``MIN_BASELINE_POINTS`` = 8 points before contact: the fitted ones and,
  when the fit cropped a longer approach away, the cropped ones, averaged in bins of the
  fitted points' width — a real curve's whole approach, not only the window's quarter), by
  :func:`estimate_noise` — ``noise_source`` "baseline"; else the user's ``sigma`` (its rms) —
  "sigma"; else :func:`estimate_noise` of the fit's own residuals over all points —
  "residuals" (then χ² is not a test: the noise was taken from the misfit itself).
  The estimate is made on the points that are fitted: when a curve is averaged in bins
  (``FitSettings.max_points``) the noise per fitted point is that of the bin means.
* **χ²** = Σ((F̂ − F)/σ̂)² (σᵢ per point with ``sigma``), ``chi2_reduced`` = χ²/(m − p)
  (m points, p free parameters).  Its p-value: χ²(m − p) with ``sigma``; with a baseline
  estimate, which is itself uncertain, the F distribution F(m − p, ν) with
  ν = 0.3 (n_b − 1) effective degrees of freedom of the estimate from n_b baseline points
  (calibrated by simulation: Var σ̂² = 2σ⁴/ν for the MAD of first differences; the test is
  then conservative, 1.5–3 × fewer false alarms than nominal).
* **Runs test** (Wald–Wolfowitz) on the signs of the residuals along the curve, over the
  contact part (compression > 0; all points when fewer than 10 are in contact): the exact
  one-sided p-value of so few runs (:func:`runs_test`).
* **Lag-1 autocorrelation** of the residuals over the same points (reported as evidence;
  noise gives −1/n ± 1/√n).
* **Verdict** ``misfit`` = runs-test p < ``MISFIT_P`` (1e-3) or, when σ̂ comes from the
  baseline or ``sigma``, χ² p < 1e-3 (a false alarm in at most ~1/500 fits of a correctly
  specified model with white Gaussian noise).  Residuals at the model's numerical accuracy
  (rms ≤ 1e-6 × the largest |force|: noise-free data) are not tested.
* **AIC** = m ln(RSS/m) + 2p, **BIC** = m ln(RSS/m) + p ln m (Gaussian likelihood with
  unknown variance; RSS of the residuals in pN², or of (F̂ − F)/σ with ``sigma``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._fit_model import contact_shift

__all__ = ["estimate_noise", "runs_test", "RunsTest", "lag1_autocorrelation", "information_criteria",
           "goodness_of_fit", "Goodness", "judge_fit", "MISFIT_P", "MIN_BASELINE_POINTS", "MISFIT_PREFIX", "NOISE_SOURCES"]

MIN_BASELINE_POINTS = 8
MIN_CONTACT_POINTS = 10  # fewer contact points: the runs test and the autocorrelation use all points
MISFIT_P = 1e-3
NOISE_DOF_PER_POINT = 0.3  # effective degrees of freedom of estimate_noise per baseline point (simulated)
MISFIT_PREFIX = "the model misfits the data systematically: "
NOISE_SOURCES = ("baseline", "sigma", "residuals")
_Q3 = 0.6744897501960817  # Φ⁻¹(3/4): the MAD of a standard normal
_EXACT_RUNS_LIMIT = 5000  # points; beyond, the runs test uses its normal approximation


def estimate_noise(force, groups=None) -> float:
    """Noise level (pN, the standard deviation of white Gaussian noise) of a sequence of force
    values, insensitive to a slowly varying baseline (offset, slope) and to outliers:
    σ̂ = MAD(ΔF) / (√2 · 0.6745), the median absolute deviation (about their median) of the
    first differences ΔFᵢ = Fᵢ₊₁ − Fᵢ.  ``groups`` ([n] labels, e.g. approach/retract): only
    differences within a group are used.  Needs at least 2 differences; NaN otherwise."""
    f = np.asarray(force, float).ravel()
    d = np.diff(f)
    if groups is not None:
        g = np.asarray(groups).ravel()
        d = d[g[1:] == g[:-1]]
    if d.size < 2:
        return math.nan
    return float(np.median(np.abs(d - np.median(d))) / (math.sqrt(2.0) * _Q3))


@dataclasses.dataclass(frozen=True)
class RunsTest:
    """Wald–Wolfowitz runs test of residual signs (zeros dropped).

    runs : number of runs (maximal blocks of equal sign); n_positive, n_negative : counts.
    expected : 2 n₊ n₋ / n + 1; variance : 2 n₊ n₋ (2 n₊ n₋ − n) / (n² (n − 1)).
    z : (runs − expected)/√variance (negative: too few runs, structured residuals).
    p_value : P(R ≤ runs) for independent signs (exact for n ≤ 5000, else normal): small
        when the residuals change sign too rarely.  1.0 when one sign has fewer than 2 points.
    """

    runs: int
    n_positive: int
    n_negative: int
    expected: float
    variance: float
    z: float
    p_value: float


def _runs_cdf(runs: int, n1: int, n2: int) -> float:
    """Exact P(R ≤ runs) for n1 and n2 signs in random order."""
    comb = math.comb
    total = 0
    for r in range(2, runs + 1):
        k = r // 2
        if r % 2 == 0:
            total += 2 * comb(n1 - 1, k - 1) * comb(n2 - 1, k - 1)
        else:
            total += comb(n1 - 1, k) * comb(n2 - 1, k - 1) + comb(n1 - 1, k - 1) * comb(n2 - 1, k)
    return min(1.0, total / comb(n1 + n2, n1))


def runs_test(residuals) -> RunsTest:
    """The runs test (:class:`RunsTest`) of the signs of ``residuals``, in the given order."""
    r = np.asarray(residuals, float).ravel()
    signs = np.sign(r[np.isfinite(r) & (r != 0)])
    n1, n2 = int(np.sum(signs > 0)), int(np.sum(signs < 0))
    n = n1 + n2
    runs = 1 + int(np.sum(signs[1:] != signs[:-1])) if n else 0
    if n1 < 2 or n2 < 2:
        return RunsTest(runs, n1, n2, math.nan, math.nan, math.nan, 1.0)
    mean = 2.0 * n1 * n2 / n + 1.0
    var = 2.0 * n1 * n2 * (2.0 * n1 * n2 - n) / (n**2 * (n - 1))
    z = (runs - mean) / math.sqrt(var)
    if n <= _EXACT_RUNS_LIMIT:
        p = _runs_cdf(runs, n1, n2)
    else:
        p = 0.5 * math.erfc(-(z + 0.5 / math.sqrt(var)) / math.sqrt(2.0))  # with continuity correction
    return RunsTest(runs, n1, n2, mean, var, z, float(p))


def lag1_autocorrelation(residuals) -> float:
    """r₁ = Σ (eᵢ − ē)(eᵢ₊₁ − ē) / Σ (eᵢ − ē)² of the residuals in the given order (white
    noise: −1/n ± 1/√n; a smooth misfit: near +1).  NaN for fewer than 3 values."""
    e = np.asarray(residuals, float).ravel()
    if e.size < 3:
        return math.nan
    e = e - e.mean()
    denominator = float(e @ e)
    return float(e[1:] @ e[:-1]) / denominator if denominator > 0 else math.nan


def information_criteria(rss: float, m: int, p: int) -> tuple[float, float]:
    """(AIC, BIC) of a least-squares fit with Gaussian errors of unknown variance:
    AIC = m ln(RSS/m) + 2p, BIC = m ln(RSS/m) + p ln m (constants common to all models of the
    same m points dropped; only differences between models fitted to the same points mean
    anything).  ``rss`` : residual sum of squares, m points, p free parameters."""
    if not (m > 0 and rss > 0 and math.isfinite(rss)):
        return (-math.inf, -math.inf) if rss == 0 else (math.nan, math.nan)
    fit_term = m * math.log(rss / m)
    return fit_term + 2.0 * p, fit_term + p * math.log(m)


@dataclasses.dataclass(frozen=True)
class Goodness:
    """Outcome of :func:`goodness_of_fit` (see the module docstring for the formulas).

    noise : σ̂ (pN); noise_source : "baseline", "sigma" or "residuals"; n_baseline : points
        before contact; noise_dof : effective degrees of freedom of σ̂ (inf for ``sigma``,
        NaN for residuals).
    chi2, chi2_reduced, dof : χ², χ²/(m − p), m − p; chi2_p : P(≥ χ²) by χ²(dof) or
        F(dof, noise_dof) (NaN when χ² is not a test).
    runs : :class:`RunsTest` over the tested points (``n_tested``); autocorrelation : r₁.
    rss : the residual sum of squares the information criteria use (pN², or dimensionless
        with ``sigma``); aic, bic; m, n_parameters.
    misfit : the verdict; evidence : one sentence of numbers; notes : caveats for warnings.
    """

    noise: float
    noise_source: str
    n_baseline: int
    noise_dof: float
    chi2: float
    chi2_reduced: float
    dof: int
    chi2_p: float
    runs: RunsTest
    n_tested: int
    autocorrelation: float
    rss: float
    aic: float
    bic: float
    m: int
    n_parameters: int
    misfit: bool
    evidence: str
    notes: tuple

    def warning(self) -> str | None:
        """The misfit warning ("the model misfits the data systematically: ..."), or None."""
        if not self.misfit:
            return None
        return (f"{MISFIT_PREFIX}{self.evidence}; the model does not follow the curve's shape (see the figure's "
                "residuals): its values are that model's best compromise, not properties of the sample")

    def to_dict(self) -> dict:
        out = dataclasses.asdict(self)
        out["notes"] = list(self.notes)
        return out


def _noise(force, residual_pN, baseline, sigma, groups, extra):
    """(noise, source, n_baseline, dof, notes); ``extra`` = (force [k], groups [k]) of
    baseline points that are not fitted."""
    f_b, g_b = force[baseline], np.unique(groups, return_inverse=True)[1][baseline]
    if extra is not None:  # the cropped points are their own groups: no difference spans the crop
        f_e, g_e = (np.asarray(a).ravel() for a in extra)
        f_b = np.concatenate([np.asarray(f_e, float), f_b])
        g_b = np.concatenate([np.unique(g_e, return_inverse=True)[1] + g_b.max(initial=0) + 1, g_b])
    n_b = int(f_b.size)
    notes = []
    if n_b >= MIN_BASELINE_POINTS:
        noise = estimate_noise(f_b, g_b)
        if math.isfinite(noise) and noise > 0:
            return noise, "baseline", n_b, NOISE_DOF_PER_POINT * (n_b - 1), notes
        notes.append(f"the {n_b} baseline points show no measurable noise (quantised or noise-free data)")
    else:
        notes.append(f"{n_b} points before contact, too few for a noise estimate from the baseline (it needs "
                     f"{MIN_BASELINE_POINTS}: fit more of the approach before contact, or give the whole approach)")
    if sigma is not None:
        return float(np.sqrt(np.mean(np.square(sigma)))), "sigma", n_b, math.inf, []
    notes.append("the noise level is estimated from the fit's own residuals, so χ² is not a test of the model "
                 "(only the runs test is)")
    return estimate_noise(residual_pN, groups), "residuals", n_b, math.nan, notes


def _chi2_p(chi2: float, dof: int, noise_dof: float) -> float:
    from scipy import stats

    if not (dof > 0 and math.isfinite(chi2)):
        return 0.0 if chi2 == math.inf else math.nan
    if noise_dof == math.inf:
        return float(stats.chi2.sf(chi2, dof))
    return float(stats.f.sf(chi2 / dof, dof, noise_dof)) if noise_dof > 0 else math.nan


def goodness_of_fit(compression, force, model_force, n_parameters: int, *, sigma=None, baseline=None,
                    contact=None, groups=None, extra_baseline=None) -> Goodness:
    """Judge a fit: noise, χ², runs test, autocorrelation, AIC/BIC and the misfit verdict.

    compression (µm), force (pN), model_force (pN) : [m] the fitted points, data and model.
    n_parameters : p, the number of free parameters.
    sigma : None, or the force uncertainty (pN, scalar or [m]) the fit was weighted with.
    baseline : [m] bool, the points before contact (default compression < 0); contact : [m]
        bool, the points in contact (default compression > 0).
    groups : [m] labels of the branches (e.g. True for retract points) when several are fitted.
    extra_baseline : None, or (force [k] pN, groups [k]) of non-contact points that are not
        fitted (e.g. the approach before the fitted window, in increasing compression per
        group, binned like the fitted points): they join the noise estimate.
    Points are taken in order of compression within each group (the noise estimate uses
    differences within a group only).  Returns a :class:`Goodness`.
    """
    c, f, fm = (np.asarray(a, float).ravel() for a in (compression, force, model_force))
    if not c.shape == f.shape == fm.shape:
        raise ValueError(f"compression, force and model_force must have one shape, got {c.shape}, {f.shape}, {fm.shape}")
    groups = np.zeros(c.size, int) if groups is None else np.asarray(groups).ravel()
    order = np.lexsort((c, groups))
    baseline = (c < 0) if baseline is None else np.asarray(baseline, bool).ravel()
    contact = (c > 0) if contact is None else np.asarray(contact, bool).ravel()
    s = None if sigma is None else np.broadcast_to(np.asarray(sigma, float), c.shape)
    c, f, fm, baseline, contact, groups = (a[order] for a in (c, f, fm, baseline, contact, groups))
    s = None if s is None else s[order]
    r = fm - f
    m, p = int(c.size), int(n_parameters)
    noise, source, n_b, noise_dof, notes = _noise(f, r, baseline, s, groups, extra_baseline)
    scale = s if source == "sigma" else noise
    with np.errstate(divide="ignore", invalid="ignore"):
        chi2 = float(np.sum((r / scale) ** 2)) if np.all(np.asarray(scale) > 0) else math.inf
    dof = m - p
    chi2_reduced = chi2 / dof if dof > 0 else math.nan
    tested = contact if int(np.sum(contact)) >= MIN_CONTACT_POINTS else np.ones(m, bool)
    weighted = r if s is None else r / s
    runs = runs_test(weighted[tested])
    rho = lag1_autocorrelation(weighted[tested])
    rss = float(weighted @ weighted)
    aic, bic = information_criteria(rss, m, p)
    chi2_p = _chi2_p(chi2, dof, noise_dof) if source != "residuals" else math.nan
    exact = float(np.sqrt(np.mean(r**2))) <= 1e-6 * max(float(np.max(np.abs(f))) if m else 0.0, 1e-300)
    misfit = not exact and (runs.p_value < MISFIT_P or (source != "residuals" and chi2_p < MISFIT_P))
    if exact:
        notes.append("the residuals are at the model's numerical accuracy (noise-free data?): no misfit test")
    n_t = int(np.sum(tested))
    chi_text = (f"χ²_red = {chi2_reduced:.3g} over {dof} degrees of freedom with noise {noise:.3g} pN from the "
                f"{source}" + (f" (p = {chi2_p:.2g})" if source != "residuals" else " (not a test)"))
    evidence = (f"{runs.runs} runs of residual signs over {n_t} points where noise gives {runs.expected:.1f} "
                f"(runs test z = {runs.z:.1f}, p = {runs.p_value:.2g}), lag-1 autocorrelation {rho:.2f} "
                f"(noise: {-1.0 / max(n_t, 1):.2f} ± {1.0 / math.sqrt(max(n_t, 1)):.2f}), {chi_text}")
    return Goodness(noise=noise, noise_source=source, n_baseline=n_b, noise_dof=noise_dof, chi2=chi2,
                    chi2_reduced=chi2_reduced, dof=dof, chi2_p=chi2_p, runs=runs, n_tested=n_t, autocorrelation=rho,
                    rss=rss, aic=aic, bic=bic, m=m, n_parameters=p, misfit=bool(misfit), evidence=evidence,
                    notes=tuple(notes))


def judge_fit(problem, values: dict, r: np.ndarray, sigma_given: bool) -> Goodness:
    """:func:`goodness_of_fit` of a fit's points (a :class:`socbjax.FitProblem`, the fitted
    ``values``, residuals ``r`` in pN): before contact are the points with c < 0 and
    c + shift < 0, in contact those with c + shift > 0 (shift = contact_offset − contact_point,
    µm); approach and retract points (``problem.retract``) are separate groups.  The points
    cropped before the window (``problem.data.baseline``) that are before contact by the same rule
    join the noise estimate."""
    c = np.asarray(problem.compression, float)
    shift = float(contact_shift(values))
    shifted = c + shift
    extra, data = None, getattr(problem, "data", None)
    cropped = None if data is None else data.baseline
    if cropped is not None:
        before = (cropped.compression < 0) & (cropped.compression + shift < 0)
        extra = (cropped.force[before], cropped.retract[before])
    return goodness_of_fit(c, problem.force, problem.force + r, len(problem.free),
                           sigma=problem.sigma if sigma_given else None, baseline=(c < 0) & (shifted < 0),
                           contact=shifted > 0, groups=getattr(problem, "retract", None), extra_baseline=extra)
