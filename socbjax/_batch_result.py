"""The outcome of a batch fit, :class:`BatchResult`: rows, CSV and JSON written atomically,
a text table and the summary figure (:func:`socbjax.fit_batch` builds it)."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ._io import finite_json

__all__ = ["BatchResult"]


@dataclasses.dataclass
class BatchResult:
    """Outcome of :func:`socbjax.fit_batch`.

    rows : one dict per curve, in the batch's order (file name, path, curve index); keys
        :attr:`columns`.  Failed curves have ``status = "failed"``, the error in ``message``
        and NaN values.
    columns : the column order (``file``, ``sha256``, ``curve_index``, ``model``, ``status``,
        per free parameter P ``P`` and ``P_se``, then contact point, fit range, points,
        noise, χ²_red, misfit, R², rms, converged, message, warnings, figure).
    units : column -> unit.
    results : the :class:`socbjax.FitResult` per row (None for a failed curve); not written.
    settings : JSON-able record of the model, options and fit settings.
    """

    rows: list
    columns: list
    units: dict
    results: list = dataclasses.field(repr=False, default_factory=list)
    settings: dict = dataclasses.field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def n_failed(self) -> int:
        return sum(r["status"] == "failed" for r in self.rows)

    @property
    def n_converged(self) -> int:
        return sum(r["status"] == "converged" for r in self.rows)

    @property
    def exit_status(self) -> int:
        """0 when at least one curve was fitted (converged or not), else 1 (every curve failed)."""
        return 0 if self.n_failed < len(self.rows) else 1

    def to_dict(self) -> dict:
        from ._version import __version__

        return finite_json({"format": "socbjax.fit_batch", "format_version": 1, "socbjax_version": __version__,
                        "settings": self.settings, "columns": list(self.columns), "units": dict(self.units),
                        "n_curves": len(self.rows), "n_converged": self.n_converged, "n_failed": self.n_failed,
                        "rows": [dict(r) for r in self.rows]})

    def to_json(self, path) -> Path:
        """Write :meth:`to_dict` as strict JSON (NaN as null), atomically."""
        from ._io import atomic_path

        text = json.dumps(self.to_dict(), indent=2, allow_nan=False, ensure_ascii=False) + "\n"
        return atomic_path(Path(path).expanduser(), lambda tmp: tmp.write_text(text, encoding="utf-8"))

    def to_csv(self, path) -> Path:
        """Write the rows as CSV (header = :attr:`columns`; NaN as ``nan``, missing as empty),
        atomically: a failing write leaves a previous file at ``path`` untouched."""
        from ._io import atomic_path

        return atomic_path(Path(path).expanduser(), lambda tmp: _write_csv(tmp, self.columns, self.rows))

    def table(self) -> str:
        """A short text table: file, status, the fitted values ± SE, χ²_red."""
        free = self.settings.get("free", [])
        lines = []
        for r in self.rows:
            values = ", ".join(f"{n} = {_fmt(r.get(n))} ± {_fmt(r.get(n + '_se'))}" for n in free)
            tail = r["message"] if r["status"] == "failed" else f"{values}, χ²_red {_fmt(r['chi2_reduced'])}"
            lines.append(f"{_label(r)}: {r['status']}: {tail}")
        return "\n".join(lines)

    def summary_figure(self):
        """Histograms of every fitted parameter across the fitted curves (median marked; EI on
        a log axis with the literature EI of actin) and χ²_red per curve."""
        from ._fit_figure import plot_batch_summary

        return plot_batch_summary(self)

    def save_summary_figure(self, path, *, dpi: int = 150) -> Path:
        from ._io import atomic_path

        fig = self.summary_figure()
        return atomic_path(Path(path).expanduser(),
                           lambda tmp: fig.savefig(tmp, format="png", dpi=dpi, bbox_inches="tight"))


def _label(row: dict) -> str:
    name = Path(row["file"]).name
    return f"{name} #{row['curve_index']}" if row.get("curve_index") else name


def _fmt(value) -> str:
    if value is None:
        return "n/a"
    value = float(value)
    return "n/a" if not math.isfinite(value) else f"{value:.4g}"


def _csv_cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return "True" if value else "False"
    if isinstance(value, (float, np.floating)):
        return repr(float(value)) if math.isfinite(value) else "nan"
    return str(value)


def _write_csv(tmp: Path, columns: Sequence[str], rows: Sequence[dict]) -> None:
    with open(tmp, "w", encoding="utf-8", newline="") as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(columns)
        for row in rows:
            writer.writerow([_csv_cell(row.get(c)) for c in columns])
