"""HDF5 input/output: :func:`save` / :func:`load` of a :class:`CompressionResult`, and the
checkpoints of long runs (:func:`save_checkpoint` / :func:`load_checkpoint`).

Layout of a result file (``format = "socbjax.compression"``, ``format_version = 1``)::

    /                 attrs: format, format_version, socbjax_version, created (UTC, ISO 8601),
                             result (name of a socbjax.RESULTS item; format 1: integer
                             status), parameters (JSON string)
    /path/<field>     one dataset per array field of the result (displacement, force, ...)
    /limit_points/    parallel datasets kind, step, displacement, force, phase (strings UTF-8)
    /network/<field>  one dataset per value (positions, ..., couples) and per topology array of
                      the Network (segments, position_projector, ...); attr dim
    /units            attrs: field -> unit (µm, pN, pN·µm, ...); datasets also carry "units"

Every file is written atomically: into a temporary file ``.<name>.<random>.tmp`` in the
target's folder, flushed to disk, then renamed over the target (``os.replace``).  An existing
file at the target is replaced whatever it holds (no check that it is a socbjax file); on any
error the temporary file is removed and a previous target is left untouched, so an interrupted
write never leaves a partial file under the target name.

Arrays keep their dtype and shape exactly (compression is lossless gzip), so a checkpoint
resumes bit-identically.  ``parameters`` and checkpoint ``meta`` go through JSON: tuples come
back as lists, numpy scalars/arrays as Python numbers/lists.
"""

from __future__ import annotations

import dataclasses
import datetime
import errno
import json
import os
import stat
import tempfile
from pathlib import Path
from typing import Any

import h5py
import jax
import jax.numpy as jnp
import numpy as np

from ._network import DIFFERENTIABLE_FIELDS, Network, Topology
from ._version import __version__
from ._result import PHASES, CompressionResult, LimitPoint
from ._solution import LEGACY_STATUS, result_from_name, result_name

TOPOLOGY_FIELDS = ("segments", "position_projector", "clamped", "moment_free", "attach", "transfer_segment",
                   "leaving_segment", "probe", "probe_direction", "strand", "socb_rows")

__all__ = ["FORMAT_VERSION", "UNITS", "atomic_path", "load", "load_checkpoint", "save", "save_checkpoint"]

FORMAT_VERSION = 2  # 2: result name (RESULTS), network couples and topology; 1 still readable
RESULT_FORMAT = "socbjax.compression"
CHECKPOINT_FORMAT = "socbjax.checkpoint"
UNITS = {
    "displacement": "µm",
    "force": "pN",
    "positions": "µm",
    "tangents": "1",
    "moments": "pN·µm",
    "segment_forces": "pN",
    "end_forces": "pN",
    "limit_points/displacement": "µm",
    "limit_points/force": "pN",
    "network/positions": "µm",
    "network/tangents": "1",
    "network/lengths": "µm",
    "network/EI": "pN·µm²",
    "network/loads": "pN",
    "network/couples": "pN·µm",
    "network/probe_direction": "1",
}
_COMPRESS_ABOVE = 4096  # elements; smaller datasets are stored contiguous, uncompressed
_PATH_FIELDS = ("displacement", "force", "converged", "stable", "phase", "positions", "tangents", "moments",
                "segment_forces", "end_nodes", "end_forces", "iterations")
_LIMIT_TYPES = {"str": h5py.string_dtype("utf-8"), "int": np.dtype(np.int64), "float": np.dtype(np.float64)}


# ----------------------------------------------------------------------------- helpers


def _to_json(value: Any, what: str) -> str:
    def default(obj):
        if isinstance(obj, (np.generic, np.ndarray)):
            return obj.tolist()
        raise TypeError(f"{type(obj).__name__} is not JSON-serialisable")

    try:
        return json.dumps(value, default=default)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{what} must be JSON-serialisable (dicts, lists, str, numbers, bool, None): {err}") from err


def _as_storable(name: str, value) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind in "OU":
        raise TypeError(f"array {name!r} has dtype {arr.dtype}; only numeric, bool or bytes arrays can be stored")
    return arr


