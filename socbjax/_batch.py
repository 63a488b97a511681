"""Batch fits: one model fitted to many force curves (:func:`fit_batch`, ``socbjax fit A B DIR ... --out DIR``).

Inputs are files and folders.  A folder contributes the curve files at its top level that
:func:`socbjax.load_curve` reads, chosen by extension (native ``.csv``/``.tsv``/``.dat``, a
``.txt`` whose header has a ``force_*`` column, afmformats' ``.jpk-force``, ``.ibw``,
``.tab``, ``.h5``, ...; HDF5 results of ``socbjax simulate`` too); symbolic links, hidden
files and anything that is not a regular file are skipped (files are untrusted input: a link
could lead out of the folder).  The same file named twice (directly and through its folder)
is fitted once.  Multi-curve files (force maps) give one row per curve.

Every curve is fitted with the same model, options and settings, in the order of the file
names (then the full path, then the curve index): the rows, the figure names and the files
written do not depend on the order of the arguments.  A curve that cannot be read or fitted
(unreadable file, ``FitRangeError``, ``ConvergenceError``, a model of another dimension than
the simulated network) gives a row with its error message and NaN values; the batch goes on.

Outputs (``out=DIR``), each written atomically (a temporary file in ``DIR``, then
``os.replace``): ``results.csv`` and ``results.json`` (one row per curve, the columns in
:data:`BASE_COLUMNS` around the fitted values and their standard errors), ``<stem>.png`` (the
fit figure of each fitted curve) and ``summary.png`` (histograms of the fitted values across
curves with their median, the literature EI of actin, and χ²_red per curve).

The dimension rule: every builder, fit model and command defaults to ``dim=3``; planar
problems are opt-in with ``dim=2``.  A curve read from a ``socbjax simulate`` result knows the
dimension of its network (``curve.metadata["dim"]``), and fitting it with a model of another
dimension is refused (:func:`check_dimension`): a planar and a spatial unit mesh carry
different forces at the same EI.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ._curve_inputs import (
    CurveFile,
    check_dimension,
    collect_curve_files,
    curve_from_result,
    model_dim,
    read_curve,
    sha256,
)
from ._batch_result import BatchResult
from ._io import finite_json
from ._fit_model import contact_shift

__all__ = ["BatchResult", "fit_batch", "compare_batch", "collect_curve_files", "read_curve", "curve_from_result",
           "check_dimension", "ACTIN_EI", "BASE_COLUMNS"]

ACTIN_EI = 0.071  # pN·µm², the literature bending stiffness of an actin filament (persistence length ≈ 17 µm)

OUTPUT_NAMES = ("results.csv", "results.json", "summary.png", "comparison.json")

# Columns of every row, around the fitted values: file, sha256, model, curve, then per free
# parameter P the columns P and P_se, then these.
BASE_COLUMNS = ("file", "sha256", "curve_index", "model", "status")
TAIL_COLUMNS = ("contact_point_um", "contact_shift_um", "contact_point_source", "fit_min_compression_um",
                "fit_max_compression_um", "n_points", "noise_pN", "chi2_reduced", "misfit", "r_squared", "rms_pN",
                "converged", "message", "warnings", "figure")
_UNITS = {"contact_point_um": "µm (tip position, the file's coordinate)", "contact_shift_um": "µm (along compression)",
          "fit_min_compression_um": "µm", "fit_max_compression_um": "µm", "noise_pN": "pN", "rms_pN": "pN",
          "chi2_reduced": "1", "r_squared": "1"}


def _nan_if_missing(value) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        return math.nan
    return value


def _contact(result, curve) -> tuple[float, float, str]:
    """(contact tip position µm or NaN, compression at which the model meets the sample µm,
    source).  The model sees u = c + contact_offset − contact_point: contact where c =
    contact_point − contact_offset, i.e. at tip position (curve's contact) − that shift."""
    values, free = result.values, result.names
    base = (curve.metadata or {}).get("contact_point_um") if curve is not None else None
    base = math.nan if base is None else float(base)
    fitted = [n for n in ("contact_point", "contact_offset") if n in free]
    if not fitted:
        return base, 0.0, "curve"
    shift = -float(contact_shift(values))
    return base - shift, shift, "fitted " + " and ".join(fitted)


def _row(entry: CurveFile, digest: str, curve_index: int, model_name: str, free: Sequence[str], result=None,
         curve=None, error: str | None = None, figure: str = "") -> dict:
    row: dict[str, Any] = {"file": entry.label, "sha256": digest, "curve_index": curve_index, "model": model_name}
    names = list(free) if result is None else list(dict.fromkeys([*free, *result.names]))
    for name in names:
        ok = result is not None and name in result.names
        row[name] = float(result.values[name]) if ok else math.nan
        row[f"{name}_se"] = float(result.standard_errors[name]) if ok else math.nan
    if result is None:
        row.update(status="failed", contact_point_um=math.nan, contact_shift_um=math.nan, contact_point_source="",
                   fit_min_compression_um=math.nan, fit_max_compression_um=math.nan, n_points=0, noise_pN=math.nan,
                   chi2_reduced=math.nan, misfit=None, r_squared=math.nan, rms_pN=math.nan, converged=False,
                   message=error or "", warnings="", figure="")
        return row
    c = np.asarray(result.compression, float)
    point, shift, source = _contact(result, curve)
    misfit = getattr(result, "misfit", None)
    row.update(status="converged" if result.converged else "not converged", contact_point_um=point,
               contact_shift_um=shift, contact_point_source=source, fit_min_compression_um=float(c.min()),
               fit_max_compression_um=float(c.max()), n_points=int(c.size),
               noise_pN=_nan_if_missing(getattr(result, "noise", math.nan)),
               chi2_reduced=_nan_if_missing(getattr(result, "chi2_reduced", math.nan)),
               misfit=None if misfit is None else bool(misfit), r_squared=float(result.r_squared),
               rms_pN=float(result.rms), converged=bool(result.converged), message=str(result.message),
               warnings="; ".join(" ".join(str(w).split()) for w in result.warnings), figure=figure)
    return row


def _error_text(err: BaseException) -> str:
    from .cli import _one_line

    text = _one_line(err)
    user = isinstance(err, (ValueError, TypeError, OSError, ImportError))
    return text if user or type(err).__name__ == "ConvergenceError" else f"{type(err).__name__}: {text}"


# ----------------------------------------------------------------------------- the batch
def prepare_folder(out, what: str = "out") -> Path:
    """Check (before any work) that ``out`` is a folder, or can be created as one (its parent
    exists), and that files can be written in it; returns it (created)."""
    from ._io import check_output_path

    folder = Path(out).expanduser()
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{what} {folder} exists and is not a folder; a batch writes results.csv, results.json and "
                         "PNG files into a folder")
    if not folder.exists():
        check_output_path(folder.parent / ".socbjax-write-test", what)  # the parent: exists, writable
        folder.mkdir()
    for name in OUTPUT_NAMES:
        check_output_path(folder / name, f"{what} {name}")
    return folder


