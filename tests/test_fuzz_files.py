"""Crafted and damaged files given to sj.load / sj.load_checkpoint: each is refused with one
ValueError naming the file and the problem (never another exception, never a crash, never a
read of another file), and whatever loads can be plotted."""

import json
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import socbjax as sj
import socbjax._hdf5 as hdf5
from socbjax import CompressionResult, LimitPoint

SECRET = "TOP-SECRET-7f3a9c"
K, N, S = 7, 4, 3


def make_result(dim=2):
    """A hand-built result on a 4-node pinned column (no solve: fast)."""
    rng = np.random.default_rng(1)
    net = sj.column(N, dim=dim, supports=("pinned", "pinned"))
    return CompressionResult(
        displacement=np.linspace(0.0, 0.6, K), force=rng.normal(size=K), converged=np.ones(K, bool),
        stable=np.arange(K) % 3 != 2, phase=np.array([0, 1, 1, 1, 1, 2, 2], np.int8),
        positions=rng.normal(size=(K, N, dim)), tangents=rng.normal(size=(K, N, dim)),
        moments=rng.normal(size=(K, N) if dim == 2 else (K, N, 3)), segment_forces=rng.normal(size=(K, S, dim)),
        twists=np.zeros((K, 0)), end_nodes=np.array([0, 3]), end_forces=rng.normal(size=(K, 2)), iterations=np.full(K, 3, np.int32),
        limit_points=(LimitPoint("force_maximum", 3, 0.3, 1.2, "loading"), LimitPoint("fold", 5, 0.5, 0.1, "unloading"),
                      LimitPoint("surface_crossing", 6, 0.55, 0.0, "unloading")),
        result=sj.RESULTS.successful, network=net, parameters_json=json.dumps({"u_max": 0.6}),
    )