def _dataset(group: h5py.Group, name: str, value: np.ndarray, units: str | None = None) -> h5py.Dataset:
    kwargs = {"compression": "gzip", "compression_opts": 4, "shuffle": True} if value.size > _COMPRESS_ABOVE else {}
    ds = group.create_dataset(name, data=value, **kwargs)
    if units is not None:
        ds.attrs["units"] = units
    return ds


def _read(ds: h5py.Dataset) -> np.ndarray:
    """The dataset as an ndarray (0-d datasets as 0-d arrays, not numpy scalars)."""
    return np.asarray(ds[()])


def _text(value) -> str | None:
    return value.decode() if isinstance(value, bytes) else (None if value is None else str(value))


def _new_file_mode(path: Path) -> int:
    """Permissions for the target: those of the file it replaces, else 0o666 minus the umask
    (temporary files are created 0o600)."""
    if path.exists():
        return stat.S_IMODE(path.stat().st_mode)
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def _fsync(path: Path, directory: bool = False) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        if not directory:  # folders cannot be fsynced on every platform/file system
            raise
    finally:
        os.close(fd)


def atomic_path(path, write) -> Path:
    """Call ``write(tmp)`` to create the file at a temporary path ``.<name>.<random>.tmp`` in
    the target's folder, flush it to disk and rename it onto ``path`` (``os.replace``); on any
    exception (KeyboardInterrupt included) remove the temporary file and re-raise, leaving a
    previous file at ``path`` untouched.  Returns ``path`` as a :class:`Path`."""
    path = Path(path).expanduser()
    if not path.parent.is_dir():
        raise FileNotFoundError(errno.ENOENT, "cannot write: folder does not exist (create it first)", str(path.parent))
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a folder; give a file name", str(path))
    with tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp", delete=False) as tmp:
        tmp_path = Path(tmp.name)
    try:
        write(tmp_path)
        _fsync(tmp_path)
        os.chmod(tmp_path, _new_file_mode(path))
        os.replace(tmp_path, path)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise
    _fsync(path.parent, directory=True)
    return path


def _atomic_write(path, fill, fmt: str) -> Path:
    """Atomically write an HDF5 file stamped with ``fmt`` and filled by ``fill(file)``."""

    def write(tmp_path: Path) -> None:
        with h5py.File(tmp_path, "w") as f:
            f.attrs["format"] = fmt
            f.attrs["format_version"] = FORMAT_VERSION
            f.attrs["socbjax_version"] = __version__
            f.attrs["created"] = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
            fill(f)

    return atomic_path(path, write)


def _open(path, fmt: str) -> h5py.File:
    """Open a socbjax file for reading after checking ``format`` and ``format_version``."""
    path = Path(path).expanduser()
    if not path.exists():
        raise FileNotFoundError(errno.ENOENT, "no such file", str(path))
    if not path.is_file() or not h5py.is_hdf5(path):
        raise ValueError(f"{path} is not an HDF5 file (expected a {fmt} file written by socbjax)")
    f = h5py.File(path, "r")
    try:
        found = _text(f.attrs.get("format"))
        if found != fmt:
            what = f"a {found} file" if found and found.startswith("socbjax.") else "not a socbjax file"
            raise ValueError(f"{path} is {what} (format attribute {found!r}); expected format {fmt!r}")
        version = f.attrs.get("format_version")
        if version is None or int(version) < 1:
            raise ValueError(f"{path} has no valid format_version attribute ({version!r}); the file is damaged")
        if int(version) > FORMAT_VERSION:
            raise ValueError(
                f"{path} has format version {int(version)}, written by a newer socbjax "
                f"({_text(f.attrs.get('socbjax_version'))}); socbjax {__version__} reads versions "
                f"up to {FORMAT_VERSION}: upgrade socbjax"
            )
    except BaseException:
        f.close()
        raise
    return f


def _require(group: h5py.Group, names, path, what: str) -> None:
    missing = [n for n in names if n not in group]
    if missing:
        raise ValueError(f"{path}: {what} lacks {missing} (damaged file, or written by an older socbjax)")


