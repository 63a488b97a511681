"""The layout of socbjax's HDF5 files, checked while reading (for :mod:`socbjax._io`).

After :class:`socbjax._hdf5.Reader` has checked the file's objects (links, storage, filters,
types, sizes), :func:`open_file` checks the ``format`` and ``format_version`` attributes and
:func:`read_result` / :func:`read_checkpoint` the layout: every dataset present with the dtype
kind and a shape consistent with the others (K steps, N nodes, S segments, d = dim ∈ {2, 3},
E strand ends, L limit points, R node equations, w = N in a twisting network, else 0), index
ranges (segments, attach, transfer and leaving segments, equation rows, end nodes, phases,
limit-point steps), finite network values and the root attributes (known result name,
parameters as a JSON object), so that a loaded result can be plotted and solved.  Problems
raise :class:`socbjax._hdf5.InvalidFile`.
"""

from __future__ import annotations

import dataclasses
import errno
import json
import re
from pathlib import Path

import h5py
import jax.numpy as jnp
import numpy as np

from ._hdf5 import InvalidFile, Reader, parse_json
from ._network import DIFFERENTIABLE_FIELDS, Network, Topology
from ._network_checks import default_directors
from ._result import PHASES, CompressionResult, LimitPoint
from ._solution import LEGACY_STATUS, result_from_name
from ._version import __version__

__all__ = ["CHECKPOINT_FORMAT", "FORMAT_VERSION", "MAX_MAGNITUDE", "PATH_FIELDS", "RESULT_FORMAT", "limit_point_kind",
           "open_file", "read_checkpoint", "read_result"]

# 6: per-step support reactions; 5: contact outputs (count, min gap, force, slot points and forces); 4: the path's frame
# angles (twists); 3: natural curvature, GJ and twisting; 2: result name (RESULTS), couples,
# topology; 1 to 5 still readable
FORMAT_VERSION = 6
RESULT_FORMAT = "socbjax.compression"
CHECKPOINT_FORMAT = "socbjax.checkpoint"
# Limit-point kinds are open-ended (force_maximum, fold, surface_crossing, ...): any identifier
# is accepted; other text could break plots (matplotlib reads "$...$" in labels as TeX).
_KIND = re.compile(r"[a-z][a-z0-9_]{0,63}")
MAX_MAGNITUDE = 1e100  # of any stored value (µm, pN, ...): beyond it plots overflow (NaN is allowed)
# Dataset layout: name -> (dtype kinds, shape in the sizes K, N, S, d, E, L, R; "m": 2D none, 3D 3).
_PATH_LAYOUT = {
    "displacement": ("f", "K"), "force": ("f", "K"), "converged": ("b", "K"), "stable": ("b", "K"),
    "phase": ("iu", "K"), "positions": ("f", "KNd"), "tangents": ("f", "KNd"), "moments": ("f", "KNm"),
    "segment_forces": ("f", "KSd"), "twists": ("f", "Kw"), "end_nodes": ("iu", "E"), "end_forces": ("f", "KE"),
    "iterations": ("iu", "K"), "contact_count": ("iu", "K"), "min_gap": ("f", "K"), "contact_force": ("f", "K"),
    "contact_points": ("f", "Kcd"), "contact_forces": ("f", "Kcd"), "reactions": ("f", "KNd"),
}
_CONTACT_FIELDS = ("contact_count", "min_gap", "contact_force", "contact_points", "contact_forces")  # format 5
PATH_FIELDS = tuple(_PATH_LAYOUT)
_NETWORK_LAYOUT = {
    "positions": ("f", "Nd"), "segments": ("iu", "S2"), "tangents": ("f", "Nd"), "lengths": ("f", "S"),
    "EI": ("f", "S"), "loads": ("f", "Nd"), "couples": ("f", "Nm"), "natural_curvature": ("f", "Sm"), "GJ": ("f", "S"), "directors": ("f", "Nd"),
    "position_projector": ("f", "Ndd"),
    "clamped": ("b", "N"), "moment_free": ("b", "N"), "attach": ("iu", "N"), "transfer_segment": ("iu", "N"),
    "leaving_segment": ("iu", "N"), "probe": ("b", "N"), "probe_direction": ("f", "d"), "strand": ("iu", "S"),
    "socb_rows": ("iu", "R"), "twisting": ("b", "N"),
}
_OPTIONAL = {1: ("couples", "leaving_segment", "natural_curvature", "GJ", "twisting", "directors"),
             2: ("natural_curvature", "GJ", "twisting", "directors")}  # absent before format 3
_KIND_NAMES = {"f": "float32/float64", "b": "bool", "iu": "integer", "s": "string"}
_LIMIT_DTYPES = {"str": "s", "int": "iu", "float": "f"}  # dtype kinds of the LimitPoint fields


