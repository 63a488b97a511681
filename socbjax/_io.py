"""HDF5 input/output: :func:`save` / :func:`load` of a :class:`CompressionResult`, the
checkpoints of long runs (:func:`save_checkpoint` / :func:`load_checkpoint`), atomic writes
(:func:`atomic_path`), output checks (:func:`check_output_path`) and :func:`output_lock`.

Layout of a result file (``format = "socbjax.compression"``, ``format_version = 6``; 6 added
the per-step support reactions ``/path/reactions``)::

    /                 attrs: format, format_version, socbjax_version, created (UTC, ISO 8601),
                             result (name of a socbjax.RESULTS item; format 1: integer
                             status), parameters (JSON object)
    /path/<field>     one dataset per array field of the result (displacement, force, ...)
    /limit_points/    parallel datasets kind, step, displacement, force, phase
    /network/<field>  one dataset per value (positions, ..., couples, natural_curvature: format
                      3) and per topology array of the Network (segments, ...); attr dim
    /units            attrs: field -> unit (µm, pN, pN·µm, ...); datasets also carry "units"

A checkpoint (``format = "socbjax.checkpoint"``) holds ``/arrays/0``, ``/arrays/1``, ... with
their names as a JSON list in the attribute ``names`` of ``/arrays`` and ``meta`` (a JSON
object) on the root.  Files are written in the HDF5 1.10 file format (checksummed metadata)
with fixed-length UTF-8 strings, which h5py reads as ``bytes``; files of earlier socbjax
(variable-length strings, older HDF5 formats, format_version 1 and 2) still load.

Reading treats every file as untrusted, since result files are shared.  Before any data is
read the whole file is checked (:mod:`socbjax._hdf5`): only hard links (soft and external
links are refused, never followed); no external storage or virtual datasets (they read other
files: a crafted result once pulled ``/etc/passwd`` into ``result.force``); only the
deflate/shuffle/fletcher32 filters socbjax writes (other filter ids load plugins); plain
numeric/bool/string types; no object outside the layout; declared sizes backed by the file's
bytes and at most ``socbjax._hdf5.MAX_LOAD_BYTES`` in all (a 38 KB file declaring 4.5 GB is
refused at once instead of allocating); and global heaps that cannot hang HDF5.  Then the
layout (:mod:`socbjax._layout`): dtype kind and shape of every dataset, consistent with each
other (K steps, N nodes, S segments, d = dim ∈ {2, 3}, E strand ends), index ranges (segments,
attach, end nodes, phases, limit-point steps, ...), finite network values and the root
attributes (format, integer format_version, known result name, parameters as a JSON object),
so that a loaded result can be plotted and solved.  Every problem raises one
``ValueError("<path> is not a valid socbjax result: <reason>")`` (checkpoints: "... socbjax
checkpoint ..."), the reason naming the dataset or attribute; a missing file raises
``FileNotFoundError``.

Every file is written atomically: the HDF5 file is built in memory (a disk filling up inside
the HDF5 library once crashed the process), written with plain file writes to a temporary
``.<name>.<random>.tmp`` in the target's folder, flushed to disk and renamed over the target
(``os.replace``).  A full disk, a file-size limit or an I/O error raises ``OSError`` naming the
target; the temporary file is removed and a previous target is left untouched.  Targets that
are folders, devices, FIFOs or sockets, and folders that are missing or not writable, are
refused before any work (``/dev/null`` as output was once replaced by a regular file).

Arrays keep their dtype and shape exactly (compression is lossless gzip), so a checkpoint
resumes bit-identically.  ``parameters`` and checkpoint ``meta`` go through JSON: tuples come
back as lists, numpy scalars/arrays as Python numbers/lists.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import errno
import json
import math
import os
import stat
import tempfile
from pathlib import Path
from typing import Any

import h5py
import jax
import numpy as np

from ._hdf5 import InvalidFile, file_image, text_data
from ._layout import (
    CHECKPOINT_FORMAT,
    FORMAT_VERSION,
    PATH_FIELDS,
    RESULT_FORMAT,
    limit_point_kind,
    open_file,
    read_checkpoint,
    read_result,
)
from ._network import DIFFERENTIABLE_FIELDS, Network
from ._result import PHASES, CompressionResult, LimitPoint
from ._solution import result_name
from ._version import __version__

TOPOLOGY_FIELDS = ("segments", "position_projector", "clamped", "moment_free", "attach", "transfer_segment",
                   "leaving_segment", "probe", "probe_direction", "strand", "socb_rows", "twisting")

__all__ = ["FORMAT_VERSION", "UNITS", "atomic_path", "check_output_path", "finite_json", "load", "load_checkpoint",
           "output_lock", "save", "save_checkpoint"]

UNITS = {
    "displacement": "µm",
    "force": "pN",
    "positions": "µm",
    "tangents": "1",
    "moments": "pN·µm",
    "segment_forces": "pN",
    "twists": "rad",
    "end_forces": "pN",
    "min_gap": "µm",
    "contact_force": "pN",
    "contact_points": "µm",
    "contact_forces": "pN",
    "reactions": "pN",
    "limit_points/displacement": "µm",
    "limit_points/force": "pN",
    "network/positions": "µm",
    "network/tangents": "1",
    "network/lengths": "µm",
    "network/natural_curvature": "1/µm",
    "network/GJ": "pN·µm²",
    "network/directors": "1",
    "network/EI": "pN·µm²",
    "network/loads": "pN",
    "network/couples": "pN·µm",
    "network/probe_direction": "1",
}
_COMPRESS_ABOVE = 4096  # elements; smaller datasets are stored contiguous, uncompressed
_LIMIT_TYPES = {"int": np.dtype(np.int64), "float": np.dtype(np.float64)}


# ----------------------------------------------------------------------------- strict JSON
def finite_json(value):
    """``value`` with every non-finite float replaced by None and numpy scalars made Python
    ones: strict JSON (no NaN or Infinity, e.g. the standard errors of a singular fit)."""
    if isinstance(value, dict):
        return {k: finite_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_json(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


# ----------------------------------------------------------------------------- output paths


def _error(cls, code: int, message: str) -> OSError:
    """``cls(message)`` with ``errno`` set (its text then starts with ``message``)."""
    err = cls(message)
    err.errno = code
    return err


def _check_target(path: Path, what: str) -> None:
    parent = path.parent
    if not parent.is_dir():
        if parent.exists():
            raise ValueError(f"{what} {path}: {parent} is not a folder; choose a path inside a folder")
        raise _error(FileNotFoundError, errno.ENOENT,
                     f"{what} {path}: the folder {parent} does not exist; create it first (mkdir -p) or choose another")
    try:
        mode = os.stat(path).st_mode  # follows symlinks: a link to /dev/null counts as the device
    except FileNotFoundError:
        return
    except OSError as err:
        raise ValueError(f"{what} {path} cannot be examined ({err.strerror}); choose another path") from None
    if stat.S_ISDIR(mode):
        raise ValueError(f"{what} {path} is a folder; give a file name (inside it, or elsewhere)")
    if not stat.S_ISREG(mode):
        kind = ("character device" if stat.S_ISCHR(mode) else "block device" if stat.S_ISBLK(mode)
                else "FIFO" if stat.S_ISFIFO(mode) else "socket" if stat.S_ISSOCK(mode) else "special file")
        raise ValueError(f"{what} {path} is a {kind}, not a regular file; socbjax writes only regular files (which "
                         "it replaces): choose another path")


def _temporary(path: Path) -> Path:
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    return Path(name)


def check_output_path(path, what: str = "path") -> Path:
    """Check that ``path`` can be written as an output, without touching it; returns it as a
    :class:`Path`.  Run before a long computation (the command line checks ``--out``).

    Raises, with a message starting with ``what`` and naming the path and the fix:
    ``FileNotFoundError`` when the folder does not exist, ``ValueError`` when the folder is a
    file or the target a folder, device, FIFO or socket, ``PermissionError`` (or ``OSError``)
    when no file can be created in the folder — checked by creating and removing a temporary
    file there, since ``os.access`` answers yes to root even on read-only mounts.
    """
    path = Path(path).expanduser()
    _check_target(path, what)
    try:
        _temporary(path).unlink()
    except OSError as err:
        cls = PermissionError if err.errno in (errno.EACCES, errno.EPERM, errno.EROFS) else OSError
        raise _error(cls, err.errno or errno.EIO, f"{what} {path}: cannot create a file in the folder {path.parent} "
                     f"({err.strerror or err}); choose a writable folder") from None
    return path


def _write_error(path: Path, err: OSError) -> OSError:
    hint = {errno.ENOSPC: "free disk space", errno.EDQUOT: "free space within your disk quota",
            errno.EFBIG: "raise the file-size limit (ulimit -f) or free space",
            errno.EROFS: "write to a writable file system", errno.EACCES: "choose a folder you can write to"}
    fix = hint.get(err.errno, "check the disk and the folder")
    # OSError(errno, text) picks the subclass of the errno (PermissionError for EACCES, ...).
    return OSError(err.errno or errno.EIO, f"cannot write {path}: {err.strerror or err}; {fix} and try again "
                   "(any previous file there is unchanged)")


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
        if not directory:
            raise
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
    previous file at ``path`` untouched.  Returns ``path`` as a :class:`Path`.

    The target is checked first (see :func:`check_output_path`); an ``OSError`` while writing
    (full disk, file-size limit, I/O error, read-only file system) is raised as an ``OSError``
    of the same errno whose message names ``path``.
    """
    return _replace_atomically(check_output_path(path, "output path"), write)


