"""HDF5 save/load of a CompressionResult and of checkpoints: exact round trips, atomic
writes that leave no partial or temporary files, and clear errors for foreign files."""

import contextlib
import dataclasses
import errno
import fcntl
import json
import os
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

import h5py
import jax.numpy as jnp
import numpy as np
import pytest

import socbjax as sj
from socbjax import CompressionResult, LimitPoint, atomic_path, check_output_path, output_lock


def make_result(dim=3, K=7, N=4, E=1, seed=0, twisting=True):
    """A hand-built result on a 4-node column (2D: crimped; 3D: twisting and curved): K steps,
    N nodes, S = N − 1 segments."""
    rng = np.random.default_rng(seed)
    net = (sj.column(N, dim=dim, GJ=0.5, natural_curvature=[0.3, -0.2, 0.1]) if dim == 3 and twisting  # curved
           else sj.column(N, dim=dim) if dim == 3 else sj.crimped_fibre(N, length=1.0, wavelength=0.8, crimp_angle=20.0))
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
        twists=rng.normal(size=(K, N if dim == 3 and twisting else 0)),
        end_nodes=np.arange(E, dtype=np.int32),
        end_forces=rng.normal(size=(K, E)),
        iterations=rng.integers(1, 9, size=K).astype(np.int32),
        reactions=rng.normal(size=(K, N, dim)),
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
            for name in ("positions", "tangents", "lengths", "EI", "loads", "couples", "natural_curvature", "GJ",
                         "directors"):
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
        # Strings are fixed-length UTF-8 (h5py reads them as bytes): kept in checksummed
        # headers, out of HDF5's unchecksummed global heap.
        text = {name: f.attrs[name].decode() for name in ("format", "socbjax_version", "created", "result")}
        assert text["format"] == "socbjax.compression" and text["socbjax_version"] == sj.__version__
        assert f.attrs["format_version"] == 6 and text["result"] == "max_steps"
        assert f["path/reactions"].shape == (7, 4, 3) and f["units"].attrs["reactions"].decode() == "pN"
        assert f["path/twists"].shape == (7, 4) and f["units"].attrs["twists"].decode() == "rad"
        assert f["units"].attrs["displacement"].decode() == "µm" and f["units"].attrs["moments"].decode() == "pN·µm"
        assert f["path/force"].attrs["units"].decode() == "pN"
        assert f["network"].attrs["dim"] == 3
        assert list(f["limit_points/kind"].asstr()[()]) == ["force_maximum", "bifurcation"]
        strings = [f.attrs.get_id(n).get_type() for n in f.attrs] + [f["limit_points/kind"].id.get_type()]
        assert all(not t.is_variable_str() for t in strings if isinstance(t, h5py.h5t.TypeStringID))
        assert f.id.get_create_plist().get_version()[0] >= 2  # superblock with a checksum


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
        f.attrs["format_version"] = 7
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
        assert f.attrs["format"].decode() == "socbjax.checkpoint" and f.attrs["format_version"] == 6
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


def test_reads_format_version_2_results_as_naturally_straight(tmp_path):
    """Format 2 had no natural curvature: its networks are straight."""
    result = make_result(dim=3, twisting=False)
    path = sj.save(result, tmp_path / "run.h5")
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 2
        del f["network/natural_curvature"], f["network/GJ"], f["network/twisting"], f["network/directors"]
        del f["path/twists"]
    assert_results_equal(result, sj.load(path))
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 3
    with pytest.raises(ValueError, match=r"lacks \['natural_curvature', 'GJ', 'directors', 'twisting'\]"):
        sj.load(path)


def test_reads_format_version_3_results_without_frame_angles(tmp_path):
    """Format 3 stored twisting networks but not the path's frame angles ψ: the result loads,
    and only CompressionResult.solution (which needs ψ) says what is missing."""
    result = make_result()
    path = sj.save(result, tmp_path / "run.h5")
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 3
        del f["path/twists"]
    back = sj.load(path)
    assert back.twists.shape == (7, 0) and not back.records_frame_angles and result.records_frame_angles
    np.testing.assert_array_equal(back.positions, result.positions)
    with pytest.raises(ValueError, match="format 3 or older"):
        back.solution(1)
    with pytest.raises(ValueError, match="re-run the compression"):  # curved: its curves need ψ
        sj.plot_snapshots(back)
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 4
    with pytest.raises(ValueError, match=r"lacks \['twists'\]"):
        sj.load(path)
    path = sj.save(result, tmp_path / "wrong.h5")
    with h5py.File(path, "a") as f:  # a twisting network's angles must be [K, N]
        del f["path/twists"]
        f["path/twists"] = np.zeros((7, 3))
    with pytest.raises(ValueError, match=r"twists has shape \(7, 3\)"):
        sj.load(path)


def test_reads_format_version_5_results_without_reactions(tmp_path):
    """Files before format 6 have no per-step support reactions: they load with NaN there (not
    recorded), and a format-6 file without them is refused."""
    result = make_result()
    path = sj.save(result, tmp_path / "v5.h5")
    with h5py.File(path, "a") as f:
        del f["path/reactions"]
        f.attrs["format_version"] = 5
    back = sj.load(path)
    assert back.reactions.shape == (7, 4, 3) and np.isnan(back.reactions).all()
    np.testing.assert_array_equal(back.force, result.force)
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 6
    with pytest.raises(ValueError, match=r"reactions"):
        sj.load(path)