def open_file(path: Path, fmt: str, groups) -> tuple[Reader, int]:
    """A :class:`Reader` of ``path`` after checking ``format`` and ``format_version``, and its
    format version; raises ``FileNotFoundError`` or :class:`InvalidFile`."""
    if not path.exists():
        raise FileNotFoundError(errno.ENOENT, "no such file", str(path))
    if not path.is_file():  # a FIFO or device would block or stream forever
        raise InvalidFile("it is not a regular file")
    with open(path, "rb"):  # PermissionError for an unreadable file, as for any file
        pass
    if not h5py.is_hdf5(path):
        raise InvalidFile(f"it is not an HDF5 file (expected a {fmt} file written by socbjax)")
    reader = Reader(path, groups)
    try:
        found = reader.attr(reader.file, "format", "str", "the attribute format")
        if found != fmt:
            what = f"a {found} file" if found and found.startswith("socbjax.") else "not a socbjax file"
            hint = {RESULT_FORMAT: "; read it with socbjax.load", CHECKPOINT_FORMAT: "; read it with socbjax.load_checkpoint"}
            raise InvalidFile(f"it is {what} (format attribute {found!r}); expected format {fmt!r}{hint.get(found, '')}")
        version = reader.attr(reader.file, "format_version", "int", "the attribute format_version")
        if version is None or version < 1:
            raise InvalidFile(f"the attribute format_version is {version!r}; expected an integer 1..{FORMAT_VERSION}")
        if version > FORMAT_VERSION:
            raise InvalidFile(f"it has format version {version}, written by a newer socbjax; socbjax {__version__} "
                              f"reads versions up to {FORMAT_VERSION}: upgrade socbjax")
        reader.check_tree()
    except BaseException:
        reader.file.close()
        raise
    return reader, version


class _Sizes:
    """The sizes K, N, S, ... of a file's arrays: the first dataset with a size fixes it, the
    others must agree."""

    def __init__(self, dim: int):
        self.known = {"d": (dim, "the attribute dim of /network"), "2": (2, ""), "m": (3, "")}
        self.dim = dim

    def template(self, letters: str) -> tuple[str, ...]:
        return tuple(c for c in letters if not (c == "m" and self.dim == 2))  # 2D moments, couples: scalars

    def check(self, where: str, ds: h5py.Dataset, kinds: str, letters: str) -> None:
        dtype, shape, template = ds.dtype, ds.shape, self.template(letters)
        ok = (h5py.check_string_dtype(dtype) is not None if kinds == "s"
              else dtype.kind in kinds and (kinds != "f" or dtype.itemsize in (4, 8)))
        if not ok:
            raise InvalidFile(f"{where} has dtype {dtype}; expected {_KIND_NAMES[kinds]}")
        if len(shape) != len(template):
            raise InvalidFile(f"{where} has shape {shape}; expected [{', '.join(template)}]")
        for size, letter in zip(shape, template):
            value, origin = self.known.setdefault(letter, (size, where))
            if size != value:
                raise InvalidFile(f"{where} has shape {shape}; expected [{', '.join(template)}] with "
                                  f"{letter} = {value} (from {origin})")


def _read_group(reader: Reader, sizes: _Sizes, group: str, layout: dict, optional=()) -> dict[str, np.ndarray]:
    datasets = reader.datasets.get(group, {})
    unknown = sorted(set(datasets) - set(layout))
    missing = [name for name in layout if name not in datasets and name not in optional]
    if unknown or missing:
        raise InvalidFile(f"/{group} " + (f"lacks {missing}" if missing else f"has unexpected datasets {unknown}") +
                          " (damaged file, or written by another program)")
    for name, (kinds, letters) in layout.items():
        if name in datasets:
            sizes.check(f"/{group}/{name}", datasets[name], kinds, letters)
    arrays = {name: reader.read(ds, f"/{group}/{name}", text=layout[name][0] == "s") for name, ds in datasets.items()}
    for name, values in arrays.items():
        huge = values[np.abs(values) > MAX_MAGNITUDE] if layout[name][0] == "f" else ()
        if len(huge):
            raise InvalidFile(f"/{group}/{name} holds {huge[0]}, beyond ±{MAX_MAGNITUDE:g} (no physical value in µm, "
                              "pN or pN·µm; damaged file)")
    return arrays


def _check_range(where: str, values: np.ndarray, stop: int, meaning: str) -> None:
    bad = values[(values < 0) | (values >= stop)]
    if bad.size:
        raise InvalidFile(f"{where} holds {bad.flat[0]}, outside 0..{stop - 1} ({meaning})")


