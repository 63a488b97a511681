"""AFM force curves: read, preprocess and reduce force–distance data (µm, pN).

:func:`load_curve` reads a native CSV/TSV file or, with the optional extra ``socbjax[afm]``
(afmformats), any AFM format afmformats supports (.jpk-force, .jpk-force-map, .ibw, .tab,
.h5, ...) into a :class:`ForceCurve`: compression (µm, positive when the probe compresses
the sample), force (pN, repulsive positive) and segment (0 approach, 1 retract) per point.

Native files (.csv, .tsv, .dat; .txt when its header has a ``force_*`` column) have a header
row of ``<quantity>_<unit>`` names: ``compression_um|nm|m``, ``force_pN|nN|N``,
``tip_position_um|nm|m``, ``height_um|nm|m`` (also µm, mm, µN; units case-insensitive) and
an optional ``segment`` column (0/1 or approach/retract); other columns are ignored.  The
delimiter (tab, semicolon, comma, else whitespace) is taken from the header row; lines
starting with ``#`` are comments.

Positions follow the AFM convention (JPK, Asylum, afmformats): height and tip position
*decrease* toward the surface; tip position = height + force / k (cantilever deflection, k
the spring constant in N/m).  Preprocessing (``preprocess=True``), the usual force–distance
procedure:

1. Segments from the ``segment`` column.  A file labelling every point approach (Igor .ibw
   through afmformats; native files without the column) is split after the point closest
   to the surface when the points after it move back by more than 10% of the travel.  The
   approach must move *overall* toward the surface (median of its last 5% of points below
   that of its first 5% by more than half its range); noise may send single steps back.
2. Baseline: a straight line (``"auto"``, ``"linear"``) or a constant (``"constant"``) in the
   position coordinate (height, else tip position), least-squares fitted to the approach
   points in the half of the approach travel farthest from the surface, is subtracted from
   every point (force offset and virtual deflection); ``None`` skips it.  Noise = 1.4826 ×
   median absolute deviation of the residuals there.
3. Contact point (``"auto"``): along the approach toward the surface, the tip position of
   the last point where the corrected force crosses from ≤ noise to > noise.  A slowly
   rising (Hertz-like) force puts it where the force reaches a few noise levels.  If the
   force never exceeds 10 noise levels there is no contact (ValueError).  A float is taken
   as the contact tip position in µm.
4. Compression = contact tip position − tip position, positive past contact.  Points before
   contact (negative compression) are kept; ``curve.select(min_compression=0)`` drops them.

Files giving only compression count as already preprocessed: only the segment is chosen,
and compression must grow along the approach (shrink along the retract) with at most 25% of
the steps going backward.  ``preprocess=False`` returns such a file as is, all segments.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ._curve_files import (
    NATIVE_SUFFIXES,
    check_finite,
    is_native,
    read_afmformats,
    read_native,
)

__all__ = ["ForceCurve", "hysteresis_energy", "load_curve", "save_curve"]

_BASELINE_FRACTION = 0.5  # far part of the approach travel used for the baseline
_MAX_BACKWARD = 0.25  # compression files: largest fraction of backward steps
_SPLIT_RETURN = 0.1  # return travel (fraction) that marks an unlabelled retract
_MIN_CONTACT_SNR = 10.0  # contact needs a force above this many noise levels


def hysteresis_energy(c_approach, f_approach, c_retract, f_retract, n: int = 512) -> float:
    """∫ F_approach dc − ∫ F_retract dc (pN·µm = aJ) over [0, the smaller of the two branches'
    largest compressions], each branch sorted by compression and interpolated linearly on
    ``n`` common points; NaN when the branches share no contact range."""
    branches = []
    for c, f in ((c_approach, f_approach), (c_retract, f_retract)):
        c, f = np.asarray(c, float), np.asarray(f, float)
        order = np.argsort(c, kind="stable")
        branches.append((c[order], f[order]))
    top = min(branches[0][0].max(), branches[1][0].max())
    if not top > 0:
        return float("nan")
    grid = np.linspace(0.0, top, n)
    a, r = (np.interp(grid, c, f) for c, f in branches)
    return float(np.trapezoid(a - r, grid))


@dataclass(frozen=True, eq=False)
class ForceCurve:
    """One AFM force curve in socbjax units (arrays are read-only copies).

    Parameters
    ----------
    compression : np.ndarray, shape (M,)
        Sample compression (µm), positive once the probe has moved past the contact point.
    force : np.ndarray, shape (M,)
        Force (pN), compressive/repulsive positive.
    segment : np.ndarray of int8, shape (M,), optional
        0 approach, 1 retract (default: all approach).
    metadata : dict
        Provenance and preprocessing record: source, format, spring constant (N/m), contact
        point (µm of tip position), baseline (pN), noise (pN), steps applied, ...
    """

    compression: np.ndarray
    force: np.ndarray
    segment: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        comp, force = np.array(self.compression, float), np.array(self.force, float)
        seg = np.zeros(comp.shape, np.int8) if self.segment is None else np.array(self.segment)
        cols = {"compression": comp, "force": force, "segment": seg}
        if any(a.ndim != 1 for a in cols.values()) or len({len(a) for a in cols.values()}) > 1:
            shapes = ", ".join(f"{k} {a.shape}" for k, a in cols.items())
            raise ValueError(f"ForceCurve columns must be 1-D of equal length, got {shapes}")
        check_finite({"compression": comp, "force": force}, "ForceCurve")
        if len(comp) < 3:
            raise ValueError(f"a ForceCurve needs at least 3 points, got {len(comp)}")
        if not np.isin(seg, (0, 1)).all():
            raise ValueError("ForceCurve segment values must be 0 (approach) or 1 (retract)")
        cols["segment"] = seg.astype(np.int8)
        for name, arr in cols.items():
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "metadata", dict(self.metadata))

    def __len__(self) -> int:
        return len(self.compression)

    def _subset(self, mask: np.ndarray, what: str) -> ForceCurve:
        if mask.sum() < 3:
            raise ValueError(f"{what} leaves {int(mask.sum())} points; a ForceCurve needs at least 3")
        return ForceCurve(self.compression[mask], self.force[mask], self.segment[mask], self.metadata)

    @property
    def approach(self) -> ForceCurve:
        """The approach points (segment 0)."""
        return self._subset(self.segment == 0, "selecting the approach")

    @property
    def retract(self) -> ForceCurve:
        """The retract points (segment 1)."""
        return self._subset(self.segment == 1, "selecting the retract")

    def hysteresis(self) -> float:
        """Energy dissipated over the cycle (pN·µm = aJ): ∫ F_approach dc − ∫ F_retract dc over
        the compressions in contact (c ≥ 0) that both branches cover; NaN without a retract."""
        if not np.any(self.segment == 1) or not np.any(self.segment == 0):
            return float("nan")
        a, r = self.segment == 0, self.segment == 1
        return hysteresis_energy(self.compression[a], self.force[a], self.compression[r], self.force[r])

    def select(self, max_compression: float | None = None,
               min_compression: float | None = None) -> ForceCurve:
        """Points with ``min_compression <= compression <= max_compression`` (µm; None =
        unbounded); ``select(min_compression=0)`` keeps the points in contact."""
        mask = np.ones(len(self), bool)
        if max_compression is not None:
            mask &= self.compression <= max_compression
        if min_compression is not None:
            mask &= self.compression >= min_compression
        return self._subset(mask, f"select(max_compression={max_compression}, min_compression={min_compression})")

    def binned(self, n_bins: int) -> ForceCurve:
        """Mean compression and force per compression bin, per segment.

        The curve's compression range is cut into ``n_bins`` equal bins; each segment gets at
        most ``n_bins`` points (empty bins skipped), the approach in increasing and the
        retract in decreasing compression.  ``metadata["bin_counts"]`` holds how many points
        each output point averages (fit weights), ``metadata["bin_span"]`` the [first, last]
        compression (µm) of those points.
        """
        if not isinstance(n_bins, numbers.Integral) or n_bins < 3:
            raise ValueError(f"n_bins must be an integer >= 3, got {n_bins!r}")
        edges = np.linspace(self.compression.min(), self.compression.max(), int(n_bins) + 1)
        parts = []
        for s in (0, 1):
            c, f = self.compression[self.segment == s], self.force[self.segment == s]
            if c.size:
                idx = np.clip(np.searchsorted(edges, c, side="right") - 1, 0, n_bins - 1)
                counts = np.bincount(idx, minlength=n_bins)
                keep = np.flatnonzero(counts)[:: 1 if s == 0 else -1]
                first, last = np.full(n_bins, np.inf), np.full(n_bins, -np.inf)
                np.minimum.at(first, idx, c)
                np.maximum.at(last, idx, c)
                parts.append((np.bincount(idx, c, n_bins)[keep] / counts[keep],
                              np.bincount(idx, f, n_bins)[keep] / counts[keep],
                              np.full(keep.size, s, np.int8), counts[keep], np.stack([first[keep], last[keep]], 1)))
        comp, force, seg, counts, span = (np.concatenate(p) for p in zip(*parts, strict=True))
        return ForceCurve(comp, force, seg, {**self.metadata, "binned": int(n_bins),
                                             "bin_counts": counts.tolist(), "bin_span": span.tolist()})


def _spring(k: Any, source: str) -> float:
    """A validated spring constant (N/m)."""
    try:
        k = float(k)
    except (TypeError, ValueError):
        raise ValueError(f"spring constant from {source} must be a number in N/m, got {k!r}") from None
    if not (math.isfinite(k) and k > 0):
        raise ValueError(f"spring constant from {source} must be positive and finite (N/m), got {k}")
    return k


# ---------------------------------------------------------------- preprocessing
def _segments(data: dict[str, np.ndarray], k: float | None, from_afmformats: bool) -> str:
    """Fill ``data["segment"]``, splitting after the point closest to the surface when the
    file gives no retract labels (rule in the module docstring); return how."""
    seg = data.get("segment")
    if seg is not None and (not from_afmformats or (seg == 1).any()):
        return "file"
    if "tip_position" in data:
        z = data["tip_position"]
    elif "height" in data:
        z = data["height"] + (data["force"] * 1e-6 / k if k else 0.0)
    else:
        z = -data["compression"]
    i = int(np.argmin(z))
    split = 0 < i < len(z) - 1 and z[-1] - z[i] > _SPLIT_RETURN * (z[0] - z[i])
    data["segment"] = (np.arange(len(z)) > i).astype(np.int8) if split else np.zeros(len(z), np.int8)
    how = "split after the tip position closest to the surface" if split else "all points approach"
    return f"{how} ({'the file labels every point approach' if from_afmformats else 'no segment column'})"


def _check_toward_surface(z: np.ndarray, what: str) -> None:
    """Raise unless positions ``z`` (µm, time order) move overall toward the surface."""
    n = max(1, len(z) // 20)
    travel = np.median(z[:n]) - np.median(z[-n:])
    if not travel > 0.5 * np.ptp(z):
        raise ValueError(f"the {what} does not move overall toward the surface (net {-travel:+.4g} µm over "
                         f"a range of {np.ptp(z):.4g} µm): heights and tip positions must decrease toward "
                         "the surface (AFM convention); negate the column or check the segment column")


def _check_compression(comp: np.ndarray, seg: np.ndarray) -> None:
    """Raise if more than 25% of a segment's steps go against its direction."""
    for s, name, sign in ((0, "approach", 1), (1, "retract", -1)):
        c = comp[seg == s]
        back = np.mean(sign * np.diff(c) < 0) if c.size > 1 else 0.0
        if back > _MAX_BACKWARD:
            raise ValueError(f"compression is not monotonic: {back:.0%} of the {name} steps go backward "
                             f"(at most {_MAX_BACKWARD:.0%} allowed); sort the rows, add a segment column, "
                             "or give raw positions as tip_position_* instead")


