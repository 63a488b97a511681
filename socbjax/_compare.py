"""Model comparison: :func:`compare_models` fits several models to one curve and tabulates
their goodness of fit and information criteria (:class:`ModelComparison`).

Every model is fitted to the same points (the curve's branch, cropped and binned by the same
:class:`socbjax.FitSettings`), so their AIC and BIC are comparable:
AIC = m ln(RSS/m) + 2p, BIC = m ln(RSS/m) + p ln m (m points, p free parameters; RSS in pN²,
or of the σ-weighted residuals with ``sigma``; :func:`socbjax.information_criteria`).
ΔAIC, ΔBIC are the differences to the lowest value among the converged fits; the ``best``
model is the converged fit of lowest AIC.  Conventional reading (Burnham & Anderson): ΔAIC < 2
indistinguishable, > 10 no support for the worse model.  A model that is not known (not in
``socbjax.FIT_MODELS``) or cannot be fitted (``FitRangeError``, ``ConvergenceError``, another
``ValueError``) gets a row with the error instead of stopping the comparison.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys

from ._solution import ConvergenceError

__all__ = ["compare_models", "ModelComparison", "DEFAULT_FREE", "attach_comparison"]

# free parameters of each model when ``free`` does not name them
DEFAULT_FREE = {"column": ("EI",), "unit-mesh": ("EI", "branch_angle"), "outcrop": ("EI",),
                "lawn": ("EI", "contact_point", "baseline")}
_ROW_KEYS = ("model", "free", "n_parameters", "m", "rss", "noise", "noise_source", "chi2_reduced", "aic", "bic",
             "delta_aic", "delta_bic", "misfit", "converged", "values", "standard_errors", "error")


@dataclasses.dataclass(frozen=True)
class ModelComparison:
    """Outcome of :func:`compare_models`.

    rows : one dict per model, in the order given: ``model`` (name), ``free``,
        ``n_parameters`` (p), ``m`` (points), ``rss`` (pN², or dimensionless with ``sigma``),
        ``noise`` (pN), ``noise_source``, ``chi2_reduced``, ``aic``, ``bic``, ``delta_aic``,
        ``delta_bic`` (to the best converged fit), ``misfit``, ``converged``, ``values``,
        ``standard_errors`` and ``error`` (None, or why the model has no fit; then the numbers
        are NaN).
    results : model name -> :class:`socbjax.FitResult` (fitted models only).
    best : name of the converged fit of lowest AIC (None if no fit converged).
    """

    rows: tuple
    results: dict
    best: str | None

    @property
    def models(self) -> tuple:
        return tuple(row["model"] for row in self.rows)

    def __getitem__(self, name: str) -> dict:
        for row in self.rows:
            if row["model"] == name:
                return row
        raise KeyError(f"no model {name!r} in this comparison; it has {list(self.models)}")

    def table(self) -> str:
        """A text table, one line per model (the best marked), errors written out."""
        fitted = [r for r in self.rows if r["error"] is None]
        points = sorted({r["m"] for r in fitted})
        head = (f"model comparison over {points[0] if len(points) == 1 else points} points; best by AIC: "
                f"{self.best or 'none (no fit converged)'}")
        columns = (f"  {'model':<12s} {'p':>2s} {'RSS':>10s} {'noise pN':>9s} {'χ²_red':>9s} {'AIC':>10s} "
                   f"{'ΔAIC':>8s} {'BIC':>10s} {'ΔBIC':>8s}  {'misfit':<6s} {'converged':<9s}")
        lines = [head, columns]
        for r in self.rows:
            if r["error"] is not None:
                lines.append(f"  {r['model']:<12s} not fitted: {r['error']}")
                continue
            mark = "  ← best" if r["model"] == self.best else ""
            lines.append(f"  {r['model']:<12s} {r['n_parameters']:>2d} {r['rss']:>10.4g} {r['noise']:>9.3g} "
                         f"{r['chi2_reduced']:>9.4g} {r['aic']:>10.2f} {r['delta_aic']:>8.2f} {r['bic']:>10.2f} "
                         f"{r['delta_bic']:>8.2f}  {'YES' if r['misfit'] else 'no':<6s} "
                         f"{'yes' if r['converged'] else 'NO':<9s}{mark}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready: ``best``, ``models`` and ``rows`` (non-finite numbers as None)."""
        from ._io import finite_json

        rows = [{k: (list(v) if isinstance(v, tuple) else v) for k, v in r.items()} for r in self.rows]
        return finite_json(json.loads(json.dumps({"best": self.best, "models": list(self.models), "rows": rows},
                                                  default=float)))

    def to_json(self, path=None, *, indent: int = 2) -> str:
        """The :meth:`to_dict` as JSON text (strict: no NaN); with ``path`` also written there
        atomically."""
        text = json.dumps(self.to_dict(), indent=indent, allow_nan=False, ensure_ascii=False)
        if path is not None:
            from ._io import atomic_path

            atomic_path(path, lambda tmp: tmp.write_text(text + "\n", encoding="utf-8"))
        return text