def _read_network(reader: Reader, version: int) -> tuple[Network, _Sizes]:
    if "network" not in reader.datasets:
        raise InvalidFile("the group /network is missing")
    dim = reader.attr(reader.file["network"], "dim", "int", "the attribute dim of /network")
    if dim not in (2, 3):
        raise InvalidFile(f"the attribute dim of /network is {dim!r}; networks are 2- or 3-dimensional (2 or 3)")
    sizes = _Sizes(dim)
    a = _read_group(reader, sizes, "network", _NETWORK_LAYOUT, _OPTIONAL.get(version, ()))
    n, s = sizes.known["N"][0], sizes.known["S"][0]
    if n < 2 or s < 1:
        raise InvalidFile(f"/network has {n} nodes and {s} segments; a network has at least 2 nodes and 1 segment")
    for name in DIFFERENTIABLE_FIELDS + ("position_projector", "probe_direction"):
        if name in a and not np.all(np.isfinite(a[name])):
            raise InvalidFile(f"/network/{name} holds NaN or infinite values")
    _check_range("/network/segments", a["segments"], n, "node indices")
    if np.any(a["segments"][:, 0] == a["segments"][:, 1]):
        raise InvalidFile("/network/segments joins a node to itself")
    _check_range("/network/attach", a["attach"], n, "node indices")
    if "leaving_segment" not in a:  # format 1: derived from the segments
        a["leaving_segment"] = np.full(n, s)
        a["leaving_segment"][a["segments"][:, 0]] = np.arange(s)
    for name in ("transfer_segment", "leaving_segment"):
        _check_range(f"/network/{name}", a[name], s + 1, f"segment indices, {s} for none")
    a.setdefault("twisting", np.zeros(n, bool))
    if a["twisting"].any() != a["twisting"].all() or (dim == 2 and a["twisting"].any()):
        raise InvalidFile("/network/twisting must be all False, or all True in a 3D network")
    width = 4 if dim == 2 else 11 + int(a["twisting"].any())
    _check_range("/network/socb_rows", a["socb_rows"], n * width, "node equation rows")
    a.setdefault("couples", np.zeros((n,) if dim == 2 else (n, 3)))
    a.setdefault("natural_curvature", np.zeros((s,) if dim == 2 else (s, 3)))
    a.setdefault("GJ", np.zeros(s))
    if "directors" not in a:  # before format 3: the default reference directors
        tangents = a["tangents"] / np.linalg.norm(a["tangents"], axis=-1, keepdims=True)
        a["directors"] = np.zeros((n, 2)) if dim == 2 else default_directors(tangents)
    values = {name: jnp.asarray(a.pop(name)) for name in DIFFERENTIABLE_FIELDS}
    return Network(**values, topology=Topology(dim=dim, **a)), sizes


def _read_path(reader: Reader, sizes: _Sizes, version: int) -> dict[str, np.ndarray]:
    if "path" not in reader.datasets:
        raise InvalidFile("the group /path is missing")
    optional = ((("twists",) if version < 4 else ()) + (_CONTACT_FIELDS if version < 5 else ())
                + (("reactions",) if version < 6 else ()))
    arrays = _read_group(reader, sizes, "path", _PATH_LAYOUT, optional)
    K = arrays["displacement"].shape[0]
    if "twists" not in arrays:  # before format 4: not recorded (CompressionResult.solution says so)
        arrays["twists"] = np.zeros((K, 0))
    # before format 5 the contact outputs are absent: CompressionResult fills "no contact";
    # before format 6 the reactions: NaN (not recorded)
    if arrays["displacement"].shape[0] == 0:
        raise InvalidFile("/path has no steps (K = 0); a result holds at least its start")
    _check_range("/path/phase", arrays["phase"], len(PHASES), f"phases {dict(enumerate(PHASES))}")
    if not np.any(arrays["phase"] <= 1):
        raise InvalidFile("/path/phase has no settle or loading step (0 or 1)")
    _check_range("/path/end_nodes", arrays["end_nodes"], sizes.known["N"][0], "node indices")
    if np.any(arrays["iterations"] < 0):
        raise InvalidFile("/path/iterations holds negative counts")
    return arrays


def limit_point_kind(field) -> str:
    """"str", "int" or "float": the type of a :class:`LimitPoint` field."""
    return field.type if isinstance(field.type, str) else field.type.__name__