class _Names:
    """Unique figure names ``<stem>.png`` (``<stem>-2.png``, ... for clashes) in batch order."""

    def __init__(self):
        self.used = {n.lower() for n in OUTPUT_NAMES}

    def __call__(self, stem: str) -> str:
        name, k = f"{stem}.png", 1
        while name.lower() in self.used:
            k += 1
            name = f"{stem}-{k}.png"
        self.used.add(name.lower())
        return name


def _free_names(free) -> tuple:
    return tuple(n.strip() for n in free.split(",") if n.strip()) if isinstance(free, str) else tuple(free)


def _check_options(model, fit_kwargs: dict) -> None:
    """The errors every curve would give (unknown parameters, free and fixed at once,
    non-identifiable sets), raised once before any curve is read."""
    from ._fit_problem import check_identifiable, parameter_table

    _, free, fixed, _ = parameter_table(model, _free_names(fit_kwargs.get("free", ("EI",))), fit_kwargs.get("fixed"),
                                         fit_kwargs.get("initial"), fit_kwargs.get("bounds"))
    check_identifiable(model, free, fixed)


def _curves_of(entry: CurveFile, read: Callable) -> Iterable[tuple[int, Any, str | None]]:
    """(curve index, curve or None, error) for every curve of the file (force maps: several)."""
    try:
        curve = read(entry.path, 0)
    except Exception as err:  # noqa: BLE001  (untrusted files: any failure is this curve's row)
        yield 0, None, _error_text(err)
        return
    yield 0, curve, None
    for index in range(1, int(curve.metadata.get("n_curves_in_file") or 1)):
        try:
            yield index, read(entry.path, index), None
        except Exception as err:  # noqa: BLE001
            yield index, None, _error_text(err)


