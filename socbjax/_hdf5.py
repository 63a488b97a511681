"""Reading untrusted HDF5 files safely, and HDF5 files built in memory (for :mod:`socbjax._io`).

HDF5 can make a file read bytes from elsewhere: external links (objects in other files),
external storage (a dataset's bytes in any other file, e.g. ``/etc/passwd``), virtual datasets
(mappings onto other files) and filters by id (which load plugin libraries).  A file can also
declare a dataset far larger than the bytes it holds (a 38 KB file declaring 4.5 GB of
zeros), so reading it allocates memory the file never backed.  :class:`Reader` therefore
checks every object of the file before any data is read: only hard links; only groups at
the top and datasets inside them, under names the caller allows; no external storage, no
virtual layout, only the filters socbjax writes (deflate, shuffle, fletcher32; read from the
dataset creation property list, so no filter is ever invoked); plain numeric, bool or string
types; declared bytes backed by storage (contiguous: stored ≥ declared; deflated: declared ≤
``MAX_COMPRESSION_RATIO`` × stored + ``COMPRESSION_SLACK``) and all datasets together at most
``MAX_LOAD_BYTES``.  Before a variable-length string is read, the file's global heap
collections (where HDF5 keeps such strings, without checksums) are checked for the damage that
makes HDF5 loop forever or copy past an object.  Every problem raises :class:`InvalidFile`,
whose message names the object and what is wrong.

Files are built in memory (:func:`file_image`) so that a failing disk never reaches the HDF5
library mid-write (a full disk there crashed the process).  They use the HDF5 1.10 file
format, whose metadata (superblock, object headers, chunk indexes) carries checksums, and
store strings fixed-length (:func:`text_data`), inline in those checksummed headers instead of
the global heap: damaged metadata is then detected instead of parsed.
"""

from __future__ import annotations

import io
import json
import math
import mmap
import os
from pathlib import Path

import h5py
import numpy as np
from h5py import h5d, h5s, h5t, h5z

__all__ = ["COMPRESSION_SLACK", "MAX_COMPRESSION_RATIO", "MAX_LOAD_BYTES", "InvalidFile", "Reader", "file_image",
           "parse_json", "text_data"]

MAX_LOAD_BYTES = 8 * 2**30  # all datasets of one file together; larger files are refused unread
MAX_COMPRESSION_RATIO = 1100  # deflate cannot exceed 1032:1, so a higher declared ratio is a lie
COMPRESSION_SLACK = 64 * 2**10  # bytes: headers make tiny deflated chunks look highly compressed
_FILTERS = {h5z.FILTER_DEFLATE: "deflate", h5z.FILTER_SHUFFLE: "shuffle", h5z.FILTER_FLETCHER32: "fletcher32"}
_TYPE_CLASSES = {h5t.INTEGER: "integer", h5t.FLOAT: "float", h5t.STRING: "string", h5t.ENUM: "enum",
                 h5t.COMPOUND: "compound", h5t.REFERENCE: "reference", h5t.OPAQUE: "opaque", h5t.VLEN: "vlen",
                 h5t.ARRAY: "array", h5t.BITFIELD: "bitfield", h5t.TIME: "time"}
_MAX_TEXT = 64 * 2**20  # characters of one string attribute (parameters, meta)
_LIBVER = ("v110", "v110")  # checksummed metadata and chunk indexes, readable by HDF5 >= 1.10 (2018)
# Errors h5py raises for unreadable or inconsistent objects (it maps HDF5 errors onto these).
_H5_ERRORS = (OSError, KeyError, ValueError, TypeError, RuntimeError, IndexError, OverflowError)


class InvalidFile(Exception):
    """The file breaks the expected layout; the message names the object and the problem."""


def file_image(fill) -> bytes:
    """The bytes of a new HDF5 file filled by ``fill(file)``, built in memory."""
    buffer = io.BytesIO()
    with h5py.File(buffer, "w", libver=_LIBVER) as f:
        fill(f)
    return buffer.getvalue()