# ----------------------------------------------------------------------------- result


def _path_fields() -> list[str]:
    return list(_PATH_FIELDS)


def _write_limit_points(f: h5py.File, points) -> None:
    g = f.create_group("limit_points")
    for field in dataclasses.fields(LimitPoint):
        kind = field.type if isinstance(field.type, str) else field.type.__name__
        dtype = _LIMIT_TYPES[kind]
        values = [getattr(p, field.name) for p in points]
        data = np.array(values, dtype=object if kind == "str" else dtype)
        g.create_dataset(field.name, data=data, dtype=dtype)
        if unit := UNITS.get(f"limit_points/{field.name}"):
            g[field.name].attrs["units"] = unit


def _read_limit_points(g: h5py.Group, path) -> list[LimitPoint]:
    fields = dataclasses.fields(LimitPoint)
    _require(g, [fl.name for fl in fields], path, "/limit_points")
    columns = {}
    for field in fields:
        kind = field.type if isinstance(field.type, str) else field.type.__name__
        ds = g[field.name]
        values = ds.asstr()[()] if kind == "str" else ds[()]
        columns[field.name] = [{"str": str, "int": int, "float": float}[kind](v) for v in values]
    n = len(columns[fields[0].name])
    return [LimitPoint(**{name: col[i] for name, col in columns.items()}) for i in range(n)]


def _write_network(f: h5py.File, network: Network) -> None:
    g = f.create_group("network")
    g.attrs["dim"] = network.dim
    for name in DIFFERENTIABLE_FIELDS:
        _dataset(g, name, _as_storable(f"network.{name}", getattr(network, name)), UNITS.get(f"network/{name}"))
    for name in TOPOLOGY_FIELDS:
        _dataset(g, name, np.asarray(getattr(network, name)))


def _read_network(g: h5py.Group, path) -> Network:
    if "dim" not in g.attrs:
        raise ValueError(f"{path}: /network lacks the attribute 'dim' (damaged file)")
    dim = int(g.attrs["dim"])
    names = [n for n in TOPOLOGY_FIELDS if n != "leaving_segment"]
    _require(g, [n for n in DIFFERENTIABLE_FIELDS if n != "couples"] + names, path, "/network")
    topology = {name: _read(g[name]) for name in names}
    n, s = topology["clamped"].shape[0], topology["segments"].shape[0]
    leaving = np.full(n, s)
    leaving[topology["segments"][:, 0]] = np.arange(s)
    topology["leaving_segment"] = _read(g["leaving_segment"]) if "leaving_segment" in g else leaving
    values = {name: jnp.asarray(_read(g[name])) for name in DIFFERENTIABLE_FIELDS if name in g}
    values.setdefault("couples", jnp.zeros((n,) if dim == 2 else (n, 3)))  # format 1 had no couples
    return Network(**values, topology=Topology(dim=dim, **topology))


def save(result: CompressionResult, path) -> Path:
    """Write ``result`` to the HDF5 file ``path``; returns ``path`` as a :class:`Path`.

    Units as in the result (µm, pN, pN·µm), also recorded in ``/units``.  The write is atomic
    (temporary file + rename): an existing file at ``path`` is replaced, whatever it holds,
    only once the new file is complete.  Raises ``FileNotFoundError`` if the folder does not
    exist and ``TypeError`` if ``result.parameters`` is not JSON-serialisable.
    """
    if not isinstance(result, CompressionResult):
        raise TypeError(f"save expects a CompressionResult (from socbjax.compress), got {type(result).__name__}")
    try:
        parameters = _to_json(result.parameters, "result.parameters")
    except ValueError as err:  # parameters_json that is not valid JSON
        raise TypeError(f"result.parameters must be JSON-serialisable: {err}") from None
    if any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(result)):
        raise TypeError("save needs a concrete CompressionResult (call it outside jax.jit / jax.grad)")
    arrays = {name: _as_storable(name, getattr(result, name)) for name in _path_fields()}

    def fill(f: h5py.File) -> None:
        f.attrs["result"] = result_name(result.result)
        f.attrs["parameters"] = parameters
        g = f.create_group("path")
        for name, value in arrays.items():
            _dataset(g, name, value, UNITS.get(name))
        g["phase"].attrs["names"] = list(PHASES)
        _write_limit_points(f, result.limit_points)
        _write_network(f, result.network)
        units = f.create_group("units")
        for key, unit in UNITS.items():
            units.attrs[key] = unit

    return _atomic_write(path, fill, RESULT_FORMAT)


