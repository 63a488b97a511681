"""``socbjax fit`` on the shipped real AFM curves (the README's commands, run in-process),
a native CSV, the options it shares with ``socbjax simulate`` (``--supports``, ``--method``),
progress lines, the help text and errors that name an option of this command."""

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import socbjax as sj
import socbjax.cli

ROOT = Path(__file__).resolve().parents[1]
JPK = "force-save-example.jpk-force"
# The README's fit commands, verbatim ("$(socbjax examples NAME)" prints the shipped file's path).
README_FIT = ('socbjax fit "$(socbjax examples force-save-example.jpk-force)" --model unit-mesh --dim 2 '
              "--model-option mother_length=12 --free EI,branch_angle --out fit.json")
README_TOO_SMALL = ('socbjax fit "$(socbjax examples force-save-example.jpk-force)" --model unit-mesh --dim 2 '
                    "--free EI,branch_angle --out fit.json")
PYTHON_SPELLINGS = ("curve.select", "FitSettings", "model_options", "method='arclength'", "initial=")


def _argv(command: str, out: Path, *extra: str) -> list[str]:
    """``command`` as the argv of socbjax.cli.main: the shipped file for its
    ``$(socbjax examples NAME)``, ``--out`` redirected to ``out``."""
    words = shlex.split(command)[1:]
    for i, word in enumerate(words):
        found = re.fullmatch(r"\$\(socbjax examples (\S+)\)", word)
        if found:
            words[i] = str(sj.example_file(found.group(1)))
        if i and words[i - 1] == "--out":
            words[i] = str(out)
    return [*words, *extra]