def text_data(value) -> tuple[np.ndarray, h5py.Datatype]:
    """``(data, dtype)`` storing a str or a sequence of str as fixed-length UTF-8 strings, kept
    in the (checksummed) object header or dataset, never in HDF5's global heap."""
    if isinstance(value, str):
        data = np.array(value.encode("utf-8"))
    else:
        data = np.array([str(v).encode("utf-8") for v in value], dtype=bytes)
    dtype = h5py.string_dtype("utf-8", max(1, data.dtype.itemsize))  # at least one byte: "" is one NUL
    return data.astype(dtype), dtype  # the dtype's metadata tells h5py the bytes are UTF-8


def _check_heap(view, start: int, size_len: int) -> str | None:
    """What is wrong with the global heap collection at ``start``, walked the way HDF5 1.x/2.0
    decodes it, or None.  Candidates that HDF5 itself refuses (version, size) are skipped."""
    header = 8 + size_len  # "GCOL", version, 3 reserved, collection size
    if start + header > len(view) or view[start + 4] != 1:
        return None
    end = start + int.from_bytes(view[start + 8:start + header], "little")
    if end < start + header or end > len(view):
        return None
    p = start + header
    while p + 8 + size_len <= end:  # object: index (2), references (2), reserved (4), size, data
        index = int.from_bytes(view[p:p + 2], "little")
        size = int.from_bytes(view[p + 8:p + 8 + size_len], "little")
        need = 8 + size_len + -(-size // 8) * 8 if index else size
        if need == 0:
            return f"the global heap at byte {start} has an empty free-space entry (HDF5 would loop forever)"
        if index and p + need > end:
            return f"object {index} of the global heap at byte {start} runs past the end of its collection"
        p += need
    return None


def parse_json(text: str, where: str, kind: type):
    """``json.loads(text)``, which must give a ``kind`` (dict or list)."""
    try:
        value = json.loads(text)
    except (ValueError, RecursionError) as err:  # RecursionError: absurdly nested text
        raise InvalidFile(f"{where} is not valid JSON ({err})") from None
    if not isinstance(value, kind):
        raise InvalidFile(f"{where} must be a JSON {'object' if kind is dict else 'array'}, got {type(value).__name__}")
    return value


def _link_class(group: h5py.Group, name: str, where: str):
    try:  # getlink=True: inspect the link itself; a soft or external link is never followed
        return group.get(name, getclass=True, getlink=True)
    except _H5_ERRORS as err:  # user-defined link types: "Unknown link type"
        raise InvalidFile(f"{where} has an unreadable link ({err})") from None


def _a(noun: str) -> str:
    return f"{'an' if noun[:1].lower() in 'aeiou' else 'a'} {noun}"


def _type_name(tid) -> str:
    return _TYPE_CLASSES.get(tid.get_class(), "unknown")


def _dtype(tid, where: str) -> np.dtype:
    """The numpy dtype of an HDF5 type socbjax writes: integer, float, bool (enum), complex
    (compound of two floats) or string; anything else is refused."""
    kind = _type_name(tid)
    if kind not in ("integer", "float", "string", "enum", "compound"):
        raise InvalidFile(f"{where} has HDF5 type class {kind}; socbjax stores only numbers, bools and strings")
    try:
        dtype = tid.dtype
    except _H5_ERRORS as err:
        raise InvalidFile(f"{where} has an unsupported {kind} type ({err})") from None
    if kind == "enum" and dtype != np.bool_ or kind == "compound" and dtype.kind != "c":
        raise InvalidFile(f"{where} has {_a(kind)} type ({dtype}); socbjax stores only numbers, bools and strings")
    if kind in ("integer", "float") and dtype.itemsize != tid.get_size():
        raise InvalidFile(f"{where} has a {8 * tid.get_size()}-bit {kind} type that numpy cannot hold exactly")
    return dtype


class Reader:
    """An HDF5 file opened read-only for validation (a context manager).

    ``Reader(path, groups)`` opens the file and checks its whole tree: the root holds only hard
    links to groups named in ``groups``, each group only hard links to datasets that pass the
    checks of the module docstring.  ``datasets[group][name]`` are the checked datasets;
    :meth:`read` reads one, :meth:`attr` reads an attribute after checking its type.
    """

    def __init__(self, path: Path, groups):
        self.path = path
        try:
            self.size = os.path.getsize(path)
            self.file = h5py.File(path, "r", locking=False)  # socbjax never writes in place: no lock needed
        except OSError as err:
            raise InvalidFile(f"it cannot be opened as HDF5 (truncated or damaged: {err})") from None
        self.groups, self.datasets, self.heaps_checked = set(groups), {}, False

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.file.close()

    def check_tree(self) -> dict[str, dict[str, h5py.Dataset]]:
        """Check every object (see the class docstring); returns ``datasets``."""
        total = stored_total = 0
        for gname in self._names(self.file, "/"):
            if gname not in self.groups:
                raise InvalidFile(f"/{gname} is not part of the layout (expected only {sorted(self.groups)})")
            group = self._object(self.file, gname, f"/{gname}", h5py.Group)
            self.datasets[gname] = {}
            for name in self._names(group, f"/{gname}/"):
                where = f"/{gname}/{name}"
                ds = self._object(group, name, where, h5py.Dataset)
                declared, stored = self._check_dataset(ds, where)
                total, stored_total = total + declared, stored_total + stored
                self.datasets[gname][name] = ds
        if stored_total > self.size:  # datasets sharing (aliasing) the same bytes to multiply what the file holds
            raise InvalidFile(f"its datasets claim {stored_total} stored bytes together, more than the file's "
                              f"{self.size} bytes (datasets that share storage: damaged or crafted file)")
        if total > MAX_LOAD_BYTES:
            raise InvalidFile(f"its datasets declare {total} bytes, above the limit of {MAX_LOAD_BYTES} "
                              "(socbjax._hdf5.MAX_LOAD_BYTES)")
        return self.datasets

    def _names(self, group: h5py.Group, where: str) -> list[str]:
        try:
            return list(group.keys())
        except _H5_ERRORS as err:
            raise InvalidFile(f"the members of {where} cannot be listed ({err})") from None

    def _object(self, group: h5py.Group, name: str, where: str, cls):
        link = _link_class(group, name, where)
        if link is None:  # listed, yet not found by name: a damaged link table
            raise InvalidFile(f"{where} is listed in its group but cannot be found (damaged file)")
        if link is not h5py.HardLink:
            raise InvalidFile(f"{where} is {_a(link.__name__)} "
                              "(socbjax files hold only hard links; links to other objects or files are not followed)")
        try:
            obj = group[name]
        except _H5_ERRORS as err:
            raise InvalidFile(f"{where} cannot be opened ({err})") from None
        if not isinstance(obj, cls):
            raise InvalidFile(f"{where} is {_a(type(obj).__name__)}, expected {_a(cls.__name__)}")
        return obj

    def _check_dataset(self, ds: h5py.Dataset, where: str) -> tuple[int, int]:
        """(declared, stored) bytes of ``ds`` after the storage, filter and type checks."""
        try:
            dcpl, space, tid = ds.id.get_create_plist(), ds.id.get_space(), ds.id.get_type()
            layout, external = dcpl.get_layout(), dcpl.get_external_count()
            filters = [dcpl.get_filter(i)[0] for i in range(dcpl.get_nfilters())] if layout == h5d.CHUNKED else []
            null, shape, stored = space.get_simple_extent_type() == h5s.NULL, space.shape, ds.id.get_storage_size()
        except _H5_ERRORS as err:
            raise InvalidFile(f"{where} has unreadable metadata ({err})") from None
        if layout == h5d.VIRTUAL:
            raise InvalidFile(f"{where} is a virtual dataset (data mapped from other files); socbjax writes none")
        if external:
            raise InvalidFile(f"{where} keeps its data in {external} external file(s); socbjax stores data in the file")
        unknown = [code for code in filters if code not in _FILTERS]
        if unknown:
            raise InvalidFile(f"{where} uses HDF5 filter id(s) {unknown}; only {sorted(_FILTERS.values())} are read "
                              "(other filters would load plugin code)")
        if null:
            raise InvalidFile(f"{where} has an empty (null) dataspace; socbjax writes arrays")
        dtype = _dtype(tid, where)
        declared = math.prod(shape) * max(dtype.itemsize, tid.get_size())
        if stored > self.size:
            raise InvalidFile(f"{where} claims {stored} stored bytes in a file of {self.size} bytes")
        if h5z.FILTER_DEFLATE in filters:
            if declared > MAX_COMPRESSION_RATIO * stored + COMPRESSION_SLACK:
                raise InvalidFile(f"{where} declares {declared} bytes backed by {stored} compressed bytes, more than "
                                  f"deflate can expand ({MAX_COMPRESSION_RATIO}:1): the data were never written")
        elif stored < declared:  # (variable-length strings: the stored heap ids count, as declared)
            raise InvalidFile(f"{where} declares {declared} bytes but the file stores {stored}: the data were never "
                              "written (damaged or crafted file)")
        return declared, stored

    def check_heaps(self) -> None:
        """Check every global heap collection (by its "GCOL" signature) before HDF5 decodes
        one: it has no checksum, and damage there makes HDF5 loop forever or overrun a buffer."""
        if self.heaps_checked or not self.size:
            return
        try:
            size_len = self.file.id.get_create_plist().get_sizes()[1]
            with open(self.path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as view:
                start = view.find(b"GCOL")
                while start >= 0:
                    if problem := _check_heap(view, start, size_len):
                        raise InvalidFile(problem)
                    start = view.find(b"GCOL", start + 1)
        except (OSError, ValueError) as err:
            raise InvalidFile(f"it cannot be scanned ({err})") from None
        self.heaps_checked = True

    def attr(self, obj, name: str, kind: str, where: str):
        """Attribute ``name`` of ``obj`` as ``kind`` ("int" or "str"), None when absent."""
        try:
            if name not in obj.attrs:
                return None
            aid = obj.attrs.get_id(name)
            cls, shape = aid.get_type().get_class(), aid.shape
        except _H5_ERRORS as err:
            raise InvalidFile(f"{where} cannot be read ({err})") from None
        want = {"int": h5t.INTEGER, "str": h5t.STRING}[kind]
        if cls != want or shape not in ((), (1,)):
            raise InvalidFile(f"{where} must be a single {'integer' if kind == 'int' else 'string'}, got "
                              f"{_a(_type_name(aid.get_type()))} of shape {shape}")
        if kind == "str" and aid.get_type().is_variable_str():
            self.check_heaps()
        try:
            value = np.asarray(obj.attrs[name]).reshape(()).item()
            value = value.decode("utf-8") if isinstance(value, bytes) else value
        except (*_H5_ERRORS, UnicodeDecodeError) as err:
            raise InvalidFile(f"{where} cannot be read ({err})") from None
        if kind == "str" and len(value) > _MAX_TEXT:
            raise InvalidFile(f"{where} holds {len(value)} characters, more than socbjax writes ({_MAX_TEXT})")
        return int(value) if kind == "int" else str(value)

    def read(self, ds: h5py.Dataset, where: str, text: bool = False) -> np.ndarray:
        """The data of a checked dataset (0-d as a 0-d array; strings decoded when ``text``)."""
        try:
            if text:
                info = h5py.check_string_dtype(ds.dtype)
                if info is None:
                    raise InvalidFile(f"{where} must hold strings, got dtype {ds.dtype}")
                if info.length is None:  # variable-length: decoded from the global heap
                    self.check_heaps()
                return np.asarray(ds.asstr()[()], dtype=object)
            data = np.asarray(ds[()])
            return data if data.dtype.isnative else data.astype(data.dtype.newbyteorder("="))
        except (*_H5_ERRORS, UnicodeDecodeError) as err:  # damaged chunks: deflate or checksum errors
            raise InvalidFile(f"the data of {where} cannot be read ({err})") from None