def _label(entry) -> str:
    from ._models import FitModel

    if isinstance(entry, FitModel):
        return entry.name
    if isinstance(entry, str):
        return entry.strip()
    raise TypeError(f"models must be names or socbjax.FitModel objects, got {type(entry).__name__}")


def _per_model(option, label: str, names, default, keyed: bool = False):
    """A per-model value: ``option[label]`` when ``option`` is a dict keyed by model names
    (``keyed``: any dict; else one whose keys are all model ``names``), else ``option`` itself
    for every model (``default`` when None)."""
    if isinstance(option, dict) and (keyed or (option and set(option) <= set(names))):
        value = option.get(label)
        return default if value is None else value
    return default if option is None else option


def _row(label, free, result=None, error=None) -> dict:
    nan = math.nan
    if result is None:
        return dict(model=label, free=tuple(free), n_parameters=len(free), m=0, rss=nan, noise=nan, noise_source="",
                    chi2_reduced=nan, aic=nan, bic=nan, delta_aic=nan, delta_bic=nan, misfit=None, converged=False,
                    values={}, standard_errors={}, error=error)
    goodness = result.goodness or {}
    return dict(model=label, free=tuple(result.names), n_parameters=int(result.n_parameters),
                m=int(result.force.size), rss=float(goodness.get("rss", nan)), noise=float(result.noise),
                noise_source=result.noise_source, chi2_reduced=float(result.chi2_reduced), aic=float(result.aic),
                bic=float(result.bic), delta_aic=nan, delta_bic=nan, misfit=bool(result.misfit),
                converged=bool(result.converged), values=dict(result.values),
                standard_errors=dict(result.standard_errors), error=None)


def _fit_one(curve, entry, label, free, options, settings, sigma, progress):
    """(result, error): the fit of one model, or why there is none."""
    from ._fit import fit
    from ._models import FIT_MODELS

    if isinstance(entry, str) and label not in FIT_MODELS:
        return None, f"unknown model {label!r} (socbjax.FIT_MODELS has {', '.join(sorted(FIT_MODELS))})"
    try:
        return fit(curve, entry if not isinstance(entry, str) else label, free=free, settings=settings, sigma=sigma,
                   model_options=options if isinstance(entry, str) else None, progress=progress), None
    except (ValueError, ConvergenceError) as err:
        return None, f"{type(err).__name__}: {' '.join(str(err).split())}"