def test_reads_format_version_1_results(tmp_path):
    """Format 1 (socbjax 0.1): an integer status, no nodal couples, no leaving_segment."""
    result = make_result(twisting=False)
    path = sj.save(result, tmp_path / "run.h5")
    with h5py.File(path, "a") as f:
        f.attrs["format_version"] = 1
        del f.attrs["result"]
        f.attrs["status"] = 6  # MAX_STEPS in socbjax 0.1
        del f["network/couples"], f["network/leaving_segment"], f["network/natural_curvature"], f["network/GJ"]
        del f["network/twisting"], f["network/directors"], f["path/twists"]
    assert_results_equal(result, sj.load(path))


# ----------------------------------------------------------------------------- output targets and failing disks

REPO = Path(__file__).resolve().parents[1]


def run_child(code: str, *args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], check=False, capture_output=True, text=True, cwd=REPO,
                          timeout=300)


def writers(result):
    return {
        "save": lambda p: sj.save(result, p),
        "save_checkpoint": lambda p: sj.save_checkpoint(p, {"a": np.arange(3)}, {}),
        "atomic_path": lambda p: atomic_path(p, lambda tmp: tmp.write_text("x")),
        "check_output_path": lambda p: check_output_path(p, "--out"),
    }


def test_special_targets_refused_and_left_alone(tmp_path):
    fifo, folder, link = tmp_path / "fifo.h5", tmp_path / "folder.h5", tmp_path / "link.h5"
    os.mkfifo(fifo)
    folder.mkdir()
    link.symlink_to(fifo)
    for name, write in writers(make_result()).items():
        for target, words in ((fifo, "is a FIFO"), (link, "is a FIFO"), (folder, "is a folder; give a file name")):
            with pytest.raises(ValueError, match=words) as info:
                write(target)
            assert str(target) in str(info.value)
            assert str(info.value).startswith("--out " if name == "check_output_path" else f"{name.replace('atomic_', 'output ')} ")
    assert stat.S_ISFIFO(os.stat(fifo).st_mode) and link.is_symlink() and folder.is_dir() and not any(folder.iterdir())
    assert sorted(os.listdir(tmp_path)) == ["fifo.h5", "folder.h5", "link.h5"]  # no temporary files