def _limit_point(values: dict, where: str, steps: int) -> LimitPoint:
    fields = {field.name: limit_point_kind(field) for field in dataclasses.fields(LimitPoint)}
    types = {"str": (str,), "int": (int, np.integer), "float": (float, int, np.floating, np.integer)}
    if set(values) != set(fields) or any(isinstance(v, (bool, np.bool_)) or not isinstance(v, types[fields[k]])
                                         for k, v in values.items()):
        raise InvalidFile(f"{where} must have the fields {fields}, got {values!r:.200}")
    point = LimitPoint(**{k: {"str": str, "int": int, "float": float}[fields[k]](v) for k, v in values.items()})
    problems = [f"kind {point.kind!r} is not a lower-case identifier"] if not _KIND.fullmatch(point.kind) else []
    problems += [f"phase {point.phase!r} is not one of {PHASES}"] if point.phase not in PHASES else []
    problems += [f"step {point.step} is outside the recorded steps 0..{steps - 1}"] if not 0 <= point.step < steps else []
    if problems:
        raise InvalidFile(f"{where}: " + "; ".join(problems))
    return point


def _read_limit_points(reader: Reader, sizes: _Sizes) -> tuple[LimitPoint, ...]:
    steps = sizes.known["K"][0]
    if "limit_points" not in reader.datasets:  # socbjax 0.1.0 before the group: a JSON attribute
        text = reader.attr(reader.file, "limit_points", "str", "the attribute limit_points") or "[]"
        rows = parse_json(text, "the attribute limit_points", list)
        return tuple(_limit_point(row if isinstance(row, dict) else {}, f"limit point {i}", steps)
                     for i, row in enumerate(rows))
    layout = {field.name: (_LIMIT_DTYPES[limit_point_kind(field)], "L") for field in dataclasses.fields(LimitPoint)}
    columns = _read_group(reader, sizes, "limit_points", layout)
    rows = [{name: col[i] for name, col in columns.items()} for i in range(sizes.known["L"][0])]
    return tuple(_limit_point(row, f"/limit_points row {i}", steps) for i, row in enumerate(rows))


def _read_result_item(reader: Reader, version: int):
    name = reader.attr(reader.file, "result", "str", "the attribute result")
    if name is None and version == 1:  # format 1: the integer codes of socbjax 0.1's Status
        status = reader.attr(reader.file, "status", "int", "the attribute status")
        if status is None or not 0 <= status < len(LEGACY_STATUS):
            raise InvalidFile(f"the attribute status is {status!r}; expected 0..{len(LEGACY_STATUS) - 1}")
        name = LEGACY_STATUS[status]
    if name is None:
        raise InvalidFile("the attribute result is missing")
    try:
        return result_from_name(name)
    except ValueError as err:  # the message lists the known names
        raise InvalidFile(f"the attribute result: {err}") from None


def read_result(reader: Reader, version: int) -> CompressionResult:
    """The :class:`CompressionResult` of a checked result file (see the module docstring)."""
    network, sizes = _read_network(reader, version)
    sizes.known["w"] = (network.n_nodes if network.twisting else 0, "/network/twisting")
    arrays = _read_path(reader, sizes, version)
    points = _read_limit_points(reader, sizes)
    item = _read_result_item(reader, version)
    text = reader.attr(reader.file, "parameters", "str", "the attribute parameters")
    if text is None:
        raise InvalidFile("the attribute parameters is missing")
    parameters = parse_json(text, "the attribute parameters", dict)
    return CompressionResult(**arrays, limit_points=points, result=item, network=network,
                             parameters_json=json.dumps(parameters))


def read_checkpoint(reader: Reader) -> tuple[dict[str, np.ndarray], dict]:
    """``(arrays, meta)`` of a checked checkpoint file."""
    text = reader.attr(reader.file, "meta", "str", "the attribute meta")
    if text is None:
        raise InvalidFile("the attribute meta is missing")
    meta = parse_json(text, "the attribute meta", dict)
    if "arrays" not in reader.datasets:
        raise InvalidFile("the group /arrays is missing")
    datasets = reader.datasets["arrays"]
    for name, ds in datasets.items():
        if ds.dtype.kind == "O":
            raise InvalidFile(f"/arrays/{name} holds variable-length strings; checkpoints hold numeric, bool or bytes")
    text = reader.attr(reader.file["arrays"], "names", "str", "the attribute names of /arrays")
    if text is None:  # early 0.1.0 checkpoints: datasets named by key, "/" as "|"
        return {key.replace("|", "/"): reader.read(ds, f"/arrays/{key}") for key, ds in datasets.items()}, meta
    names = parse_json(text, "the attribute names of /arrays", list)
    if not all(isinstance(name, str) for name in names) or len(set(names)) != len(names):
        raise InvalidFile("the attribute names of /arrays must list distinct strings")
    if set(datasets) != {str(i) for i in range(len(names))}:
        raise InvalidFile(f"/arrays holds datasets {sorted(datasets)[:8]}; its names attribute lists {len(names)} "
                          f"arrays (datasets 0..{len(names) - 1})")
    return {name: reader.read(datasets[str(i)], f"/arrays/{i} ({name!r})") for i, name in enumerate(names)}, meta