def _replace_atomically(path: Path, write) -> Path:
    """:func:`atomic_path` on a checked ``path``."""
    tmp = None
    try:
        try:
            tmp = _temporary(path)
            write(tmp)
            _fsync(tmp)
            os.chmod(tmp, _new_file_mode(path))
            os.replace(tmp, path)
        except OSError as err:
            raise _write_error(path, err) from err
    except BaseException:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        raise
    _fsync(path.parent, directory=True)
    return path


def _write_bytes(tmp: Path, data: bytes) -> None:
    with open(tmp, "wb") as fh:
        fh.write(data)


def _atomic_write(path: Path, fill, fmt: str) -> Path:
    """Atomically write to the checked ``path`` an HDF5 file stamped with ``fmt`` and filled by
    ``fill(file)``."""

    def stamped(f: h5py.File) -> None:
        _set_text(f, "format", fmt)
        f.attrs["format_version"] = FORMAT_VERSION
        _set_text(f, "socbjax_version", __version__)
        _set_text(f, "created", datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"))
        fill(f)

    data = file_image(stamped)  # in memory: a failing disk cannot reach the HDF5 library mid-write
    return _replace_atomically(path, lambda tmp: _write_bytes(tmp, data))


def _lock_holder(fd: int) -> str:
    with contextlib.suppress(OSError, ValueError):
        text = os.pread(fd, 32, 0).decode().strip()
        if text.isdigit():
            return text
    return "unknown"


def _acquire(lock: Path, path: Path) -> int:
    import fcntl  # POSIX only; imported here so that the rest of socbjax imports everywhere

    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as err:
            raise OSError(err.errno, f"cannot create the lock file {lock} for {path}: {err.strerror}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            locked = True
        except BlockingIOError:
            locked = False
        try:  # the holder may have removed the file (releasing) after we opened it: retry on the new one
            same = os.path.samestat(os.stat(lock), os.fstat(fd))
        except FileNotFoundError:
            same = False
        if same and locked:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            return fd
        holder = _lock_holder(fd)
        os.close(fd)
        if same:
            raise OSError(errno.EBUSY, f"another socbjax run is writing this output (pid {holder}); wait for it to "
                          "finish or choose another output", str(path))


@contextlib.contextmanager
def output_lock(path):
    """Hold an advisory lock (``fcntl.flock``) on ``path`` for the ``with`` block, so that two
    socbjax runs never write the same output; yields ``path`` as a :class:`Path`.

    The lock is the file ``.<name>.lock`` next to ``path``, holding the pid of its holder, and
    is removed on exit.  If another process holds it, raises ``OSError(errno.EBUSY, ...)``
    naming that pid at once (no waiting).
    """
    path = Path(path).expanduser()
    lock = path.with_name(f".{path.name}.lock")
    fd = _acquire(lock, path)
    try:
        yield path
    finally:
        # Remove the file while still holding the lock: a process that opened it meanwhile sees
        # (after its own flock) that the path no longer names its file and starts over.
        with contextlib.suppress(FileNotFoundError):
            os.unlink(lock)
        os.close(fd)


# ----------------------------------------------------------------------------- writing


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


def _set_text(obj, name: str, value) -> None:
    """A str (or list of str) attribute, stored fixed-length: see :func:`socbjax._hdf5.text_data`."""
    data, dtype = text_data(value)
    obj.attrs.create(name, data, dtype=dtype)


def _dataset(group: h5py.Group, name: str, value: np.ndarray, units: str | None = None) -> h5py.Dataset:
    kwargs = {"compression": "gzip", "compression_opts": 4, "shuffle": True} if value.size > _COMPRESS_ABOVE else {}
    ds = group.create_dataset(name, data=value, **kwargs)
    if units is not None:
        _set_text(ds, "units", units)
    return ds


def _write_limit_points(f: h5py.File, points) -> None:
    g = f.create_group("limit_points")
    for field in dataclasses.fields(LimitPoint):
        kind = limit_point_kind(field)
        values = [getattr(p, field.name) for p in points]
        data, dtype = text_data(values) if kind == "str" else (np.array(values, _LIMIT_TYPES[kind]), None)
        g.create_dataset(field.name, data=data, dtype=dtype)
        if unit := UNITS.get(f"limit_points/{field.name}"):
            _set_text(g[field.name], "units", unit)


def _write_network(f: h5py.File, network: Network) -> None:
    g = f.create_group("network")
    g.attrs["dim"] = network.dim
    for name in DIFFERENTIABLE_FIELDS:
        _dataset(g, name, _as_storable(f"network.{name}", getattr(network, name)), UNITS.get(f"network/{name}"))
    for name in TOPOLOGY_FIELDS:
        _dataset(g, name, np.asarray(getattr(network.topology, name)))


def save(result: CompressionResult, path) -> Path:
    """Write ``result`` to the HDF5 file ``path``; returns ``path`` as a :class:`Path`.

    Units as in the result (µm, pN, pN·µm), also recorded in ``/units``.  The write is atomic
    (built in memory, temporary file + rename): an existing regular file at ``path`` is
    replaced only once the new file is complete.  Raises, before any work, the errors of
    :func:`check_output_path` (``FileNotFoundError`` for a missing folder, ``ValueError`` for
    a folder/device/FIFO target, ``PermissionError`` for a read-only folder), ``TypeError`` if
    ``result.parameters`` is not JSON-serialisable, and ``OSError`` naming ``path`` when the
    disk fails (full, file-size limit, I/O error).
    """
    if not isinstance(result, CompressionResult):
        raise TypeError(f"save expects a CompressionResult (from socbjax.compress), got {type(result).__name__}")
    path = check_output_path(path, "save path")
    try:
        parameters = _to_json(result.parameters, "result.parameters")
    except ValueError as err:  # parameters_json that is not valid JSON
        raise TypeError(f"result.parameters must be JSON-serialisable: {err}") from None
    if any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(result)):
        raise TypeError("save needs a concrete CompressionResult (call it outside jax.jit / jax.grad)")
    arrays = {name: _as_storable(name, getattr(result, name)) for name in PATH_FIELDS}

    def fill(f: h5py.File) -> None:
        _set_text(f, "result", result_name(result.result))
        _set_text(f, "parameters", parameters)
        g = f.create_group("path")
        for name, value in arrays.items():
            _dataset(g, name, value, UNITS.get(name))
        _set_text(g["phase"], "names", list(PHASES))
        _write_limit_points(f, result.limit_points)
        _write_network(f, result.network)
        units = f.create_group("units")
        for key, unit in UNITS.items():
            _set_text(units, key, unit)

    return _atomic_write(path, fill, RESULT_FORMAT)


def save_checkpoint(path, arrays: dict[str, np.ndarray], meta: dict) -> Path:
    """Atomically write named arrays and JSON-able ``meta`` (a checkpoint of a long run).

    Arrays (numeric, bool or bytes; 0-d allowed; numpy or JAX) keep dtype, shape and every bit,
    so a run resumed from :func:`load_checkpoint` is bit-identical.  Names are arbitrary strings
    ("/" allowed); their order is kept.  Returns ``path`` as a :class:`Path`.  Errors as for
    :func:`save` (a failed write leaves the previous checkpoint intact).
    """
    path = check_output_path(path, "save_checkpoint path")
    meta_json = _to_json(meta, "checkpoint meta")
    items = [(str(name), _as_storable(str(name), value)) for name, value in arrays.items()]

    def fill(f: h5py.File) -> None:
        _set_text(f, "meta", meta_json)
        g = f.create_group("arrays")
        _set_text(g, "names", json.dumps([name for name, _ in items]))
        for i, (_, value) in enumerate(items):
            _dataset(g, str(i), value)

    return _atomic_write(path, fill, CHECKPOINT_FORMAT)


# ----------------------------------------------------------------------------- reading


def load(path) -> CompressionResult:
    """Read a :class:`CompressionResult` written by :func:`save` (dtypes and shapes as saved).

    The file is checked completely before any data is read (see the module docstring): a
    loaded result can be plotted and solved.  Raises ``FileNotFoundError`` for a missing file
    and ``ValueError("<path> is not a valid socbjax result: <reason>")`` for anything else —
    not HDF5, damaged, crafted, another format or a newer ``format_version``.
    """
    path = Path(path).expanduser()
    try:
        reader, version = open_file(path, RESULT_FORMAT, ("path", "network", "limit_points", "units"))
        with reader:
            return read_result(reader, version)
    except InvalidFile as err:
        raise ValueError(f"{path} is not a valid socbjax result: {err}") from None


def load_checkpoint(path) -> tuple[dict[str, np.ndarray], dict]:
    """``(arrays, meta)`` of a checkpoint written by :func:`save_checkpoint` (arrays in their
    saved order, 0-d arrays as 0-d ndarrays).  Errors as for :func:`load` ("... is not a valid
    socbjax checkpoint: ...")."""
    path = Path(path).expanduser()
    try:
        reader, _ = open_file(path, CHECKPOINT_FORMAT, ("arrays",))
        with reader:
            return read_checkpoint(reader)
    except InvalidFile as err:
        raise ValueError(f"{path} is not a valid socbjax checkpoint: {err}") from None