def test_device_node_target_refused(tmp_path):
    node = tmp_path / "null"
    try:  # a private node with /dev/null's numbers: never the real /dev
        os.mknod(node, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    except (PermissionError, OSError) as err:
        pytest.skip(f"cannot create a device node here ({err})")
    for write in writers(make_result()).values():
        with pytest.raises(ValueError, match="character device"):
            write(node)
    assert stat.S_ISCHR(os.stat(node).st_mode)


def test_check_output_path_messages(tmp_path):
    target = tmp_path / "run.h5"
    assert check_output_path(str(target), "--out") == target
    assert os.listdir(tmp_path) == []  # the probe file is removed, the target not created
    with pytest.raises(FileNotFoundError) as info:
        check_output_path(tmp_path / "missing" / "run.h5", "--out")
    assert str(info.value).startswith(f"--out {tmp_path / 'missing' / 'run.h5'}") and "mkdir" in str(info.value)
    assert info.value.errno == errno.ENOENT
    (tmp_path / "plain").write_text("")
    with pytest.raises(ValueError, match=r"^--out .*plain is not a folder"):
        check_output_path(tmp_path / "plain" / "run.h5", "--out")
    with pytest.raises(ValueError, match=r"^--out .* is a folder; give a file name"):
        check_output_path(tmp_path, "--out")


def test_unwritable_folder_refused_before_any_work(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(h5py.Group, "create_dataset", lambda *a, **k: calls.append(a))

    def read_only(*args, **kwargs):  # what a read-only mount answers (chmod cannot stop root)
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    for name, write in writers(make_result()).items():
        with pytest.raises(OSError) as info:
            write(tmp_path / "run.h5")
        if name == "check_output_path":
            assert str(info.value).startswith("--out ")
        assert isinstance(info.value, PermissionError) and str(tmp_path / "run.h5") in str(info.value)
        assert "writ" in str(info.value)
    assert calls == [] and os.listdir(tmp_path) == []


def test_read_only_folder(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        try:
            (folder / "probe").write_text("x")
        except PermissionError:
            pass
        else:
            pytest.skip("running as root: the folder's mode does not stop writes")
        with pytest.raises(PermissionError, match=r"^--out .*choose a writable folder"):
            check_output_path(folder / "run.h5", "--out")
        with pytest.raises(PermissionError, match="ro"):
            sj.save(make_result(), folder / "run.h5")
    finally:
        folder.chmod(0o755)


def test_io_error_while_writing_names_target_and_keeps_previous(tmp_path, monkeypatch):
    path = sj.save(make_result(seed=1), tmp_path / "run.h5")
    before = path.read_bytes()

    def failing_fsync(fd):
        raise OSError(errno.EIO, "Input/output error")

    monkeypatch.setattr(os, "fsync", failing_fsync)
    with pytest.raises(OSError) as info:
        sj.save(make_result(seed=2), path)
    assert info.value.errno == errno.EIO and f"cannot write {path}" in str(info.value)
    with pytest.raises(OSError, match="No space left") as info:
        atomic_path(path, lambda tmp: (_ for _ in ()).throw(OSError(errno.ENOSPC, "No space left on device")))
    assert str(path) in str(info.value) and "free disk space" in str(info.value)
    monkeypatch.undo()
    assert path.read_bytes() == before and tmp_files(tmp_path) == []


DISK_FULL_CHILD = r"""
import json, resource, signal, sys
import numpy as np
import socbjax as sj
big, run, ck, limit = sys.argv[1:5]
result = sj.load(big)
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write then fails with EFBIG instead of killing the process
resource.setrlimit(resource.RLIMIT_FSIZE, (int(limit), int(limit)))
out = {}
for name, save in [("result", lambda: sj.save(result, run)),
                   ("checkpoint", lambda: sj.save_checkpoint(ck, {"x": np.random.default_rng(0).normal(size=10**5)},
                                                             {"i": 2}))]:
    try:
        save()
        out[name] = "saved"
    except OSError as err:
        out[name] = [err.errno, str(err)]
print(json.dumps(out))
"""


def test_file_size_limit_during_writes_is_a_clean_oserror(tmp_path):
    """A disk filling mid-write (here RLIMIT_FSIZE) once crashed the process inside h5py."""
    folder = tmp_path / "out"
    folder.mkdir()
    big = sj.save(make_result(K=400, N=12), tmp_path / "big.h5")
    run, ck = sj.save(make_result(seed=3), folder / "run.h5"), sj.save_checkpoint(folder / "ck.h5", {"x": np.arange(3)}, {})
    before = {p: p.read_bytes() for p in (run, ck)}
    limit = 64 * 1024
    assert big.stat().st_size > limit
    child = run_child(DISK_FULL_CHILD, big, run, ck, limit)
    assert child.returncode == 0, (child.returncode, child.stderr[-2000:])  # < 0 would be a signal (SIGSEGV, SIGXFSZ)
    out = json.loads(child.stdout.strip().splitlines()[-1])
    for name, path in (("result", run), ("checkpoint", ck)):
        code, message = out[name]
        assert code == errno.EFBIG and f"cannot write {path}" in message and "unchanged" in message, message
        assert path.read_bytes() == before[path]
    assert sorted(os.listdir(folder)) == ["ck.h5", "run.h5"]  # no .tmp left


LOCK_CHILD = r"""
import json, sys
from socbjax import output_lock
try:
    with output_lock(sys.argv[1]):
        print(json.dumps(["acquired", ""]))
except OSError as err:
    print(json.dumps([err.errno, str(err)]))
"""


def test_output_lock_excludes_a_second_process(tmp_path):
    target, lock = tmp_path / "run.h5", tmp_path / ".run.h5.lock"
    with output_lock(target) as held:
        assert held == target and lock.read_text().strip() == str(os.getpid())
        child = run_child(LOCK_CHILD, target)
        assert child.returncode == 0, child.stderr[-2000:]
        code, message = json.loads(child.stdout.strip().splitlines()[-1])
        assert code == errno.EBUSY and f"another socbjax run is writing this output (pid {os.getpid()})" in message
        assert str(target) in message
        with pytest.raises(OSError) as info, output_lock(target):  # flock: another open file, same process
            pass
        assert info.value.errno == errno.EBUSY
    assert not lock.exists()
    with output_lock(target):  # free again once released
        assert lock.exists()
    assert not lock.exists()


def test_output_lock_survives_the_release_race(tmp_path, monkeypatch):
    """A contender opens the lock file, the holder then removes it and releases, and only then
    does the contender's flock succeed, on a file no longer at the path: it must notice and
    start over, else a third process would lock a new file and two would write at once."""
    target, holder = tmp_path / "run.h5", contextlib.ExitStack()
    holder.enter_context(output_lock(target))
    real_flock, calls = fcntl.flock, []

    def flock_after_release(fd, operation):
        if not calls:
            holder.close()  # between the contender's open and its flock
        calls.append(fd)
        return real_flock(fd, operation)

    monkeypatch.setattr(fcntl, "flock", flock_after_release)
    with output_lock(target):
        assert len(calls) == 2  # the first lock was on the removed file: retried on a new one
        with pytest.raises(OSError) as info, output_lock(target):
            pass
        assert info.value.errno == errno.EBUSY
    assert not (tmp_path / ".run.h5.lock").exists()


def test_load_never_turns_interrupts_into_value_errors(tmp_path, monkeypatch):
    path = sj.save(make_result(), tmp_path / "run.h5")

    def interrupted(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(h5py.Dataset, "__getitem__", interrupted)
    with pytest.raises(KeyboardInterrupt):
        sj.load(path)