def _contact_index(f: np.ndarray, noise: float) -> int:
    """Index of the contact point in forces ``f`` (pN) ordered toward the surface."""
    above = f > noise
    cross = np.flatnonzero(~above[:-1] & above[1:])
    if cross.size == 0 or f.max() < _MIN_CONTACT_SNR * noise:
        raise ValueError(f"no contact found: the baseline-corrected approach force stays below "
                         f"{_MIN_CONTACT_SNR:g} noise levels ({noise:.3g} pN each); check the segment or "
                         "pass contact_point=<tip position in µm>")
    return int(cross[-1])


def _preprocess(data: dict[str, np.ndarray], k: float | None, baseline: str | None,
                contact_point: float | str) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Baseline correction and contact point: ``(compression µm, force pN, metadata)``."""
    seg, force = data["segment"], data["force"]
    z = data["height"] if "height" in data else data["tip_position"]
    use_approach = (seg == 0).sum() >= 3  # else the retract, reversed in time
    order = np.flatnonzero(seg == 0) if use_approach else np.flatnonzero(seg == 1)[::-1]
    _check_toward_surface(z[order], "approach" if use_approach else "retract (reversed)")
    far = order[z[order] >= z[order].min() + (1 - _BASELINE_FRACTION) * np.ptp(z[order])]
    if far.size < 3:
        raise ValueError(f"the baseline region far from the surface has {far.size} points; need at least 3")
    deg = {"auto": 1, "linear": 1, "constant": 0, None: None}[baseline]
    coef = np.zeros(1) if deg is None else np.polyfit(z[far], force[far], deg)
    force = force - np.polyval(coef, z)
    noise = 1.4826 * float(np.median(np.abs(force[far] - np.median(force[far]))))
    tip = data["height"] + force * 1e-6 / k if "height" in data else data["tip_position"]
    steps = [] if deg is None else ["baseline:" + ("linear" if deg else "constant")]
    if contact_point == "auto":
        c = float(tip[order][_contact_index(force[order], noise)])
    else:
        c = float(contact_point)
    steps.append(f"contact_point:{'auto' if contact_point == 'auto' else 'given'}")
    z_contact = z[order][np.argmin(np.abs(tip[order] - c))]
    return c - tip, force, {
        "contact_point_um": c, "baseline_pN": float(np.polyval(coef, z_contact)),
        "baseline_slope_pN_per_um": float(coef[0]) if deg == 1 else 0.0,
        "baseline_coordinate": "height" if "height" in data else "tip_position",
        "baseline_region_um": [float(z[far].min()), float(z[far].max())], "noise_pN": noise,
        "steps": steps}


# ---------------------------------------------------------------- public functions
def _check_options(segment: str, baseline: str | None, contact_point: float | str) -> None:
    if segment not in ("approach", "retract", "both"):
        raise ValueError(f"segment must be 'approach', 'retract' or 'both', got {segment!r}")
    if baseline not in ("auto", "linear", "constant", None):
        raise ValueError(f"baseline must be 'auto', 'linear', 'constant' or None, got {baseline!r}")
    ok = contact_point == "auto" if isinstance(contact_point, str) else (
        isinstance(contact_point, numbers.Real) and math.isfinite(contact_point))
    if not ok:
        raise ValueError(f"contact_point must be 'auto' or a finite tip position in µm, got {contact_point!r}")


def _read(path: Path, columns: Mapping[str, str] | None, curve_index: int, k_arg: float | None
          ) -> tuple[dict[str, np.ndarray], dict[str, Any], float | None]:
    """Raw data (µm, pN), metadata and spring constant (N/m or None) of a file."""
    native = is_native(path)
    if native:
        data, meta = read_native(path, columns), {"format": "socbjax native text"}
    elif columns:
        raise ValueError("columns= renames native CSV/TSV header columns; it does not apply to afmformats files")
    else:
        data, meta = read_afmformats(path, curve_index)
    if len(data["force"]) < 3:
        raise ValueError(f"{path}: {len(data['force'])} data point(s); a force curve needs at least 3")
    k_file = meta.get("file_spring_constant_N_per_m")
    k = k_arg if k_arg is not None else None if k_file is None else _spring(k_file, f"the file {path.name}")
    meta.update(source=str(path), n_raw_points=len(data["force"]), spring_constant_N_per_m=k,
                spring_constant_source="argument" if k_arg is not None else "file" if k else None,
                segments_from=_segments(data, k, not native))
    return data, meta, k


def load_curve(path: str | Path, *, segment: Literal["approach", "retract", "both"] = "approach",
               spring_constant: float | None = None,
               baseline: Literal["auto", "linear", "constant"] | None = "auto",
               contact_point: float | Literal["auto"] = "auto", preprocess: bool = True,
               columns: Mapping[str, str] | None = None, curve_index: int = 0) -> ForceCurve:
    """Read an AFM force curve as compression (µm) and force (pN); see the module docstring.

    Parameters
    ----------
    path : str or Path
        Native .csv/.tsv/.dat/.txt file, or any file afmformats reads (extra ``socbjax[afm]``).
    segment : {"approach", "retract", "both"}
        Points returned (in time order).
    spring_constant : float, optional
        Cantilever spring constant (N/m); overrides the file's; needed for ``height_*`` columns.
    baseline : {"auto", "linear", "constant", None}
        Baseline subtracted from the force (fitted far from the surface); None skips it.
    contact_point : "auto" or float
        Automatic estimate, or the contact tip position in µm (file coordinate).
    preprocess : bool
        False returns a file that gives compression as is (all segments, units converted).
    columns : mapping, optional
        Renames native header columns, e.g. ``{"Indentation (nm)": "compression_nm"}``.
    curve_index : int
        Curve of a multi-curve afmformats file (force maps).

    Returns
    -------
    ForceCurve
        With metadata: source, format, spring constant, contact point, baseline, noise, steps.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ImportError
        A non-native file without afmformats installed.
    ValueError
        Empty file, too few points, NaNs, unknown units, missing columns, non-positive
        spring constant, non-monotonic compression, approach not toward the surface, no contact.
    """
    path = Path(path).expanduser()
    if not path.is_file():
        raise FileNotFoundError(f"AFM force-curve file not found: {path}")
    _check_options(segment, baseline, contact_point)
    k_arg = None if spring_constant is None else _spring(spring_constant, "spring_constant=")
    data, meta, k = _read(path, columns, curve_index, k_arg)
    raw = "tip_position" in data or "height" in data
    if not preprocess and "compression" not in data:
        raise ValueError(f"{path}: preprocess=False returns the file as is and needs a compression_* column; "
                         "this file gives positions: use preprocess=True")
    if preprocess and raw and "tip_position" not in data and k is None:
        raise ValueError(f"{path}: height data need the spring constant: pass spring_constant=<N/m> "
                         "(tip position = height + force / spring constant)")
    seg = data["segment"]
    if preprocess and raw:
        comp, force, pre = _preprocess(data, k, baseline, contact_point)
    else:
        if preprocess and (baseline != "auto" or contact_point != "auto"):
            raise ValueError(f"{path}: gives compression (taken as already preprocessed); baseline and "
                             "contact-point options need tip_position_* or height_* columns")
        comp, force, pre = data["compression"], data["force"], {"contact_point_um": None, "steps": []}
        _check_compression(comp, seg)
    mask = seg == (0 if segment == "approach" else 1)
    if not preprocess or segment == "both":
        mask = np.ones(len(seg), bool)
    elif mask.sum() < 3:
        raise ValueError(f"{path}: the file has {int(mask.sum())} {segment} points; need at least 3 "
                         "(check the segment column or choose another segment)")
    else:
        pre["steps"].insert(0, f"segment:{segment}")
    meta.update(pre, preprocessed=bool(preprocess), segment=segment if preprocess else "both")
    return ForceCurve(comp[mask], force[mask], seg[mask], meta)


def save_curve(curve: ForceCurve, path: str | Path) -> Path:
    """Write ``curve`` as a native CSV (``compression_um,force_pN,segment``), atomically.

    Written to a temporary file in the same folder, then renamed onto ``path``
    (``os.replace``).  ``load_curve(path, preprocess=False)`` gives back the same arrays
    (17 significant digits).  Returns ``path`` as a Path.
    """
    from ._io import atomic_path

    path = Path(path)
    if path.suffix.lower() not in (*NATIVE_SUFFIXES, ".txt"):
        raise ValueError(f"save_curve writes CSV: give a path ending in .csv (got {path.name!r})")
    source = str(curve.metadata.get("source", "")).replace("\n", " ")
    rows = zip(curve.compression, curve.force, curve.segment, strict=True)
    text = ("# socbjax ForceCurve: compression µm (positive = compressing), force pN, segment 0/1\n"
            f"# source: {source}\ncompression_um,force_pN,segment\n"
            + "".join(f"{c:.17g},{f:.17g},{s}\n" for c, f, s in rows))
    return atomic_path(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
