"""Curve files of a batch: which files of a folder are curves (:func:`collect_curve_files`),
their identity and hash, and reading a curve from a measured file or a ``socbjax simulate``
result (:func:`read_curve`, :func:`curve_from_result`) with its network's dimension, which
:func:`check_dimension` compares with a model's.  Files are untrusted input: symbolic links,
hidden and non-regular files are skipped."""

from __future__ import annotations

import dataclasses
import hashlib
import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np

__all__ = ["CurveFile", "collect_curve_files", "sha256", "curve_from_result", "read_curve", "model_dim",
           "check_dimension"]

# Extensions read through afmformats (its supported_extensions, less the generic ones that a folder
# often holds for other reasons: .txt is taken only with a force_* header, .zip never).
_AFM_SUFFIXES = (".jpk-force", ".jpk-force-map", ".jpk-qi-data", ".jpk-qi-series", ".ibw", ".tab", ".h5")
_HDF5_SUFFIXES = (".h5", ".hdf5")
_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"


# ----------------------------------------------------------------------------- reading curves
@dataclasses.dataclass(frozen=True)
class CurveFile:
    """One input: ``path`` (as found), ``label`` (the path as given or joined to its folder)."""

    path: Path
    label: str

    @property
    def key(self) -> tuple:
        return (self.path.name, self.label)


def _readable_suffix(path: Path) -> bool:
    from ._curve_files import NATIVE_SUFFIXES, is_native

    suffix = path.suffix.lower()
    if suffix in NATIVE_SUFFIXES or suffix in _AFM_SUFFIXES or suffix in _HDF5_SUFFIXES:
        return True
    if suffix == ".txt":
        try:
            return is_native(path)
        except (OSError, UnicodeError):
            return True  # unreadable: its row says why
    return False


def collect_curve_files(paths: Iterable, *, exclude: Iterable = ()) -> list[CurveFile]:
    """The curve files named by ``paths`` (files and folders, see the module docstring),
    sorted by file name and then path, each file once; ``exclude`` holds paths never taken
    from a folder (the batch's own outputs).  A path that does not exist raises
    ``FileNotFoundError``; a folder without curve files adds nothing."""
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    excluded = {_identity(Path(p)) for p in exclude if Path(p).exists()}
    found: dict[tuple, CurveFile] = {}
    for given in paths:
        path = Path(given).expanduser()
        if path.is_dir():
            with os.scandir(path) as entries:
                for entry in sorted(entries, key=lambda e: e.name):
                    if entry.name.startswith(".") or entry.is_symlink() or not entry.is_file(follow_symlinks=False):
                        continue
                    child = path / entry.name
                    if _readable_suffix(child) and _identity(child) not in excluded:
                        found.setdefault(_identity(child), CurveFile(child, str(Path(given) / entry.name)))
        elif path.exists():
            found.setdefault(_identity(path), CurveFile(path, str(given)))
        else:
            raise FileNotFoundError(f"curve file or folder not found: {given}")
    return sorted(found.values(), key=lambda f: f.key)


def _identity(path: Path) -> tuple:
    st = path.stat()
    return (st.st_dev, st.st_ino)


def sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _socbjax_result(path: Path):
    """The :class:`socbjax.CompressionResult` in ``path``, or None when it is not a socbjax
    result file (another kind of HDF5 file, e.g. an afmformats export)."""
    if path.suffix.lower() not in _HDF5_SUFFIXES:
        return None
    with open(path, "rb") as fh:
        if fh.read(8) != _HDF5_MAGIC:
            return None
    from ._io import load

    try:
        return load(path)
    except ValueError as err:
        if "not a socbjax file" in str(err):
            return None
        raise


def curve_from_result(result, *, segment: str = "approach"):
    """The probe force curve of a :class:`socbjax.CompressionResult` (or of the result file at
    that path, written by ``socbjax simulate`` or :func:`socbjax.save`) as a
    :class:`socbjax.ForceCurve`: compression = probe displacement (µm), force (pN), the
    converged rows of the loading phase (``segment="approach"``), the unloading phase
    (``"retract"``) or both; not the settle row (u = 0 and no force, before the loading path
    starts on the settled network's force: the vertical rise of the force curve at u = 0).  ``metadata`` records the network's ``dim``,
    the run's ``parameters`` and ``network`` name, so that fits can refuse a model of another
    dimension (:func:`check_dimension`)."""
    from ._afm import ForceCurve
    from ._io import load

    source = None
    if isinstance(result, (str, os.PathLike)):
        source = str(result)
        result = load(result)
    if segment not in ("approach", "retract", "both"):
        raise ValueError(f"segment must be 'approach', 'retract' or 'both', got {segment!r}")
    phase, ok = np.asarray(result.phase), np.asarray(result.converged, bool)
    seg = (phase == 2).astype(np.int8)
    # the settle row (phase 0) is the probe's as-built position, before it bears on the network: at
    # u = 0 with zero force, where the loading path starts on the force of the settled network
    keep = ok & (phase > 0) & {"approach": seg == 0, "retract": seg == 1, "both": np.ones_like(ok)}[segment]
    if keep.sum() < 3:
        raise ValueError(f"{source or 'the result'} has {int(keep.sum())} converged {segment} rows; a force curve "
                         "needs at least 3 (simulate with unloading for a retract)")
    params = result.parameters
    meta = {"source": source, "format": "socbjax.compression", "dim": int(result.network.dim),
            "network": params.get("network"), "parameters": params, "contact_point_um": None, "segment": segment,
            "preprocessed": False, "steps": [], "n_raw_points": int(phase.size)}
    return ForceCurve(np.asarray(result.displacement, float)[keep], np.asarray(result.force, float)[keep], seg[keep],
                      meta)


def read_curve(path, *, segment: str = "approach", spring_constant: float | None = None, curve_index: int = 0,
               max_compression: float | None = None, **load_options):
    """A force curve from ``path``: a ``socbjax simulate`` result (:func:`curve_from_result`)
    or anything :func:`socbjax.load_curve` reads (``segment``, ``spring_constant``,
    ``curve_index`` and ``load_options`` go to it), cropped at ``max_compression`` (µm)."""
    from ._afm import load_curve

    path = Path(path).expanduser()
    result = _socbjax_result(path) if path.is_file() else None
    if result is not None:
        curve = curve_from_result(result, segment=segment)
        curve.metadata["source"] = str(path)
    else:
        curve = load_curve(path, segment=segment, spring_constant=spring_constant, curve_index=curve_index,
                           **load_options)
    if max_compression is not None:
        curve = curve.select(max_compression=max_compression)
    return curve


def model_dim(model) -> int | None:
    base = getattr(model, "base", None)
    return None if base is None else int(base.dim)


def check_dimension(curve, model, *, option: str = "model_options={'dim': %d}") -> None:
    """Refuse to fit a curve simulated with a network of one dimension with a model of the
    other (``ValueError`` naming both and the fix ``option % dim``).  Curves that do not
    know their dimension (measured curves) pass."""
    meta = getattr(curve, "metadata", None) or {}
    data_dim, dim = meta.get("dim"), model_dim(model)
    if data_dim is None or dim is None or int(data_dim) == dim:
        return
    network = meta.get("network") or "network"
    source = meta.get("source") or "the curve"
    raise ValueError(f"{source} was simulated with a {int(data_dim)}D {network} (dim={int(data_dim)}), but the "
                     f"{model.name} model is {dim}D (dim={dim}): planar and spatial networks carry different forces "
                     f"at the same EI, so the fit would be wrong; fit it with {option % int(data_dim)}")


# ----------------------------------------------------------------------------- one row