def fit_batch(paths, model="unit-mesh", *, out=None, segment: str | None = None, spring_constant: float | None = None,
              max_compression: float | None = None, figures: bool = True, report: Callable[[str], Any] | None = None,
              _cli_fixes: dict | None = None, _dim_option: str = "model_options={'dim': %d}", **fit_kwargs) -> BatchResult:
    """Fit ``model`` to every curve in ``paths`` (files and folders; see the module docstring).

    Parameters
    ----------
    paths : a path or paths of curve files and folders.
    model : a fit model name or :class:`socbjax.FitModel`, built once for all curves
        (``model_options=`` in ``fit_kwargs`` go to its constructor, e.g. ``{"dim": 2}``).
    out : folder for ``results.csv``, ``results.json``, ``<stem>.png`` per fitted curve and
        ``summary.png`` (created if missing; its parent must exist); None writes nothing.
    segment : the curve segment read (default: "approach", or "retract" when
        ``settings.branch`` is "unloading"); ``spring_constant`` (N/m) overrides the files';
        ``max_compression`` (µm) crops every curve.
    figures : write the per-curve and summary figures (with ``out``).
    report : called with one line per curve (``"[3/12] a.jpk-force: EI = … ± … pN·µm², χ²_red …"``),
        e.g. ``print``.
    fit_kwargs : :func:`socbjax.fit`'s keywords (``free``, ``fixed``, ``initial``,
        ``bounds``, ``sigma``, ``settings``, ``progress``).

    Returns a :class:`BatchResult`.  Raises before any fit for option errors that every
    curve would share (unknown model or parameters, a folder that cannot be written, no
    curve files at all); errors of single curves become failed rows.
    """
    from ._fit import FitSettings, fit
    from ._fit_figure import save_fit_figure
    from ._fit_problem import FitRangeError
    from ._models import make_fit_model

    paths = [paths] if isinstance(paths, (str, os.PathLike)) else list(paths)
    fit_kwargs = dict(fit_kwargs)
    options = fit_kwargs.pop("model_options", None) or {}
    fit_model = make_fit_model(model, **options)
    _check_options(fit_model, fit_kwargs)
    free = _free_names(fit_kwargs.pop("free", ("EI",)))
    settings = fit_kwargs.get("settings") or FitSettings()
    segment = segment or ("retract" if settings.branch == "unloading" else "approach")
    entries = _entries(paths, out)
    folder = prepare_folder(out, "out") if out is not None else None
    cli, option = _cli_fixes, _dim_option

    def read(path, index):
        return read_curve(path, segment=segment, spring_constant=spring_constant, curve_index=index,
                          max_compression=max_compression)

    names, rows, results = _Names(), [], []
    for k, entry in enumerate(entries, 1):
        try:
            digest = sha256(entry.path)
        except OSError as err:
            curves = [(0, None, _error_text(err))]
            digest = ""
        else:
            curves = _curves_of(entry, read)
        for index, curve, error in curves:
            result, figure, note = None, "", None
            if curve is not None:
                try:
                    check_dimension(curve, fit_model, option=option)
                    result = fit(curve, fit_model, free=free, **fit_kwargs)
                except FitRangeError as err:
                    error = _one(err.describe(cli)) if cli else _error_text(err)
                except Exception as err:  # noqa: BLE001  (the batch goes on; the row says why)
                    error = _error_text(err)
            if result is not None and folder is not None and figures:
                figure = names(entry.path.stem if not _multi(curve) else f"{entry.path.stem}-{index}")
                try:
                    save_fit_figure(result, folder / figure, title=_title(entry, curve, index))
                except OSError as err:
                    figure, note = "", f"figure not written: {_error_text(err)}"
            row = _row(entry, digest, index, fit_model.name, free, result, curve, error, figure)
            if note:
                row["warnings"] = "; ".join(filter(None, [row["warnings"], note]))
            rows.append(row)
            results.append(result)
            if report is not None:
                report(_progress_line(k, len(entries), row, result))
    fitted = [r for r in results if r is not None]
    names_all = list(dict.fromkeys([*free, *(n for r in fitted for n in r.names)]))
    units = dict(_UNITS)
    for r in fitted:
        for n in r.names:
            units.setdefault(n, r.units.get(n, ""))
            units.setdefault(f"{n}_se", r.units.get(n, ""))
    columns = [*BASE_COLUMNS, *[c for n in names_all for c in (n, f"{n}_se")], *TAIL_COLUMNS]
    batch = BatchResult(rows=[{c: r.get(c, math.nan) for c in columns} for r in rows], columns=columns, units=units,
                        results=results, settings=_settings_record(fit_model, options, free, fit_kwargs, settings,
                                                                   segment, spring_constant, max_compression))
    if folder is not None:
        batch.to_csv(folder / "results.csv")
        batch.to_json(folder / "results.json")
        if figures:
            batch.save_summary_figure(folder / "summary.png")
    return batch


def _entries(paths: list, out) -> list[CurveFile]:
    """The curve files of ``paths`` (never the batch's own outputs in ``out``); ValueError if none."""
    exclude = [Path(out).expanduser() / n for n in OUTPUT_NAMES] if out is not None else []
    entries = collect_curve_files(paths, exclude=exclude)
    if not entries:
        raise ValueError(f"no curve files in {', '.join(map(str, paths)) or '(no paths)'}: a folder contributes its "
                         ".csv/.tsv/.dat files, .txt files with a force_* column, and .jpk-force, .jpk-force-map, .ibw, "
                         ".tab and .h5 files (no symbolic links, hidden files or sub-folders)")
    return entries


