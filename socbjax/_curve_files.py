"""Reading AFM force-curve files into arrays (µm, pN): native CSV/TSV text and, with the
optional extra ``socbjax[afm]``, the instrument formats of afmformats.  Files are untrusted
input: oversized, binary or undecodable text and afmformats' own errors (which derive from
``BaseException``) all become one ``ValueError`` naming the file.  Formats and units: see
:mod:`socbjax._afm`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["MAX_TEXT_BYTES", "NATIVE_SUFFIXES", "check_finite", "is_native", "read_afmformats", "read_native"]

_LENGTH = {"m": 1e6, "mm": 1e3, "um": 1.0, "µm": 1.0, "μm": 1.0, "nm": 1e-3}  # → µm
_FORCE = {"n": 1e12, "un": 1e6, "µn": 1e6, "μn": 1e6, "nn": 1e3, "pn": 1.0}  # → pN
_QUANTITIES = {"compression": _LENGTH, "tip_position": _LENGTH, "height": _LENGTH, "force": _FORCE}
_ACCEPTED = ("compression_um|nm|m, force_pN|nN|N, tip_position_um|nm|m, height_um|nm|m "
             "(also µm, mm, µN; case-insensitive) and optional segment")
NATIVE_SUFFIXES = (".csv", ".tsv", ".dat")
_SEGMENT_NAMES = {"0": 0, "1": 1, "approach": 0, "retract": 1, "false": 0, "true": 1}


def check_finite(columns: Mapping[str, np.ndarray], where: str) -> None:
    """Raise ValueError naming how many NaN/inf values each column has, and their rows."""
    bad = {k: np.flatnonzero(~np.isfinite(v)) for k, v in columns.items()}
    bad = {k: v for k, v in bad.items() if v.size}
    if bad:
        parts = [f"{v.size} in {k} (rows {', '.join(map(str, v[:5]))}{', ...' if v.size > 5 else ''})"
                 for k, v in bad.items()]
        raise ValueError(f"{where}: {sum(v.size for v in bad.values())} NaN/infinite values: "
                         f"{'; '.join(parts)}; remove or fill those rows")


# ---------------------------------------------------------------- native text files
def _classify(name: str) -> tuple[str, float] | None:
    """``(quantity, scale to µm or pN)`` of a header name; None for an ignored column."""
    low = name.strip().lower()
    if low == "segment":
        return "segment", 1.0
    for quantity, units in _QUANTITIES.items():
        if low == quantity:
            raise ValueError(f"column {name!r} has no unit suffix; accepted names: {_ACCEPTED}")
        if low.startswith(quantity + "_"):
            unit = low[len(quantity) + 1:]
            if unit not in units:
                raise ValueError(f"column {name!r}: unknown unit {unit!r}; accepted names: {_ACCEPTED}")
            return quantity, units[unit]
    return None


def _parse_column(table: list[tuple[int, list[str]]], j: int, name: str, path: Path) -> np.ndarray:
    """Column ``j`` of the split rows in µm/pN (segment: int8 0/1)."""
    q, scale = _classify(name)
    out = np.empty(len(table), np.int8 if q == "segment" else float)
    for i, (lineno, toks) in enumerate(table):
        try:
            out[i] = _SEGMENT_NAMES[toks[j].lower()] if q == "segment" else float(toks[j])
        except (KeyError, ValueError):
            hint = " (use 0/1 or approach/retract)" if q == "segment" else ""
            raise ValueError(f"{path}: line {lineno}: cannot read {toks[j]!r} in column {name!r}{hint}") from None
    return out if q == "segment" else out * scale


MAX_TEXT_BYTES = 512 * 2**20  # a force curve as text is a few MB; larger files are refused, not read


def _text_lines(path: Path) -> list[str]:
    """The lines of a native text curve, refusing binary or oversized files by name."""
    size = path.stat().st_size
    if size > MAX_TEXT_BYTES:
        raise ValueError(f"{path}: {size / 2**20:.0f} MiB is too large for a text force curve (limit "
                         f"{MAX_TEXT_BYTES // 2**20} MiB); average or crop it first")
    raw = path.read_bytes()
    if b"\0" in raw:
        raise ValueError(f"{path}: a binary file, not a CSV/TSV text curve (it holds NUL bytes); instrument files "
                         "(.jpk-force, .ibw, ...) are read with socbjax[afm] under their own extension")
    try:
        return raw.decode("utf-8-sig").splitlines()
    except UnicodeDecodeError as err:
        raise ValueError(f"{path}: not UTF-8 text (byte {err.start} is 0x{raw[err.start]:02x}); save the curve as "
                         "UTF-8 CSV/TSV, or give an instrument file under its own extension") from None


def read_native(path: Path, columns: Mapping[str, str] | None) -> dict[str, np.ndarray]:
    """Read a native file into ``{quantity: array in µm/pN, "segment": int8 array}``."""
    lines = [(i + 1, ln) for i, ln in enumerate(_text_lines(path)) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ValueError(f"{path}: empty file (no header row); accepted column names: {_ACCEPTED}")
    delim = next((d for d in ("\t", ";", ",") if d in lines[0][1]), None)
    split = (lambda s: [t.strip() for t in s.split(delim)]) if delim else str.split
    names = [(columns or {}).get(n, n) for n in split(lines[0][1])]
    found = [kind[0] for kind in map(_classify, names) if kind]
    if dup := sorted({q for q in found if found.count(q) > 1}):
        raise ValueError(f"{path}: more than one {dup[0]} column in {names}; keep one")
    if "force" not in found:
        raise ValueError(f"{path}: missing force column (force_pN, force_nN or force_N) in {names}; "
                         f"accepted names: {_ACCEPTED}")
    if not {"compression", "tip_position", "height"} & set(found):
        raise ValueError(f"{path}: missing position column: need compression_*, tip_position_* or "
                         f"height_* (with spring_constant) in {names}; accepted names: {_ACCEPTED}")
    table = [(n, split(line)) for n, line in lines[1:]]
    if not table:
        raise ValueError(f"{path}: no data rows below the header")
    for lineno, toks in table:
        if len(toks) != len(names):
            raise ValueError(f"{path}: line {lineno} has {len(toks)} fields, the header has {len(names)}")
    used = [(j, n, _classify(n)[0]) for j, n in enumerate(names) if _classify(n)]
    data = {q: _parse_column(table, j, n, path) for j, n, q in used}
    check_finite({n: data[q] for _, n, q in used if q != "segment"}, str(path))
    return data


def is_native(path: Path) -> bool:
    """Native suffix, or a .txt file whose header row has a ``force_<unit>`` column."""
    suffix = path.suffix.lower()
    if suffix != ".txt":
        return suffix in NATIVE_SUFFIXES
    if path.stat().st_size > MAX_TEXT_BYTES:  # read_native refuses it by name; never scan a huge first line
        return True
    with path.open(encoding="utf-8-sig", errors="replace") as fh:
        header = next((ln for ln in fh if ln.strip() and not ln.lstrip().startswith("#")), "force_")
    return "force_" in header.lower()


# ---------------------------------------------------------------- afmformats files
def read_afmformats(path: Path, curve_index: int) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read curve ``curve_index`` with afmformats: ``(data in µm/pN, metadata)``."""
    try:
        import afmformats
    except ImportError as exc:
        raise ImportError(f"reading {path.suffix or 'extension-less'} files needs the optional extra: "
                          "pip install 'socbjax[afm]' (afmformats); native files are .csv/.tsv/.dat/.txt"
                          ) from exc
    if path.suffix not in afmformats.supported_extensions:
        raise ValueError(f"{path}: unsupported file type {path.suffix!r}; use a native .csv/.tsv/.dat/.txt "
                         f"file or one of afmformats' {afmformats.supported_extensions}")
    from afmformats.errors import AFMFileFormatError, MissingMetaDataError
    from afmformats.meta import MetaDataMissingError

    try:
        curves = afmformats.load_data(path)
    # afmformats' own errors derive from BaseException, which `except Exception` misses
    except (Exception, AFMFileFormatError, MissingMetaDataError, MetaDataMissingError) as exc:  # noqa: BLE001
        raise ValueError(f"{path}: afmformats could not read it ({type(exc).__name__}: {exc}); is it a complete "
                         f"{path.suffix} force-curve file?") from None
    if not 0 <= curve_index < len(curves):
        raise ValueError(f"{path}: curve_index {curve_index} out of range; the file has {len(curves)} curve(s)")
    d = curves[curve_index]
    cols = d.columns_innate
    pos = next((c for c in ("tip position", "height (measured)", "height (piezo)") if c in cols), None)
    if "force" not in cols or pos is None:
        raise ValueError(f"{path}: needs force and height or tip position columns, has {cols}")
    data = {"force": np.asarray(d["force"], float) * 1e12,
            "tip_position" if pos == "tip position" else "height": np.asarray(d[pos], float) * 1e6}
    if "segment" in cols:
        data["segment"] = np.asarray(d["segment"]).astype(np.int8)
    md = d.metadata
    return data, {"format": str(md.get("format", "afmformats")), "curve_index": curve_index,
                  "n_curves_in_file": len(curves), "position_column": pos,
                  "file_spring_constant_N_per_m": md.get("spring constant"),
                  "setpoint_N": md.get("setpoint"), "instrument": md.get("instrument")}