def legacy(content: bytes, path):
    """``content`` rewritten the way socbjax <= 0.2.0 wrote files: variable-length strings (in
    HDF5's global heap) and the earliest HDF5 file format (no metadata checksums)."""
    source = path.with_name(path.name + ".src")
    source.write_bytes(content)

    def copy_attrs(a, b):
        for key, value in a.attrs.items():
            if isinstance(value, bytes):
                value = value.decode()
            elif isinstance(value, np.ndarray) and value.dtype.kind == "S":
                value = [v.decode() for v in value]
            b.attrs[key] = value

    with h5py.File(source, "r") as a, h5py.File(path, "w") as b:
        copy_attrs(a, b)
        for gname, group in a.items():
            copy_attrs(group, b.create_group(gname))
            for name, ds in group.items():
                if ds.dtype.kind == "S":
                    b[gname].create_dataset(name, data=ds.asstr()[()].astype(object), dtype=h5py.string_dtype())
                else:
                    b[gname].create_dataset(name, data=ds[()], compression=ds.compression, shuffle=ds.shuffle)
                copy_attrs(ds, b[gname][name])
    source.unlink()
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Bytes of a valid 2D and 3D result, a checkpoint, both also as written by earlier socbjax,
    and a secret file that no load may read."""
    folder = tmp_path_factory.mktemp("valid")
    secret = folder / "secret.txt"
    secret.write_text(SECRET * 64)
    with h5py.File(folder / "other.h5", "w") as f:
        f["data"] = np.frombuffer((SECRET * 8).encode()[: K * 8], np.float64)
    out = {"secret": secret, "other": folder / "other.h5"}
    for dim in (2, 3):
        out[dim] = sj.save(make_result(dim), folder / f"run{dim}.h5").read_bytes()
    out["ck"] = sj.save_checkpoint(folder / "ck.h5", {"x": np.arange(5.0), "big": np.zeros(20000)}, {"i": 1}).read_bytes()
    for key in (2, "ck"):
        out["legacy", key] = legacy(out[key], folder / "legacy.h5").read_bytes()
    return out


def assert_refused(path, *words, checkpoint=False):
    """The load raises exactly ValueError("<path> is not a valid socbjax ...: ...") with ``words``."""
    load = sj.load_checkpoint if checkpoint else sj.load
    with pytest.raises(ValueError) as info:
        load(path)
    message = str(info.value)
    assert type(info.value) is ValueError, repr(info.value)
    assert message.startswith(f"{path} is not a valid socbjax {'checkpoint' if checkpoint else 'result'}: "), message
    for word in words:
        assert word in message, message
    assert SECRET not in message
    return message


def replace(f, name, **kwargs):
    del f[name]
    return f.create_dataset(name, **kwargs)


def external_storage(files):
    def edit(f):
        replace(f, "path/force", shape=(K,), dtype="f8", external=[(str(files["secret"]), 0, K * 8)])
    return edit


def virtual(files):
    def edit(f):
        layout = h5py.VirtualLayout(shape=(K,), dtype="f8")
        layout[:] = h5py.VirtualSource(str(files["other"]), "data", shape=(K,))
        del f["path/force"]
        f.create_virtual_dataset("path/force", layout)
    return edit


def external_link(files):
    def edit(f):
        del f["path/force"]
        f["path/force"] = h5py.ExternalLink(str(files["other"]), "/data")
    return edit


def soft(target):
    def edit(f):
        del f["path/force"]
        f["path/force"] = h5py.SoftLink(target)
    return edit


def attr(name, value, where="/"):
    def edit(f):
        if value is None:
            del f[where].attrs[name]
        else:
            f[where].attrs[name] = value
    return edit


def data(name, value, **kwargs):
    return lambda f: replace(f, name, data=value, **kwargs)


def set_item(name, index, value):
    def edit(f):
        f[name][index] = value
    return edit


def delete(name):
    def edit(f):
        del f[name]
    return edit


COMPOUND = np.zeros(K, dtype=[("a", "f8"), ("b", "i4")])
# (id, edit or edit factory taking the fixture, words the message must hold)
CRAFTED = [
    ("external storage", external_storage, ["/path/force", "external file"]),
    ("virtual dataset", virtual, ["/path/force", "virtual"]),
    ("external link", external_link, ["/path/force", "ExternalLink"]),
    ("soft link to a dataset", lambda fx: soft("/path/displacement"), ["/path/force", "SoftLink"]),
    ("dangling soft link", lambda fx: soft("/nowhere"), ["/path/force", "SoftLink"]),
    ("soft link group", lambda fx: lambda f: (delete("units")(f), f.__setitem__("units", h5py.SoftLink("/path"))),
     ["/units", "SoftLink"]),
    ("unknown filter", lambda fx: lambda f: replace(f, "path/force", shape=(K,), dtype="f8", compression=32001,
                                                    allow_unknown_filter=True), ["/path/force", "filter"]),
    ("huge chunked gzip", lambda fx: lambda f: replace(f, "path/force", shape=(10**9,), dtype="f8", chunks=(2**16,),
                                                       compression="gzip"), ["/path/force", "deflate can expand"]),
    ("huge contiguous", lambda fx: lambda f: replace(f, "path/force", shape=(10**9,), dtype="f8"),
     ["/path/force", "never written"]),
    ("huge unwritten string", lambda fx: lambda f: replace(f, "limit_points/kind", shape=(10**8,),
                                                           dtype=h5py.string_dtype()), ["/limit_points/kind"]),
    ("format missing", lambda fx: attr("format", None), ["not a socbjax file"]),
    ("format other", lambda fx: attr("format", "socbjax.checkpoint"), ["socbjax.checkpoint file", "load_checkpoint"]),
    ("format as number", lambda fx: attr("format", 3), ["attribute format", "string"]),
    *[(f"format_version {v!r}", lambda fx, v=v: attr("format_version", v), ["format_version"])
      for v in (0, -1, "x", 2.5, np.array([1, 2]))],
    ("format_version 99", lambda fx: attr("format_version", 99), ["newer socbjax"]),
    ("format_version missing", lambda fx: attr("format_version", None), ["format_version"]),
    ("result missing", lambda fx: attr("result", None), ["attribute result", "missing"]),
    ("result garbled", lambda fx: attr("result", "nonsense"), ["attribute result", "unknown result"]),
    ("result as int", lambda fx: attr("result", 3), ["attribute result", "string"]),
    ("result bytes not UTF-8", lambda fx: attr("result", np.bytes_(b"\xff\xfe")), ["attribute result"]),
    ("status instead of result (v2)", lambda fx: lambda f: (attr("result", None)(f), attr("status", 1)(f)),
     ["attribute result"]),
    ("parameters bad JSON", lambda fx: attr("parameters", '{"f": '), ["attribute parameters", "JSON"]),
    ("parameters deeply nested", lambda fx: attr("parameters", "[" * 100000), ["attribute parameters", "JSON"]),
    ("parameters a list", lambda fx: attr("parameters", "[1]"), ["attribute parameters", "object"]),
    ("parameters missing", lambda fx: attr("parameters", None), ["parameters", "missing"]),
    ("parameters int", lambda fx: attr("parameters", 7), ["attribute parameters"]),
    ("/path missing", lambda fx: delete("path"), ["/path", "missing"]),
    ("/network missing", lambda fx: delete("network"), ["/network", "missing"]),
    ("/path/force missing", lambda fx: delete("path/force"), ["/path", "force"]),
    ("/network/segments missing", lambda fx: delete("network/segments"), ["/network", "segments"]),
    ("/limit_points/step missing", lambda fx: delete("limit_points/step"), ["/limit_points", "step"]),
    ("unexpected dataset", lambda fx: lambda f: f.create_dataset("path/extra", data=[1.0]), ["/path", "extra"]),
    ("unexpected group", lambda fx: lambda f: f.create_group("extra"), ["/extra"]),
    ("root dataset", lambda fx: lambda f: f.create_dataset("loose", data=[1.0]), ["/loose"]),
    ("group instead of dataset", lambda fx: lambda f: (delete("path/force")(f), f.create_group("path/force")),
     ["/path/force", "Group"]),
    ("dataset instead of group", lambda fx: lambda f: (delete("units")(f), f.create_dataset("units", data=[1])),
     ["/units", "Dataset"]),
    ("named datatype", lambda fx: lambda f: f["path"].__setitem__("dt", np.dtype("f8")), ["/path/dt", "Datatype"]),
    ("force too long", lambda fx: data("path/force", np.zeros(K + 1)), ["/path/force", "K = 7"]),
    ("positions wrong N", lambda fx: data("path/positions", np.zeros((K, N + 1, 2))), ["/path/positions", "N = 4"]),
    ("positions wrong rank", lambda fx: data("path/positions", np.zeros((K, N))), ["/path/positions", "shape"]),
    ("lengths wrong S", lambda fx: data("network/lengths", np.ones(S + 2)), ["/network/lengths", "S = 3"]),
    ("moments 2 components", lambda fx: data("path/moments", np.zeros((K, N, 2))), ["/path/moments"]),
    ("scalar force", lambda fx: data("path/force", 1.0), ["/path/force", "shape"]),
    ("empty path", lambda fx: lambda f: [data(f"path/{n}", np.zeros((0,) + f[f"path/{n}"].shape[1:],
                                                                     f[f"path/{n}"].dtype))(f) for n in list(f["path"])
                                       if n != "end_nodes"],
     ["no steps"]),
    ("float segments", lambda fx: data("network/segments", np.array([[0, 1], [1, 2], [2, 3]], float)),
     ["/network/segments", "dtype float64", "integer"]),
    ("string iterations", lambda fx: data("path/iterations", np.array([b"3"] * K)), ["/path/iterations", "integer"]),
    ("compound force", lambda fx: data("path/force", COMPOUND), ["/path/force", "compound"]),
    ("object references", lambda fx: lambda f: replace(f, "path/force", shape=(K,), dtype=h5py.ref_dtype),
     ["/path/force", "reference"]),
    ("vlen ints", lambda fx: lambda f: replace(f, "path/iterations", shape=(K,), dtype=h5py.vlen_dtype("i4")),
     ["/path/iterations", "vlen"]),
    ("int converged", lambda fx: data("path/converged", np.ones(K, np.int8)), ["/path/converged", "bool"]),
    ("enum converged", lambda fx: data("path/converged", np.ones(K, np.int8),
                                       dtype=h5py.enum_dtype({"A": 0, "B": 1, "C": 2}, basetype="i1")),
     ["/path/converged", "enum"]),
    ("float16 force", lambda fx: data("path/force", np.zeros(K, np.float16)), ["/path/force", "float32/float64"]),
    ("complex force", lambda fx: data("path/force", np.zeros(K, complex)), ["/path/force"]),
    ("limit kind numeric", lambda fx: data("limit_points/kind", np.zeros(2)), ["/limit_points/kind", "string"]),
    ("segment index 999", lambda fx: set_item("network/segments", (1, 1), 999), ["/network/segments", "999"]),
    ("segment index -1", lambda fx: set_item("network/segments", (1, 1), -1), ["/network/segments", "-1"]),
    ("segment self loop", lambda fx: set_item("network/segments", (1, 1), 1), ["/network/segments", "itself"]),
    ("attach 999", lambda fx: set_item("network/attach", 0, 999), ["/network/attach", "999"]),
    ("transfer segment 999", lambda fx: set_item("network/transfer_segment", 0, 999), ["/network/transfer_segment"]),
    ("leaving segment -5", lambda fx: set_item("network/leaving_segment", 0, -5), ["/network/leaving_segment"]),
    ("socb row out of range", lambda fx: set_item("network/socb_rows", 0, 10**6), ["/network/socb_rows"]),
    ("end node 999", lambda fx: set_item("path/end_nodes", 1, 999), ["/path/end_nodes", "999"]),
    ("phase 9", lambda fx: set_item("path/phase", 2, 9), ["/path/phase", "9"]),
    ("no loading phase", lambda fx: data("path/phase", np.full(K, 2, np.int8)), ["/path/phase", "loading"]),
    ("negative iterations", lambda fx: set_item("path/iterations", 0, -3), ["/path/iterations"]),
    ("limit step K", lambda fx: set_item("limit_points/step", 0, K), ["/limit_points row 0", "step 7 is outside"]),
    ("limit step -1", lambda fx: set_item("limit_points/step", 1, -1), ["/limit_points row 1", "step -1"]),
    ("limit kind not an identifier", lambda fx: set_item("limit_points/kind", 0, "$\\frac{"),
     ["/limit_points row 0", "identifier"]),
    ("limit phase unknown", lambda fx: set_item("limit_points/phase", 0, "sideways"), ["/limit_points row 0", "sideways"]),
    ("limit columns unequal", lambda fx: data("limit_points/step", np.array([1, 2])), ["/limit_points/step"]),
    ("absurd position", lambda fx: set_item("path/positions", (1, 1, 0), -1e300), ["/path/positions", "beyond"]),
    ("infinite limit force", lambda fx: set_item("limit_points/force", 0, np.inf), ["/limit_points/force", "inf"]),
    ("NaN network position", lambda fx: set_item("network/positions", (0, 0), np.nan), ["/network/positions", "NaN"]),
    ("dim 7", lambda fx: attr("dim", 7, "network"), ["dim", "7"]),
    ("dim swapped", lambda fx: lambda f: f["network"].attrs.__setitem__("dim", 5 - f["network"].attrs["dim"]),
     ["/network/positions", "d = "]),
    ("dim text", lambda fx: attr("dim", "2", "network"), ["dim", "integer"]),
    ("dim missing", lambda fx: attr("dim", None, "network"), ["dim", "None"]),
    ("legacy limit points bad JSON", lambda fx: lambda f: (delete("limit_points")(f), attr("limit_points", "[{")(f)),
     ["attribute limit_points", "JSON"]),
    ("legacy limit point wrong fields", lambda fx: lambda f: (delete("limit_points")(f),
                                                              attr("limit_points", '[{"kind": "fold"}]')(f)),
     ["limit point 0"]),
    ("legacy limit point step out of range", lambda fx: lambda f: (delete("limit_points")(f), attr("limit_points", json.dumps(
        [{"kind": "fold", "step": 70, "displacement": 0.1, "force": 1, "phase": "loading"}]))(f)), ["limit point 0"]),
]
VERSION_1 = [  # format 1 files: an integer status instead of the result name
    ("status 99", lambda f: attr("status", 99)(f), ["attribute status", "99"]),
    ("status missing", lambda f: None, ["attribute status", "None"]),
    ("status text", lambda f: attr("status", "six")(f), ["attribute status"]),
]
CHECKPOINT = [
    ("external storage", lambda fx: lambda f: replace(f, "arrays/0", shape=(40,), dtype="u1",
                                                      external=[(str(fx["secret"]), 0, 40)]), ["/arrays/0", "external"]),
    ("huge", lambda fx: lambda f: replace(f, "arrays/1", shape=(10**10,), dtype="f8", chunks=(2**16,),
                                          compression="gzip"), ["/arrays/1"]),
    ("names bad JSON", lambda fx: attr("names", "[", "arrays"), ["names", "JSON"]),
    ("names not strings", lambda fx: attr("names", "[1, 2]", "arrays"), ["names", "strings"]),
    ("names count", lambda fx: attr("names", '["x"]', "arrays"), ["/arrays", "names"]),
    ("names duplicate", lambda fx: attr("names", '["x", "x"]', "arrays"), ["names", "distinct"]),
    ("meta bad JSON", lambda fx: attr("meta", "{"), ["attribute meta", "JSON"]),
    ("meta missing", lambda fx: attr("meta", None), ["attribute meta", "missing"]),
    ("meta list", lambda fx: attr("meta", "[]"), ["attribute meta", "object"]),
    ("vlen strings", lambda fx: data("arrays/0", np.array(["a", "b"], dtype=object), dtype=h5py.string_dtype()),
     ["/arrays/0", "variable-length"]),
    ("soft link", lambda fx: lambda f: (delete("arrays/0")(f), f["arrays"].__setitem__("0", h5py.SoftLink("/arrays/1"))),
     ["/arrays/0", "SoftLink"]),
    ("arrays missing", lambda fx: delete("arrays"), ["/arrays", "missing"]),
    ("format result", lambda fx: attr("format", "socbjax.compression"), ["socbjax.compression file", "socbjax.load"]),
]


def crafted(tmp_path, content: bytes, edit) -> os.PathLike:
    path = tmp_path / "crafted.h5"
    path.write_bytes(content)
    with h5py.File(path, "a") as f:
        edit(f)
    return path


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name, make, words", CRAFTED, ids=[c[0] for c in CRAFTED])
def test_crafted_result_refused(tmp_path, files, dim, name, make, words):
    assert_refused(crafted(tmp_path, files[dim], make(files)), *words)  # from the metadata, nothing read


@pytest.mark.parametrize("name, edit, words", VERSION_1, ids=[c[0] for c in VERSION_1])
def test_crafted_format_1_result_refused(tmp_path, files, name, edit, words):
    def to_version_1(f):
        f.attrs["format_version"] = 1
        del f.attrs["result"]
        edit(f)

    assert_refused(crafted(tmp_path, files[2], to_version_1), *words)


@pytest.mark.parametrize("name, make, words", CHECKPOINT, ids=[c[0] for c in CHECKPOINT])
def test_crafted_checkpoint_refused(tmp_path, files, name, make, words):
    assert_refused(crafted(tmp_path, files["ck"], make(files)), *words, checkpoint=True)


@pytest.mark.parametrize("make", [external_storage, virtual, external_link], ids=["storage", "virtual", "link"])
def test_crafted_files_are_real_attacks(tmp_path, files, make):
    """Plain h5py follows what load refuses: the bytes of the other file come back."""
    path = crafted(tmp_path, files[2], make(files))
    with h5py.File(path, "r") as f:
        assert SECRET.encode()[:8] in f["path/force"][()].tobytes()
    assert_refused(path, "/path/force")


def test_total_size_cap(tmp_path, files, monkeypatch):
    path = tmp_path / "run.h5"
    path.write_bytes(files[2])
    assert sj.load(path).n_steps == K
    monkeypatch.setattr(hdf5, "MAX_LOAD_BYTES", 1000)
    assert_refused(path, "MAX_LOAD_BYTES", "1000")


@pytest.mark.parametrize("content", [b"", b"hello", b"\x89HDF\r\n\x1a\n", bytes(range(256)) * 40],
                         ids=["empty", "text", "signature only", "bytes"])
def test_not_hdf5_refused(tmp_path, content):
    path = tmp_path / "x.h5"
    path.write_bytes(content)
    assert_refused(path)
    assert_refused(path, checkpoint=True)


def test_special_inputs_refused_without_blocking(tmp_path):
    fifo = tmp_path / "fifo.h5"
    os.mkfifo(fifo)
    assert_refused(fifo, "not a regular file")  # would block forever if opened
    assert_refused(tmp_path, "not a regular file")
    with pytest.raises(FileNotFoundError, match="absent"):
        sj.load(tmp_path / "absent.h5")


@pytest.mark.parametrize("fraction", [0.0, 0.01, 0.1, 0.3, 0.5, 0.9, 0.999])
def test_truncated_refused(tmp_path, files, fraction):
    for key in (2, "ck"):
        path = tmp_path / "cut.h5"
        path.write_bytes(files[key][: int(fraction * len(files[key]))])
        assert_refused(path, checkpoint=key == "ck")


def _load_or_refuse(path, checkpoint=False):
    """Load (and, for a result, draw every plot) or return the ValueError message."""
    try:
        if checkpoint:
            sj.load_checkpoint(path)
            return "loaded"
        result = sj.load(path)
    except ValueError as err:
        assert type(err) is ValueError and str(err).startswith(f"{path} is not a valid socbjax"), repr(err)
        return "refused"
    for plot in (sj.plot_force_curve, sj.plot_snapshots, sj.plot_end_forces, sj.plot_strand_forces):
        plot(result)
    return "loaded"


FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@FUZZ
@given(cut=st.integers(0, 10**6), key=st.sampled_from([2, 3, "ck"]))
def test_random_truncation(tmp_path, files, cut, key):
    content = files[key]
    path = tmp_path / "cut.h5"
    path.write_bytes(content[: cut % len(content)])
    assert _load_or_refuse(path, checkpoint=key == "ck") == "refused"


@FUZZ
@given(flips=st.lists(st.tuples(st.integers(0, 10**6), st.integers(1, 255)), min_size=1, max_size=6),
       key=st.sampled_from([2, 3, "ck"]))
def test_random_byte_flips(tmp_path, files, flips, key):
    content = bytearray(files[key])
    for offset, mask in flips:
        content[offset % len(content)] ^= mask
    path = tmp_path / "flipped.h5"
    path.write_bytes(bytes(content))
    assert _load_or_refuse(path, checkpoint=key == "ck") in ("loaded", "refused")


@FUZZ
@given(flips=st.lists(st.tuples(st.integers(0, 10**6), st.integers(1, 255)), min_size=1, max_size=4),
       key=st.sampled_from([2, "ck"]), in_heap=st.booleans())
def test_random_byte_flips_in_files_of_earlier_socbjax(tmp_path, files, flips, key, in_heap):
    """Files without checksums, with strings in the global heap (where one flip hung HDF5)."""
    path, content = tmp_path / "old.h5", bytearray(files["legacy", key])
    heap = content.find(b"GCOL")
    for offset, mask in flips:
        content[heap + 8 + offset % 400 if in_heap else offset % len(content)] ^= mask
    path.write_bytes(bytes(content))
    assert _load_or_refuse(path, checkpoint=key == "ck") in ("loaded", "refused")


def test_valid_files_load_and_plot(tmp_path, files):
    for dim in (2, 3):
        path = tmp_path / f"run{dim}.h5"
        path.write_bytes(files[dim])
        result = sj.load(path)
        assert result.network.dim == dim and result.n_steps == K
        assert [p.name for p in sj.save_figures(result, tmp_path / f"fig{dim}")] == [
            "force_curve.png", "snapshots.png", "end_forces.png", "strand_forces.png"]


def test_files_of_earlier_socbjax_still_load(tmp_path, files):
    for dim in (2, 3):
        back = sj.load(legacy(files[dim], tmp_path / "old.h5"))
        assert back.network.dim == dim and back.limit_points == make_result(dim).limit_points
    arrays, meta = sj.load_checkpoint(legacy(files["ck"], tmp_path / "old.h5"))
    assert meta == {"i": 1} and arrays["x"].tolist() == [0, 1, 2, 3, 4]


def test_damaged_global_heap_refused_instead_of_hanging(tmp_path, files):
    """A zero-sized free-space entry in a global heap collection made HDF5 2.0 loop forever
    reading the first string attribute (found by the byte-flip fuzzing below)."""
    path = legacy(files[2], tmp_path / "old.h5")
    content = bytearray(path.read_bytes())
    start = content.find(b"GCOL")
    end, p = start + int.from_bytes(content[start + 8:start + 16], "little"), start + 16
    while int.from_bytes(content[p:p + 2], "little"):  # walk to the free-space entry (index 0)
        p += 16 + -(-int.from_bytes(content[p + 8:p + 16], "little") // 8) * 8
    assert p < end
    content[p + 8:p + 16] = bytes(8)
    path.write_bytes(bytes(content))
    # in a child process with a timeout: a regression hangs inside HDF5, where no test could stop it
    code = "import sys, socbjax as sj\ntry:\n sj.load(sys.argv[1])\nexcept ValueError as err:\n print(err)\n"
    child = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=120,
                           check=False)
    assert "global heap" in child.stdout and "loop forever" in child.stdout, child.stdout + child.stderr[-2000:]
    content[p + 8:p + 16] = (10**6).to_bytes(8, "little")  # an object running past its collection
    content[start + 16 + 8:start + 16 + 16] = (5000).to_bytes(8, "little")
    path.write_bytes(bytes(content))
    assert_refused(path, "global heap", "runs past")


def test_datasets_sharing_storage_cannot_multiply_the_file(tmp_path):
    """Contiguous datasets whose layout addresses all point at one stored array (old file
    format, no checksums) would load as N copies from one file's bytes: refused."""
    n, m = 12, 2**17 // 8
    path = tmp_path / "aliased.h5"
    with h5py.File(path, "w", libver="earliest") as f:
        f.attrs["format"] = np.bytes_(b"socbjax.checkpoint")
        f.attrs["format_version"] = 2
        f.attrs["meta"] = np.bytes_(json.dumps({"i": 0}).encode())
        g = f.create_group("arrays")
        g.attrs["names"] = np.bytes_(json.dumps([f"a{i}" for i in range(n)]).encode())
        address = g.create_dataset("0", data=np.arange(m, dtype=np.float64)).id.get_offset()
        for i in range(1, n):
            g.create_dataset(str(i), shape=(m,), dtype=np.float64)  # contiguous, never written
    raw = bytearray(path.read_bytes())
    undefined = b"\xff" * 8 + (m * 8).to_bytes(8, "little")  # "no address yet" + size, in each layout message
    assert raw.count(undefined) == n - 1
    path.write_bytes(bytes(raw).replace(undefined, address.to_bytes(8, "little") + (m * 8).to_bytes(8, "little")))
    assert_refused(path, "stored bytes together", checkpoint=True)