def _one(text: str) -> str:
    return " ".join(text.split())


def _multi(curve) -> bool:
    return curve is not None and int(curve.metadata.get("n_curves_in_file") or 1) > 1


def _title(entry: CurveFile, curve, index: int) -> str:
    return entry.path.name if not _multi(curve) else f"{entry.path.name} #{index}"


def _progress_line(k: int, total: int, row: dict, result) -> str:
    name = Path(row["file"]).name + (f" #{row['curve_index']}" if row["curve_index"] else "")
    head = f"[{k}/{total}] {name}"
    if result is None:
        return f"{head}: FAILED: {row['message']}"
    parts = [f"{n} = {row[n]:.4g} ± {row[n + '_se']:.2g} {result.units.get(n, '')}".rstrip() for n in result.names]
    chi2 = row["chi2_reduced"]
    parts.append(f"χ²_red {chi2:.3g}" if math.isfinite(chi2) else f"R² {row['r_squared']:.3g}")
    status = "" if result.converged else f" (not converged: {result.message})"
    flag = " [misfit]" if row.get("misfit") else ""
    return f"{head}: {', '.join(parts)}{flag}{status}"


def _settings_record(model, options, free, fit_kwargs, settings, segment, spring_constant, max_compression) -> dict:
    def plain(value):
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
        if isinstance(value, dict):  # sorted: the record does not depend on the order options were given in
            return {str(k): plain(v) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
        if isinstance(value, (list, tuple)):
            return [plain(v) for v in value]
        if isinstance(value, (int, float, str, bool)) or value is None:
            return value
        return repr(value)

    return finite_json({"model": model.name, "dim": model_dim(model), "model_options": plain(dict(options)),
                    "free": list(free), "fixed": plain(dict(fit_kwargs.get("fixed") or {})),
                    "initial": plain(dict(fit_kwargs.get("initial") or {})),
                    "bounds": plain(dict(fit_kwargs.get("bounds") or {})), "fit_settings": plain(settings),
                    "segment": segment, "spring_constant_N_per_m": spring_constant,
                    "max_compression_um": max_compression})


# ----------------------------------------------------------------------------- model comparison
def compare_batch(paths, models: Sequence[str], *, out=None, segment: str = "approach",
                  spring_constant: float | None = None, max_compression: float | None = None,
                  report: Callable[[str], Any] | None = None, **compare_kwargs) -> dict:
    """:func:`socbjax.compare_models` on every curve of ``paths`` (order as for
    :func:`fit_batch`); ``report`` receives each curve's table.  With ``out`` writes
    ``out/comparison.json`` (atomically): ``{"models": [...], "curves": [{"file", "sha256",
    "curve_index", "comparison" (the comparison's ``to_dict()``) or "error"}]}``.  Returns
    that dict."""
    import socbjax

    from ._io import atomic_path
    from ._version import __version__

    if not hasattr(socbjax, "compare_models"):
        raise ImportError("this socbjax has no compare_models (model comparison); --compare needs it")
    paths = [paths] if isinstance(paths, (str, os.PathLike)) else list(paths)
    entries = _entries(paths, out)
    folder = prepare_folder(out, "out") if out is not None else None

    def read(path, index):
        return read_curve(path, segment=segment, spring_constant=spring_constant, curve_index=index,
                          max_compression=max_compression)

    curves_out = []
    for k, entry in enumerate(entries, 1):
        try:
            digest = sha256(entry.path)
        except OSError as err:
            curves_out.append({"file": entry.label, "sha256": "", "curve_index": 0, "error": _error_text(err)})
            continue
        for index, curve, error in _curves_of(entry, read):
            item = {"file": entry.label, "sha256": digest, "curve_index": index}
            if curve is not None:
                try:
                    comparison = socbjax.compare_models(curve, models=tuple(models), **compare_kwargs)
                    item["comparison"] = finite_json(json.loads(json.dumps(comparison.to_dict(), default=float)))
                    text = comparison.table()
                except Exception as err:  # noqa: BLE001
                    error = _error_text(err)
            if error is not None:
                item["error"] = error
                text = f"FAILED: {error}"
            curves_out.append(item)
            if report is not None:
                report(f"[{k}/{len(entries)}] {entry.path.name}{f' #{index}' if index else ''}:\n{text}")
    record = {"format": "socbjax.model_comparison_batch", "format_version": 1, "socbjax_version": __version__,
              "models": list(models), "curves": curves_out}
    if folder is not None:
        text = json.dumps(finite_json(record), indent=2, allow_nan=False, ensure_ascii=False) + "\n"
        atomic_path(folder / "comparison.json", lambda tmp: tmp.write_text(text, encoding="utf-8"))
    return record
