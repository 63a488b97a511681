"""HDF5 save/load of a CompressionResult and of checkpoints: exact round trips, atomic
writes that leave no partial or temporary files, and clear errors for foreign files."""

import dataclasses
import json
import os

import h5py
import jax.numpy as jnp
import numpy as np
import pytest

import socbjax as sj
from socbjax import CompressionResult, LimitPoint


def make_result(dim=3, K=7, N=4, E=1, seed=0):
    """A hand-built result on a 4-node column: K steps, N nodes, S = N − 1 segments."""
    rng = np.random.default_rng(seed)
    net = sj.column(N, dim=dim)
    S = N - 1
    moments = rng.normal(size=(K, N, 3) if dim == 3 else (K, N))
    return CompressionResult(
        displacement=np.linspace(0.0, 0.6, K),
        force=rng.normal(size=K),
        converged=np.ones(K, bool),
        stable=np.arange(K) % 3 != 2,
        phase=np.array([0] + [1] * (K - 3) + [2, 2], dtype=np.int64),
        positions=rng.normal(size=(K, N, dim)),
        tangents=rng.normal(size=(K, N, dim)),
        moments=moments,
        segment_forces=rng.normal(size=(K, S, dim)),
        end_nodes=np.arange(E, dtype=np.int32),
        end_forces=rng.normal(size=(K, E)),
        iterations=rng.integers(1, 9, size=K).astype(np.int32),
        limit_points=(
            LimitPoint("force_maximum", 3, 0.3, 1.25, "loading"),
            LimitPoint("bifurcation", 5, 0.5, -0.5, "unloading"),
        ),
        result=sj.RESULTS.max_steps,
        network=net,
        parameters_json=json.dumps({"u_max": 0.6, "method": "arclength",
                                    "nested": {"list": [1, 2.5, "µm"], "flag": True, "none": None}}),
    )


def assert_results_equal(a, b):
    for field in dataclasses.fields(CompressionResult):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if field.name == "network":
            assert x.topology == y.topology and y.dim == x.dim and type(y.dim) is int
            for name in ("positions", "tangents", "lengths", "EI", "loads", "couples"):
                u, v = np.asarray(getattr(x, name)), np.asarray(getattr(y, name))
                assert u.dtype == v.dtype and u.shape == v.shape, name
                np.testing.assert_array_equal(u, v)
        elif field.name == "result":
            assert bool(x == y)
        elif field.name == "parameters_json":
            assert json.loads(x) == json.loads(y)
        elif isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, field.name
            np.testing.assert_array_equal(x, y)
        else:
            assert x == y, field.name


def tmp_files(folder):
    return [name for name in os.listdir(folder) if name.endswith(".tmp")]


@pytest.mark.parametrize("dim", [2, 3])
def test_round_trip_equal_in_every_field(tmp_path, dim):
    result = make_result(dim)
    path = sj.save(result, tmp_path / "run.h5")
    assert path == tmp_path / "run.h5" and path.is_file()
    back = sj.load(str(path))
    assert_results_equal(result, back)
    assert isinstance(back.network.positions, jnp.ndarray)
    assert back.summary() == result.summary()
    assert tmp_files(tmp_path) == []


def test_file_layout_units_and_stamps(tmp_path):
    result = make_result()
    path = sj.save(result, tmp_path / "run.h5")
    with h5py.File(path, "r") as f:
        assert f.attrs["format"] == "socbjax.compression"
        assert f.attrs["format_version"] == 2
        assert f.attrs["socbjax_version"] == sj.__version__
        assert "created" in f.attrs and f.attrs["result"] == "max_steps"
        assert f["units"].attrs["displacement"] == "µm" and f["units"].attrs["moments"] == "pN·µm"
        assert f["path/force"].attrs["units"] == "pN"
        assert f["network"].attrs["dim"] == 3
        assert list(f["limit_points/kind"].asstr()[()]) == ["force_maximum", "bifurcation"]


def test_large_arrays_compressed_and_empty_limit_points(tmp_path):
    result = dataclasses.replace(make_result(K=400, N=12, E=0), limit_points=())
    path = sj.save(result, tmp_path / "big.h5")
    with h5py.File(path, "r") as f:
        assert f["path/positions"].compression == "gzip"
        assert f["path/force"].compression is None
    assert_results_equal(result, sj.load(path))


def test_overwrite_replaces_atomically(tmp_path):
    path = tmp_path / "run.h5"
    sj.save(make_result(seed=1), path)
    path.chmod(0o640)
    second = make_result(seed=2)
    sj.save(second, path)
    assert_results_equal(second, sj.load(path))
    assert (path.stat().st_mode & 0o777) == 0o640  # permissions of the replaced file kept
    assert tmp_files(tmp_path) == []


def test_failure_mid_write_keeps_previous_file_and_no_temporaries(tmp_path, monkeypatch):
    path = tmp_path / "run.h5"
    sj.save(make_result(seed=1), path)
    before = path.read_bytes()
    original = h5py.Group.create_dataset
    calls = []

    def failing(self, name, *args, **kwargs):
        calls.append(name)
        if len(calls) % 5 == 0:
            raise RuntimeError("disk full (simulated)")
        return original(self, name, *args, **kwargs)

    monkeypatch.setattr(h5py.Group, "create_dataset", failing)
    with pytest.raises(RuntimeError, match="simulated"):
        sj.save(make_result(seed=2), path)
    calls.clear()
    with pytest.raises(RuntimeError, match="simulated"):
        sj.save(make_result(seed=2), tmp_path / "new.h5")
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert not (tmp_path / "new.h5").exists()
    assert tmp_files(tmp_path) == []
    assert_results_equal(make_result(seed=1), sj.load(path))