def load(path) -> CompressionResult:
    """Read a :class:`CompressionResult` written by :func:`save` (dtypes and shapes as saved).

    Raises ``FileNotFoundError`` for a missing file and ``ValueError`` for a file that is not
    a socbjax compression result, is damaged, or has a newer ``format_version``.
    """
    with _open(path, RESULT_FORMAT) as f:
        _require(f, ["path", "network"], path, "the file")
        fields = _path_fields()
        _require(f["path"], fields, path, "/path")
        if "limit_points" in f:
            points = _read_limit_points(f["limit_points"], path)
        else:  # files of socbjax 0.1.0 before the /limit_points group: a JSON attribute
            points = [LimitPoint(**p) for p in json.loads(f.attrs.get("limit_points", "[]"))]
        return CompressionResult(
            **{name: _read(f["path"][name]) for name in fields},
            limit_points=tuple(points),
            result=_read_result(f, path),
            network=_read_network(f["network"], path),
            parameters_json=json.dumps(json.loads(f.attrs["parameters"])),
        )


def _read_result(f: h5py.File, path):
    if "result" in f.attrs:
        return result_from_name(_text(f.attrs["result"]))
    status = f.attrs.get("status")  # format 1: the integer codes of socbjax 0.1's Status
    if status is None or not 0 <= int(status) < len(LEGACY_STATUS):
        raise ValueError(f"{path}: the file has no valid result/status attribute ({status!r}); the file is damaged")
    return result_from_name(LEGACY_STATUS[int(status)])


# ----------------------------------------------------------------------------- checkpoints


def save_checkpoint(path, arrays: dict[str, np.ndarray], meta: dict) -> Path:
    """Atomically write named arrays and JSON-able ``meta`` (a checkpoint of a long run).

    Arrays (numeric, bool or bytes; 0-d allowed; numpy or JAX) keep dtype, shape and every bit,
    so a run resumed from :func:`load_checkpoint` is bit-identical.  Names are arbitrary strings
    ("/" allowed); their order is kept.  Returns ``path`` as a :class:`Path`.
    """
    meta_json = _to_json(meta, "checkpoint meta")
    items = [(str(name), _as_storable(str(name), value)) for name, value in arrays.items()]

    def fill(f: h5py.File) -> None:
        f.attrs["meta"] = meta_json
        g = f.create_group("arrays")
        g.attrs["names"] = json.dumps([name for name, _ in items])
        for i, (_, value) in enumerate(items):
            _dataset(g, str(i), value)

    return _atomic_write(path, fill, CHECKPOINT_FORMAT)


def load_checkpoint(path) -> tuple[dict[str, np.ndarray], dict]:
    """``(arrays, meta)`` of a checkpoint written by :func:`save_checkpoint` (arrays in their
    saved order, 0-d arrays as 0-d ndarrays).  Errors as for :func:`load`."""
    with _open(path, CHECKPOINT_FORMAT) as f:
        _require(f, ["arrays"], path, "the checkpoint")
        g = f["arrays"]
        meta = json.loads(f.attrs["meta"])
        if "names" not in g.attrs:  # early 0.1.0 checkpoints: datasets named by key, "/" as "|"
            return {key.replace("|", "/"): _read(g[key]) for key in g}, meta
        names = json.loads(g.attrs["names"])
        _require(g, [str(i) for i in range(len(names))], path, "/arrays")
        return {name: _read(g[str(i)]) for i, name in enumerate(names)}, meta
