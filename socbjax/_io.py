"""HDF5 input/output: :func:`save` / :func:`load` of a :class:`CompressionResult`, and the
checkpoints of long runs.

Every file is written atomically: to a temporary file in the target's folder, then renamed
over the target (``os.replace``), so an interrupted write never leaves a partial or corrupt
file under the target name.  Files carry ``format``, ``format_version`` and the socbjax
version; units are stored as attributes (µm, pN, pN·µm).
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import os
import tempfile
from pathlib import Path

import h5py
import jax.numpy as jnp
import numpy as np

from ._network import Network
from ._result import CompressionResult, LimitPoint

__all__ = ["save", "load", "save_checkpoint", "load_checkpoint", "FORMAT_VERSION"]

FORMAT_VERSION = 1
_RESULT_FORMAT = "socbjax.compression"
_CHECKPOINT_FORMAT = "socbjax.checkpoint"
UNITS = {
    "displacement": "µm",
    "force": "pN",
    "positions": "µm",
    "tangents": "1",
    "moments": "pN·µm",
    "segment_forces": "pN",
    "end_forces": "pN",
    "network/positions": "µm",
    "network/lengths": "µm",
    "network/EI": "pN·µm²",
    "network/loads": "pN",
}


def _atomic_write(path, fill, fmt: str) -> Path:
    from . import __version__

    path = Path(path)
    if not path.parent.exists():
        raise FileNotFoundError(f"folder {path.parent} does not exist; create it first")
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = fmt
            f.attrs["format_version"] = FORMAT_VERSION
            f.attrs["socbjax_version"] = __version__
            f.attrs["created"] = datetime.datetime.now(datetime.timezone.utc).isoformat()
            fill(f)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
    return path


def _open(path, fmt: str) -> h5py.File:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such file: {path}")
    f = h5py.File(path, "r")
    if f.attrs.get("format") != fmt:
        f.close()
        raise ValueError(f"{path} is not a {fmt} file (format attribute {f.attrs.get('format')!r})")
    if int(f.attrs.get("format_version", 0)) > FORMAT_VERSION:
        f.close()
        raise ValueError(f"{path} was written by a newer socbjax (format version > {FORMAT_VERSION}); upgrade socbjax")
    return f


def _dataset(group, name, value):
    value = np.asarray(value)
    kwargs = {"compression": "gzip", "compression_opts": 4} if value.size > 4096 else {}
    group.create_dataset(name, data=value, **kwargs)


def save(result: CompressionResult, path) -> Path:
    """Write ``result`` to HDF5 at ``path`` (atomically; an existing file is replaced)."""
    if not isinstance(result, CompressionResult):
        raise TypeError(f"save expects a CompressionResult (from socbjax.compress), got {type(result).__name__}")

    def fill(f):
        g = f.create_group("path")
        for field in dataclasses.fields(result):
            if field.name in ("limit_points", "network", "parameters", "status"):
                continue
            _dataset(g, field.name, getattr(result, field.name))
        f.attrs["status"] = int(result.status)
        f.attrs["parameters"] = json.dumps(result.parameters)
        f.attrs["limit_points"] = json.dumps([dataclasses.asdict(p) for p in result.limit_points])
        net = f.create_group("network")
        for field in dataclasses.fields(result.network):
            if field.name == "dim":
                net.attrs["dim"] = result.network.dim
            else:
                _dataset(net, field.name, getattr(result.network, field.name))
        units = f.create_group("units")
        for key, unit in UNITS.items():
            units.attrs[key] = unit

    return _atomic_write(path, fill, _RESULT_FORMAT)


def load(path) -> CompressionResult:
    """Read a :class:`CompressionResult` written by :func:`save`."""
    with _open(path, _RESULT_FORMAT) as f:
        arrays = {name: f["path"][name][()] for name in f["path"]}
        net = {name: jnp.asarray(f["network"][name][()]) for name in f["network"]}
        network = Network(**net, dim=int(f["network"].attrs["dim"]))
        points = [LimitPoint(**p) for p in json.loads(f.attrs["limit_points"])]
        return CompressionResult(
            **arrays,
            limit_points=points,
            status=int(f.attrs["status"]),
            network=network,
            parameters=json.loads(f.attrs["parameters"]),
        )


def save_checkpoint(path, arrays: dict, meta: dict) -> Path:
    """Atomically write named arrays (dtype and shape kept exactly) and JSON-able ``meta``."""

    def fill(f):
        g = f.create_group("arrays")
        for name, value in arrays.items():
            g.create_dataset(name.replace("/", "|"), data=np.asarray(value))
        f.attrs["meta"] = json.dumps(meta)

    return _atomic_write(path, fill, _CHECKPOINT_FORMAT)


def load_checkpoint(path) -> tuple[dict, dict]:
    """(arrays, meta) of a checkpoint written by :func:`save_checkpoint`."""
    with _open(path, _CHECKPOINT_FORMAT) as f:
        arrays = {name.replace("|", "/"): f["arrays"][name][()] for name in f["arrays"]}
        return arrays, json.loads(f.attrs["meta"])