def test_bad_parameters_fail_before_writing(tmp_path):
    result = dataclasses.replace(make_result(), parameters_json='{"f": NaN')  # not JSON
    with pytest.raises(TypeError, match="JSON"):
        sj.save(result, tmp_path / "run.h5")
    assert os.listdir(tmp_path) == []
    result = dataclasses.replace(make_result(), parameters_json=json.dumps({"n": 3, "x": 0.5, "a": [0, 1]}))
    assert sj.load(sj.save(result, tmp_path / "run.h5")).parameters == {"n": 3, "x": 0.5, "a": [0, 1]}


def test_missing_folder_and_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere"):
        sj.save(make_result(), tmp_path / "nowhere" / "run.h5")
    with pytest.raises(FileNotFoundError, match="absent.h5"):
        sj.load(tmp_path / "absent.h5")
    with pytest.raises(FileNotFoundError, match="absent.h5"):
        sj.load_checkpoint(tmp_path / "absent.h5")
    with pytest.raises(TypeError, match="CompressionResult"):
        sj.save({"force": 1}, tmp_path / "run.h5")


def test_foreign_and_future_files_rejected(tmp_path):
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = np.arange(3)
    with pytest.raises(ValueError, match="not a socbjax file"):
        sj.load(foreign)
    text = tmp_path / "notes.h5"
    text.write_text("hello")
    with pytest.raises(ValueError, match="not an HDF5 file"):
        sj.load(text)
    path = sj.save(make_result(), tmp_path / "run.h5")
    with pytest.raises(ValueError, match="socbjax.compression file"):
        sj.load_checkpoint(path)
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 3
    with pytest.raises(ValueError, match="newer socbjax"):
        sj.load(path)


def test_checkpoint_round_trip_is_bitwise(tmp_path, rng):
    floats = rng.normal(size=(5, 3))
    floats[0, :3] = [np.nan, -0.0, np.inf]
    floats[1, 0] = 5e-324  # subnormal
    arrays = {
        "carry/X": floats,
        "carry/u": np.float64(0.125),
        "carry/done": np.bool_(True),
        "carry/k": np.asarray(7, np.int32),
        "mask": rng.random(9) > 0.5,
        "index": np.arange(6, dtype=np.int32).reshape(2, 3),
        "big": rng.normal(size=20000),
        "empty": np.zeros((0, 3)),
        "jax": jnp.arange(4.0),
    }
    meta = {"fingerprint": "abc123", "phase_index": 2, "u": 0.1 + 0.2, "list": [1, "two", None]}
    path = sj.save_checkpoint(tmp_path / "ck.h5", arrays, meta)
    back, meta_back = sj.load_checkpoint(path)
    assert list(back) == list(arrays) and meta_back == meta
    for name, value in arrays.items():
        value = np.asarray(value)
        got = back[name]
        assert isinstance(got, np.ndarray) and got.dtype == value.dtype and got.shape == value.shape, name
        assert got.tobytes() == value.tobytes(), name
    with h5py.File(path, "r") as f:
        assert f.attrs["format"] == "socbjax.checkpoint" and f.attrs["format_version"] == 2
    with pytest.raises(ValueError, match="socbjax.checkpoint file"):
        sj.load(path)


def test_checkpoint_overwrite_failure_and_bad_input(tmp_path, monkeypatch):
    path = tmp_path / "ck.h5"
    sj.save_checkpoint(path, {"a": np.arange(3)}, {"step": 1})
    before = path.read_bytes()

    def boom(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(h5py.Group, "create_dataset", boom)
    with pytest.raises(KeyboardInterrupt):
        sj.save_checkpoint(path, {"a": np.arange(4)}, {"step": 2})
    monkeypatch.undo()
    assert path.read_bytes() == before and tmp_files(tmp_path) == []
    with pytest.raises(TypeError, match="dtype"):
        sj.save_checkpoint(path, {"s": np.array(["text"])}, {})
    with pytest.raises(TypeError, match="JSON"):
        sj.save_checkpoint(path, {}, {"x": {1, 2}})
    sj.save_checkpoint(path, {"a": np.arange(4)}, {"step": 2})
    arrays, meta = sj.load_checkpoint(path)
    assert meta == {"step": 2} and arrays["a"].tolist() == [0, 1, 2, 3]


def test_reads_files_of_the_first_0_1_0_layout(tmp_path):
    """Early 0.1.0 files: limit points as a JSON attribute, checkpoint datasets named by key."""
    result = make_result()
    path = sj.save(result, tmp_path / "run.h5")
    with h5py.File(path, "a") as f:
        del f["limit_points"]
        f.attrs["limit_points"] = json.dumps([dataclasses.asdict(p) for p in result.limit_points])
    assert_results_equal(result, sj.load(path))
    ck = tmp_path / "old.ckpt.h5"
    with h5py.File(ck, "w") as f:
        f.attrs.update({"format": "socbjax.checkpoint", "format_version": 1, "meta": json.dumps({"i": 1})})
        f.create_group("arrays")["carry|X"] = np.arange(3.0)
    arrays, meta = sj.load_checkpoint(ck)
    assert meta == {"i": 1} and list(arrays) == ["carry/X"] and arrays["carry/X"].tolist() == [0.0, 1.0, 2.0]


def test_reads_format_version_1_results(tmp_path):
    """Format 1 (socbjax 0.1): an integer status, no nodal couples, no leaving_segment."""
    result = make_result()
    path = sj.save(result, tmp_path / "run.h5")
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 1
        del f.attrs["result"]
        f.attrs["status"] = 6  # MAX_STEPS in socbjax 0.1
        del f["network/couples"], f["network/leaving_segment"]
    assert_results_equal(result, sj.load(path))
