"""The command line and the demo job (quick settings)."""

import json
import os
import stat
import subprocess
import sys

import numpy as np
import pytest

import socbjax.cli


def test_help_lists_the_demo(capsys):
    try:
        socbjax.cli.main(["--help"])
    except SystemExit as exc:
        assert exc.code == 0
    assert "demo" in capsys.readouterr().out


@pytest.mark.slow
def test_demo_quick_writes_table_and_figure(tmp_path):
    assert socbjax.cli.main(["demo", "--quick", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "demo.json").read_text())
    assert (tmp_path / "demo.png").stat().st_size > 10_000
    two_node = [r for r in report["cantilever"] if r["model"] == "socb" and r["nodes"] == 2][0]
    assert two_node["rel_error"] < 1e-3
    assert all(r["socb_5_error"] < 5e-4 for r in report["buckling"])


def test_python_dash_m_entry_point():
    out = subprocess.run([sys.executable, "-m", "socbjax", "--help"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "demo" in out.stdout


_NO_JAX = """
import sys, socbjax.cli
try:
    code = socbjax.cli.main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
print(code, sorted(m for m in sys.modules if m.split(".")[0] in ("jax", "jaxlib")))
"""


@pytest.mark.parametrize("argv, code", [
    (["--help"], 0), (["simulate", "--help"], 0), (["fit", "--help"], 0), (["simulate", "nope", "--out", "x.h5"], 2),
    (["simulate", "unit-mesh", "--dim", "5", "--out", "x.h5"], 2),
    (["simulate", "column", "--supports", "pinned/free", "--out", "x.h5"], 2),
    (["simulate", "column", "--max-step", "-1", "--out", "x.h5"], 2), (["plot", "x.h5", "--steps", "1,x"], 2),
    (["fit", "x.csv"], 2), (["fit", "x.csv", "y.csv", "--out", "fit.json"], 2), (["fit", "x.csv", "--compare", "column"], 2),
    (["fit", "x.csv", "--dim", "4", "--out", "fit.json"], 2),
])
def test_help_and_argument_errors_do_not_import_jax(tmp_path, argv, code):
    """--help and argument errors answer before JAX (seconds to import) is loaded."""
    out = subprocess.run([sys.executable, "-c", _NO_JAX, *argv], capture_output=True, text=True, timeout=120,
                         cwd=tmp_path)
    assert out.stdout.strip().splitlines()[-1] == f"{code} []", (out.stdout[-2000:], out.stderr[-2000:])


def test_package_import_is_light_and_still_float64():
    code = ("import sys, socbjax; light = 'jax' not in sys.modules; "
            "import jax.numpy as jnp; from socbjax import solve; "
            "print(light, jnp.zeros(2).dtype, socbjax.__version__ == socbjax._version.__version__, callable(solve), "
            "socbjax.testing.elastica_cantilever.__name__, sorted(set(socbjax.__all__) - set(dir(socbjax))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.stdout.split() == ["True", "float64", "True", "True", "elastica_cantilever", "[]"], out.stderr[-2000:]


def test_python_dash_m_help_imports_no_jax():
    out = subprocess.run([sys.executable, "-X", "importtime", "-m", "socbjax", "--help"], capture_output=True,
                         text=True, timeout=120)
    modules = [line.rsplit("|", 1)[-1].strip() for line in out.stderr.splitlines() if line.startswith("import time:")]
    assert out.returncode == 0 and "socbjax.cli" in modules, out.stderr[-2000:]
    assert not [m for m in modules if m.split(".")[0] in ("jax", "jaxlib")]


def test_every_network_and_fit_model_defaults_to_3d():
    """One default dimension (3) for socbjax simulate, socbjax fit and the builders and fit
    models behind them; planar problems are opt-in (--dim 2)."""
    parser = socbjax.cli.build_parser()
    for network in ("unit-mesh", "outcrop", "column"):
        args = parser.parse_args(["simulate", network, "--out", "x.h5"])
        socbjax.cli._check_simulate(args)
        assert args.dim == 3
    assert parser.parse_args(["simulate", "column", "--dim", "2", "--out", "x.h5"]).dim == 2
    args = parser.parse_args(["fit", "x.csv", "--out", "fit.json"])
    assert args.dim is None and "dim" not in socbjax._cli_fit._model_options(args)  # the models' own default: 3
    assert socbjax._cli_fit._model_options(parser.parse_args(["fit", "x.csv", "--dim", "2", "--out", "f.json"]))["dim"] == 2
    import inspect

    for target in (socbjax.ColumnModel.__init__, socbjax.UnitMeshModel.__init__, socbjax.column,
                   socbjax.unit_dendritic_mesh, socbjax.dendritic_outcrop, socbjax.cantilever):
        assert inspect.signature(target).parameters["dim"].default == 3, target
    assert socbjax.OutcropModel(generations=1, gap=2.0).base.dim == 3


def test_simulate_twists_actin_networks_by_default_and_records_GJ():
    parser = socbjax.cli.build_parser()

    def built(*argv):
        net, params, _ = socbjax.cli._build(parser.parse_args(["simulate", *argv, "--out", "x.h5"]))
        return net.twisting, params["GJ"]

    assert built("unit-mesh") == (True, socbjax.ACTIN_GJ) and built("outcrop", "--generations", "2")[0]
    assert built("unit-mesh", "--GJ", "none") == (False, None) and built("unit-mesh", "--GJ", "0.02") == (True, 0.02)
    assert built("column") == (False, None) and built("column", "--GJ", "0.5") == (True, 0.5)


def test_column_supports_default_and_separator_match_fit():
    args = socbjax.cli._parser().parse_args(["simulate", "column", "--out", "x.h5"])
    assert args.supports == "clamped,pinned"
    assert socbjax.cli._supports(" clamped , free ") == ("clamped", "free")
    assert socbjax.cli._SUPPORT_KINDS == socbjax.SUPPORTS  # the solver's names, without importing it
    assert [socbjax.cli.plural(n, "junction") for n in (0, 1, 2)] == ["0 junctions", "1 junction", "2 junctions"]


def test_simulate_help_documents_units(capsys):
    try:
        socbjax.cli.main(["simulate", "--help"])
    except SystemExit as exc:
        assert exc.code == 0
    text = capsys.readouterr().out
    for option in ("--displacement", "--EI", "--branch-angle", "--gap", "--perturbation", "--resume", "--checkpoint-every"):
        assert option in text
    assert "µm" in text and "pN·µm²" in text and "pN" in text


def test_simulate_column_then_plot(tmp_path, capsys):
    out = tmp_path / "column.h5"
    code = socbjax.cli.main(["simulate", "column", "--dim", "2", "--nodes", "5", "--displacement", "0.2", "--out", str(out), "--quiet"])
    assert code == 0 and out.exists()
    captured = capsys.readouterr()
    assert "completed" in captured.out and "5 nodes, 4 segments, 0 junctions; probe travel 0.2 µm and back" in captured.err
    result = socbjax.load(out)
    assert result.completed and result.parameters["network"] == "column" and (result.phase == 2).any()
    assert result.parameters["supports"] == ["clamped", "pinned"]  # the default, as fit's
    assert not (tmp_path / "column.h5.ckpt.h5").exists()  # removed after a completed run
    assert socbjax.cli.main(["plot", str(out), "--out", str(tmp_path / "figs")]) == 0
    pngs = sorted(p.name for p in (tmp_path / "figs").glob("*.png"))
    assert pngs == ["end_forces.png", "force_curve.png", "snapshots.png", "strand_forces.png"]
    assert all((tmp_path / "figs" / p).stat().st_size > 5_000 for p in pngs)


def test_simulate_with_contact_records_the_obstacles_and_contact_outputs(tmp_path, capsys):
    out = tmp_path / "column.h5"
    argv = ["simulate", "column", "--dim", "2", "--nodes", "5", "--displacement", "0.2", "--contact", "--diameter", "0.01",
            "--out", str(out), "--quiet"]
    assert socbjax.cli.main(argv) == 0
    result = socbjax.load(out)
    contact = result.parameters["contact"]
    assert contact["diameter_um"] == 0.01 and contact["surfaces"] and contact["self_contact"]
    assert result.contact_points.shape[1] >= 4 * 2  # a slot per segment for the probe face and the substrate, + pairs
    assert np.all(result.min_gap > -0.01 * 0.01)  # nothing crosses the probe face or the substrate


# ------------------------------------------------------------------ errors and output paths
def _user_error(capsys, argv) -> str:
    """Run the command line; it must fail with exit 2 and one line ``socbjax: error: ...``."""
    code = socbjax.cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, err
    assert err and err[-1].startswith("socbjax: error: ") and not any("Traceback" in line for line in err), err
    return err[-1]


@pytest.mark.parametrize("argv, words", [
    (["simulate", "column", "--supports", "pinned,glued", "--out", "{tmp}/c.h5"], ["glued"]),
    (["simulate", "column", "--supports", "clamped/pinned", "--out", "{tmp}/c.h5"],
     ["--supports", "'clamped/pinned'", "clamped,pinned"]),
    (["simulate", "column", "--nodes", "1", "--out", "{tmp}/c.h5"], ["n_nodes", "1"]),
    (["simulate", "column", "--out", "{tmp}/missing/c.h5"], ["--out", "does not exist"]),
    (["simulate", "column", "--out", "{tmp}"], ["--out", "folder"]),
    (["simulate", "column", "--displacement", "5", "--out", "{tmp}/c.h5"], ["gap"]),
    (["simulate", "unit-mesh", "--GJ", "-0.1", "--out", "{tmp}/c.h5"], ["--GJ", "'-0.1'", "'none'"]),
    (["simulate", "column", "--contact", "--diameter", "-1", "--out", "{tmp}/c.h5"], ["diameter", "-1"]),
    (["plot", "{tmp}/nothing.h5"], ["nothing.h5"]),
    (["plot", "{tmp}/not-hdf5.h5"], ["not-hdf5.h5", "not a valid socbjax result"]),
    (["plot", "{tmp}/not-hdf5.h5", "--steps", "1,x"], ["--steps"]),
    (["fit", "{tmp}/binary.csv", "--out", "{tmp}/fit.json"], ["binary.csv", "binary"]),
    (["fit", "{tmp}/curve.csv", "--out", "{tmp}/fit.json", "--fixed", "EI"], ["--fixed", "name=value"]),
    (["fit", "{tmp}/curve.csv", "--out", "{tmp}/missing/fit.json"], ["--out", "does not exist"]),
])
def test_user_errors_are_one_line_with_exit_2(tmp_path, capsys, argv, words):
    (tmp_path / "not-hdf5.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(200))
    (tmp_path / "binary.csv").write_bytes(bytes(range(256)) * 4)
    (tmp_path / "curve.csv").write_text("compression_um,force_pN\n0,0\n0.1,1\n0.2,2\n")
    line = _user_error(capsys, [a.replace("{tmp}", str(tmp_path)) for a in argv])
    for word in words:
        assert word in line, line
    assert not list(tmp_path.glob("*.tmp")) and not list(tmp_path.glob(".*.tmp"))


def test_debug_shows_the_traceback(tmp_path):
    (tmp_path / "x.h5").write_bytes(b"junk")
    with pytest.raises(ValueError, match="not a valid socbjax result"):
        socbjax.cli.main(["plot", str(tmp_path / "x.h5"), "--debug"])
    with pytest.raises(ValueError, match="not a valid socbjax result"):
        socbjax.cli.main(["--debug", "plot", str(tmp_path / "x.h5")])


def test_outputs_that_are_not_regular_files_are_refused_untouched(tmp_path, capsys):
    fifo = tmp_path / "run.h5"
    os.mkfifo(fifo)
    line = _user_error(capsys, ["simulate", "column", "--out", str(fifo), "--quiet"])
    assert "FIFO" in line and stat.S_ISFIFO(os.stat(fifo).st_mode)  # still the FIFO, not replaced


def test_another_runs_checkpoint_is_never_discarded(tmp_path, capsys):
    out = tmp_path / "run.h5"
    checkpoint = tmp_path / "run.h5.ckpt.h5"
    checkpoint.write_bytes(b"someone else's checkpoint")
    line = _user_error(capsys, ["simulate", "column", "--out", str(out), "--quiet"])
    assert "--resume" in line and checkpoint.read_bytes() == b"someone else's checkpoint" and not out.exists()


def test_a_second_run_on_the_same_output_refuses(tmp_path, capsys):
    out = tmp_path / "run.h5"
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from socbjax import output_lock\n"
                               f"with output_lock({str(out)!r}):\n print('locked', flush=True); time.sleep(60)"],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        line = _user_error(capsys, ["simulate", "column", "--dim", "2", "--nodes", "3", "--out", str(out), "--quiet"])
        assert "another socbjax run" in line and str(holder.pid) in line and not out.exists()
    finally:
        holder.kill()
        holder.wait()


@pytest.mark.slow  # suite time; in the default suite: full disk and size limits of writes: tests/test_io.py
def test_a_full_disk_gives_one_line_and_keeps_the_previous_output(tmp_path):
    """With a file-size limit below the result's size (as on a full disk) the run ends with
    a one-line OSError and exit 2 — no signal, no traceback — the previous output intact."""
    out = tmp_path / "run.h5"
    out.write_bytes(b"the previous output")
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_FSIZE, (12_000, 12_000)); import socbjax.cli; "
            "sys.exit(socbjax.cli.main(sys.argv[1:]))")
    env = {**os.environ, "SOCBJAX_CACHE_DIR": "off"}
    proc = subprocess.run([sys.executable, "-c", code, "simulate", "column", "--dim", "2", "--nodes", "3", "--displacement",
                           "0.1", "--no-unload", "--out", str(out), "--quiet"], capture_output=True, text=True, env=env,
                          timeout=300)
    last = proc.stderr.strip().splitlines()[-1]
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert last.startswith("socbjax: error: ") and str(out) in last and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert out.read_bytes() == b"the previous output"
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_examples_lists_the_shipped_curves_and_prints_one_path(capsys):
    assert socbjax.cli.main(["examples"]) == 0
    listing = capsys.readouterr().out
    for name, path in socbjax.example_files().items():
        assert name in listing and str(path) in listing
    name = "fmt-igor-fd_SiN_FD_plot.ibw"
    assert socbjax.cli.main(["examples", name]) == 0
    assert capsys.readouterr().out.strip() == str(socbjax.example_file(name))
    assert socbjax.cli.main(["examples", "nope"]) == 2
    assert "choose one of force-save-example.jpk-force" in capsys.readouterr().err