def compare_models(curve, models=("column", "unit-mesh", "lawn"), *, free=None, model_options=None, settings=None,
                   sigma=None, progress: bool = False, fitted: dict | None = None) -> ModelComparison:
    """Fit each of ``models`` to ``curve`` and compare them (module docstring): a
    :class:`ModelComparison` (``.table()``, ``.best``, ``.results[name]``, ``.to_json()``).

    curve : as for :func:`socbjax.fit` (a ForceCurve, or (compression µm, force pN)).
    models : names (``socbjax.FIT_MODELS``) or :class:`socbjax.FitModel` objects; unknown names
        get a row saying so.
    free : a dict model name -> free parameters (missing names: ``DEFAULT_FREE``, "EI" for
        the column and outcrop, ("EI", "branch_angle") for the unit mesh, ("EI",
        "contact_point", "baseline") for the lawn), or one tuple for every model.
    model_options : a dict model name -> builder options (e.g. ``{"column": {"dim": 2}}``), or
        one dict of options for every model given by name (e.g. ``{"dim": 2}``).
    settings, sigma, progress : as for :func:`socbjax.fit`, the same for every model.
    fitted : model name -> an existing :class:`socbjax.FitResult` of this curve, used instead
        of fitting that model again.
    """
    entries = [models] if isinstance(models, str) and "," not in models else models
    entries = [m for m in entries.split(",") if m.strip()] if isinstance(entries, str) else list(entries)
    labels = [_label(e) for e in entries]
    if len(set(labels)) != len(labels):
        raise ValueError(f"each model can be compared once, got {labels}")
    if not labels:
        raise ValueError("compare_models needs at least one model")
    from ._models import FIT_MODELS

    fitted = dict(fitted or {})
    rows, results = [], {}
    for k, (entry, label) in enumerate(zip(entries, labels, strict=True), 1):
        names = _per_model(free, label, labels, DEFAULT_FREE.get(label, ("EI",)), keyed=True)
        names = tuple(n.strip() for n in names.split(",")) if isinstance(names, str) else tuple(names)
        if label in fitted:
            result, error = fitted[label], None
        else:
            if progress:
                sys.stderr.write(f" compare: model {k}/{len(labels)}: {label}, free {', '.join(names)}\n")
            options = _per_model(model_options, label, {*labels, *FIT_MODELS}, None)
            result, error = _fit_one(curve, entry, label, names, options, settings, sigma, progress)
        rows.append(_row(label, names, result, error))
        if result is not None:
            results[label] = result
    converged = [r for r in rows if r["converged"] and math.isfinite(r["aic"])]
    best = min(converged, key=lambda r: r["aic"])["model"] if converged else None
    if converged:
        low_aic, low_bic = min(r["aic"] for r in converged), min(r["bic"] for r in converged)
        for r in rows:
            if r["error"] is None:
                r["delta_aic"], r["delta_bic"] = r["aic"] - low_aic, r["bic"] - low_bic
    return ModelComparison(rows=tuple(rows), results=results, best=best)


def attach_comparison(result, curve, compare, model, *, free, model_options, settings, sigma, progress, dim=None):
    """``result`` (a FitResult of ``model``) with ``comparison``: :func:`compare_models` of
    ``compare`` plus this fit's model (reused, not refitted).  Models given by name that
    take a ``dim`` option get this fit's dimension ``dim``."""
    from . import _models

    FIT_MODELS = _models.FIT_MODELS
    options_of = _models.builder_options

    entries = [m.strip() for m in compare.split(",") if m.strip()] if isinstance(compare, str) else list(compare)
    labels = [_label(e) for e in entries]
    if result.model not in labels:
        entries, labels = [model, *entries], [result.model, *labels]
    options = {}
    for entry, label in zip(entries, labels, strict=True):
        if label == result.model:
            options[label] = model_options
        elif isinstance(entry, str) and dim is not None and label in FIT_MODELS and "dim" in options_of(label):
            options[label] = {"dim": dim}
    comparison = compare_models(curve, entries, free={result.model: free}, model_options=options, settings=settings,
                                sigma=sigma, progress=progress, fitted={result.model: result})
    return dataclasses.replace(result, comparison=comparison)