def _error_line(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines and lines[-1].startswith("socbjax: error: "), lines
    return lines[-1]


def test_readme_fit_commands_are_the_ones_tested(tmp_path, capsys):
    """The README's fit section shows exactly the commands run below, and the error its
    first command prints, verbatim."""
    pytest.importorskip("afmformats")
    readme = (ROOT / "README.md").read_text()
    assert README_FIT in readme and README_TOO_SMALL in readme
    assert socbjax.cli.main(_argv(README_TOO_SMALL, tmp_path / "fit.json")) == 2
    assert f"# {_error_line(capsys)}" in readme


@pytest.mark.slow
def test_readme_fit_on_the_shipped_jpk_curve(tmp_path, capsys):
    """The README command: a 12-µm unit mesh (the curve's 3.4 µm of compression stay below the
    ~0.3 × 12 µm where the mesh's nodes would cross the surface) on the JPK example.  The fit
    converges; the nN forces of the soft sample need an EI of order 10⁴ pN·µm² (10⁵ × actin's),
    the model's post-buckling plateau sits near the Euler load 20.19 EI/L² of its clamped–pinned
    mother (an independent check of the fitted EI against the fitted forces), and the plateau
    cannot follow the sample's steady rise: the residuals change sign only a few times (model
    above the data after contact, below at the deepest compression) and the fit says so."""
    pytest.importorskip("afmformats")
    out = tmp_path / "fit.json"
    assert socbjax.cli.main(_argv(README_FIT, out)) == 0
    captured = capsys.readouterr()
    report = json.loads(out.read_text())
    EI, angle = report["values"]["EI"], report["values"]["branch_angle"]
    assert np.isfinite(EI) and 1e3 < EI < 1e5 and 0 < angle < 90
    assert np.isfinite(report["standard_errors"]["EI"]) and report["converged"]
    c, model, force = (np.asarray(report[k]) for k in ("compression", "model_force", "force"))
    plateau = np.median(model[c > 0.1 * c.max()])
    assert 1.0 < plateau / (20.19 * EI / 12.0**2) < 3.0
    assert 0.1 < report["r_squared"] < 0.5  # explains a part of the rise, not its shape
    residual = model - force
    assert residual[c > 0][0] > 0 > residual[-1]
    assert np.count_nonzero(np.diff(np.sign(residual[c > 0]))) <= 3  # noise would flip it every other point
    assert any("systematic" in w for w in report["warnings"])
    assert out.with_suffix(".png").stat().st_size > 20_000
    assert "EI" in captured.out and "R²" in captured.out
    progress = [line for line in captured.err.splitlines() if re.search(r"iteration \d+/30: loss", line)]
    assert progress and all("EI = " in line and "branch_angle = " in line for line in progress)
    assert not re.search(r"\b1 (iterations|points|parameters)\b", captured.err + captured.out)


def test_shipped_jpk_curve_fits_EI_of_a_12_um_mesh(tmp_path, capsys):
    """The README's model with EI alone (the default suite's end-to-end check on a real file:
    load, preprocess, size, start, fit, outputs).  Forces scale exactly with EI, so the start
    scaled to the data's force level already is the least-squares EI; the model's plateau
    sits near the Euler load 20.19 EI/L² of the 12-µm clamped–pinned mother."""
    pytest.importorskip("afmformats")
    out = tmp_path / "fit.json"
    argv = ["fit", str(sj.example_file(JPK)), "--dim", "2", "--model-option", "mother_length=12", "--out", str(out)]
    assert socbjax.cli.main(argv) == 0
    captured = capsys.readouterr()
    report = json.loads(out.read_text())
    EI = report["values"]["EI"]
    assert report["names"] == ["EI"] and report["units"]["EI"] == "pN·µm²" and 1e3 < EI < 1e5
    c, model, force = (np.asarray(report[k]) for k in ("compression", "model_force", "force"))
    assert 1.0 < np.median(model[c > 0.1 * c.max()]) / (20.19 * EI / 12.0**2) < 3.0
    # least squares in a pure scale: the residuals are orthogonal to the model's force
    assert abs(np.dot(model, model - force)) < 1e-6 * np.dot(model, model)
    assert report["r_squared"] > 0 and any("systematic" in w for w in report["warnings"])
    assert out.with_suffix(".png").stat().st_size > 20_000
    assert "scaled" in captured.err and "done after" in captured.err


@pytest.mark.parametrize("name", [JPK, "fmt-tab-fd_version_0.13.3.tab"])
def test_readme_command_on_a_too_small_mesh_names_the_fix(tmp_path, capsys, name):
    """Without mother_length the 1-µm mesh cannot be compressed by the curves' 3 µm: one
    line, exit 2, naming the cause and this command's options (the README's mother_length=12
    is the suggested size), before any compilation; nothing written."""
    pytest.importorskip("afmformats")
    command = README_TOO_SMALL.replace(JPK, name)
    assert socbjax.cli.main(_argv(command, tmp_path / "fit.json", "--quiet")) == 2
    line = _error_line(capsys)
    assert "probe–surface gap" in line and "--model-option mother_length=12" in line and "--max-compression" in line
    assert not any(s in line for s in PYTHON_SPELLINGS)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_surface_crossing_inside_the_data_is_named_with_its_fixes(tmp_path, capsys):
    """The issue's `--max-compression 0.9`: the 1-µm mesh's nodes cross the surface at
    ≈ 0.43 µm (no contact model), before the data's 0.9 µm.  The error says so and offers
    this command's fixes (crop below it, or a larger mesh), not a Python option (the old
    message sent users to `method='arclength'`, which crosses the surface too), and the
    suggested crop then runs."""
    pytest.importorskip("afmformats")
    argv = _argv(README_TOO_SMALL, tmp_path / "fit.json", "--quiet")
    assert socbjax.cli.main([*argv, "--max-compression", "0.9"]) == 2
    line = _error_line(capsys)
    assert "cross the surface" in line and "no contact model" in line
    crossing = float(re.search(r"at ([\d.]+) µm", line).group(1))
    assert 0.35 < crossing < 0.5  # the unit mesh's crossing at 70°: 0.43 × the mother
    crop = float(re.search(r"--max-compression ([\d.]+)", line).group(1))
    assert crop < crossing and "--model-option mother_length=" in line
    assert not any(s in line for s in PYTHON_SPELLINGS)
    # the suggested crop is evaluable: the fit runs and writes its outputs (on this soft
    # sample's rise the 2-parameter fit may end at its iteration budget: exit 1, not 2)
    assert socbjax.cli.main([*argv, "--max-compression", str(crop)]) in (0, 1)
    assert "socbjax: error" not in capsys.readouterr().err and (tmp_path / "fit.png").exists()


@pytest.mark.slow
def test_a_fold_at_the_start_names_method_arclength_which_then_fits(tmp_path, capsys):
    """A 40° unit mesh buckles at contact into a branch displacement control cannot follow
    (a fold at u ≈ 0): the error names `--method arclength`, which then fits."""
    pytest.importorskip("afmformats")
    argv = ["fit", str(sj.example_file("fmt-jpk-fd_spot3-0192.jpk-force")), "--dim", "2", "--model-option", "branch_angle=40",
            "--free", "EI", "--out", str(tmp_path / "fit.json"), "--quiet"]
    assert socbjax.cli.main(argv) == 2
    line = _error_line(capsys)
    assert "folds back" in line and "--method arclength" in line
    assert not any(s in line for s in PYTHON_SPELLINGS)
    assert socbjax.cli.main([*argv, "--method", "arclength"]) == 0
    report = json.loads((tmp_path / "fit.json").read_text())
    assert report["values"]["EI"] > 0 and report["r_squared"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("name", ["fmt-jpk-fd_spot3-0192.jpk-force", "fmt-igor-fd_SiN_FD_plot.ibw"])
def test_shallow_shipped_curves_fit_the_default_mesh(tmp_path, name):
    """The two shallow curves (0.2 µm and 10 nm of compression) fit with the 1-µm mesh as is:
    the start's EI is scaled to their nN forces (the default 0.071 is 10³ × too soft), the fit
    converges with R² > 0, and the shape misfit is reported."""
    pytest.importorskip("afmformats")
    out = tmp_path / "fit.json"
    argv = ["fit", str(sj.example_file(name)), "--dim", "2", "--free", "EI,branch_angle", "--out", str(out), "--quiet"]
    assert socbjax.cli.main(argv) == 0
    report = json.loads(out.read_text())
    assert 1.0 < report["values"]["EI"] < 1e4 and report["r_squared"] > 0.05
    assert any("systematic" in w for w in report["warnings"])
    assert out.with_suffix(".png").exists()


@pytest.mark.slow  # the default suite fits the shipped JPK curve on the command line
def test_native_csv_fit_with_supports_like_simulate(tmp_path):
    """A pinned–pinned column simulated, written as CSV, fitted with `--supports pinned,pinned`
    (the convention of `socbjax simulate column --supports`): EI recovered exactly, from the
    default start (scaled to the data's force level)."""
    model = sj.ColumnModel(4, supports=("pinned", "pinned"), dim=2)
    c = np.linspace(0.02, 0.25, 10)
    F = np.asarray(sj.compress(model.network({"EI": 0.9}), 0.25, at=c).force)
    path = tmp_path / "curve.csv"
    path.write_text("compression_um,force_pN\n" + "\n".join(f"{a},{b}" for a, b in zip(c, F)))
    out = tmp_path / "fit.json"
    assert socbjax.cli.main(["fit", str(path), "--model", "column", "--dim", "2", "--model-option", "n_nodes=4", "--supports",
                             "pinned,pinned", "--free", "EI", "--out", str(out), "--quiet"]) == 0
    report = json.loads(out.read_text())
    assert report["values"]["EI"] == pytest.approx(0.9, rel=1e-5)
    # Euler's pinned–pinned load π² EI/L² (L = 1 µm) is where the force curve starts
    assert F[0] == pytest.approx(np.pi**2 * 0.9, rel=0.05)


@pytest.mark.parametrize("value", ["clamped/pinned", "clamped", "clamped,glued", "pinned,pinned,free", ""])
def test_malformed_supports_is_one_line_naming_value_and_form(tmp_path, capsys, value):
    path = tmp_path / "curve.csv"
    path.write_text("compression_um,force_pN\n0.01,1\n0.02,2\n0.03,3\n0.04,4\n")
    assert socbjax.cli.main(["fit", str(path), "--model", "column", "--supports", value,
                             "--out", str(tmp_path / "f.json")]) == 2
    line = _error_line(capsys)
    assert repr(value) in line and "--supports clamped,pinned" in line and "clamped, pinned, free" in line


def test_supports_errors_point_to_the_right_option(tmp_path, capsys):
    path = tmp_path / "curve.csv"
    path.write_text("compression_um,force_pN\n0.01,1\n0.02,2\n0.03,3\n0.04,4\n")
    out = ["--out", str(tmp_path / "f.json")]
    assert socbjax.cli.main(["fit", str(path), "--model", "unit-mesh", "--supports", "pinned,pinned", *out]) == 2
    assert "--model column only" in _error_line(capsys)
    assert socbjax.cli.main(["fit", str(path), "--model", "column", "--model-option", "supports=pinned/pinned", *out]) == 2
    assert "--supports FIRST,LAST" in _error_line(capsys)
    assert socbjax.cli.main(["fit", str(path), "--model-option", "mother=2", *out]) == 2
    assert "unknown option(s) 'mother'" in (line := _error_line(capsys)) and "mother_length" in line


def test_fit_help_and_errors(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        socbjax.cli.main(["fit", "--help"])
    assert exc.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    for option in ("--free", "--fixed", "--model", "--out", "--max-compression", "--spring-constant", "--method",
                   "--supports", "arclength", "displacement"):
        assert option in text
    assert "default clamped,pinned" in text and "µm" in text and "pN" in text and "N/m" in text
    path = tmp_path / "curve.csv"
    path.write_text("compression_um,force_pN\n0.01,1\n0.02,2\n0.03,3\n0.04,4\n")
    for argv, words in ((["--model", "column", "--free", "EJ"], "unknown parameter 'EJ'"), (["--fixed", "EI"], "name=value"),
                        (["--max-compression", "-1"], "--max-compression must be a positive"),
                        (["--max-iterations", "0"], "--max-iterations must be"), (["--max-points", "2"], "--max-points")):
        assert socbjax.cli.main(["fit", str(path), *argv, "--out", str(tmp_path / "f.json")]) == 2  # a user error
        assert words in _error_line(capsys)
    assert not (tmp_path / "f.json").exists()


def test_fit_module_imports_no_jax():
    """`socbjax --help` stays fast: the fit command's parser needs only the standard library."""
    code = "import sys, socbjax._cli_fit; print(sorted(m for m in ('jax', 'numpy', 'socbjax._fit') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_dimension_options(tmp_path, capsys):
    """--dim (default 3, as every builder and socbjax simulate) and the older --model-option
    dim=... agree or the command says to give the dimension once."""
    path = tmp_path / "curve.csv"
    path.write_text("compression_um,force_pN\n0.01,1\n0.02,2\n0.03,3\n0.04,4\n")
    argv = ["fit", str(path), "--model", "column", "--out", str(tmp_path / "f.json")]
    assert socbjax.cli.main([*argv, "--dim", "2", "--model-option", "dim=3"]) == 2
    assert "give the dimension once" in _error_line(capsys)
    args = socbjax.cli.build_parser().parse_args([*argv, "--dim", "2", "--model-option", "dim=2"])
    assert socbjax._cli_fit._model_options(args)["dim"] == 2
    assert socbjax.cli.main(["fit", str(path), str(path), "--out", str(tmp_path / "f.json")]) == 2
    assert "names a JSON file" in _error_line(capsys) and not (tmp_path / "f.json").exists()
