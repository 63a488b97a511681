"""``socbjax fit``: a real JPK force curve end to end (load → preprocess → fit → JSON + PNG),
a native CSV, the help text and errors."""

import json
from pathlib import Path

import numpy as np
import pytest

import socbjax as sj
import socbjax.cli

DATA = Path(__file__).parent / "data" / "afm"


@pytest.mark.slow
def test_jpk_curve_end_to_end(tmp_path, capsys):
    """The JPK example (6 nN setpoint on a soft sample) through the unit mesh: the fit runs and
    writes its outputs; the elastica's force plateau cannot follow the data's steady rise,
    which the residuals show (see docs/fitting.md for what the value means)."""
    pytest.importorskip("afmformats")
    out = tmp_path / "fit.json"
    code = socbjax.cli.main([
        "fit", str(DATA / "force-save-example.jpk-force"), "--model", "unit-mesh", "--model-option", "mother_length=4",
        "--model-option", "segment_length=1", "--free", "EI", "--initial", "EI=100", "--max-compression", "1.5",
        "--max-points", "24", "--out", str(out), "--quiet",
    ])
    assert code == 0
    report = json.loads(out.read_text())
    assert report["names"] == ["EI"] and report["units"]["EI"] == "pN·µm²"
    assert report["values"]["EI"] > 1.0 and np.isfinite(report["standard_errors"]["EI"])
    assert out.with_suffix(".png").stat().st_size > 20_000
    residuals = np.asarray(report["residuals"])
    assert np.abs(residuals).max() > 0.2 * np.abs(report["force"]).max()  # systematic misfit, honestly shown
    assert "EI" in capsys.readouterr().out


def test_native_csv_fit_recovers_a_simulated_column(tmp_path):
    model = sj.ColumnModel(4)  # the command line's column: clamped–pinned
    c = np.linspace(0.02, 0.25, 10)
    F = np.asarray(sj.compress(model.network({"EI": 0.09}), 0.25, at=c).force)
    path = tmp_path / "curve.csv"
    path.write_text("compression_um,force_pN\n" + "\n".join(f"{a},{b}" for a, b in zip(c, F)))
    out = tmp_path / "fit.json"
    assert socbjax.cli.main(["fit", str(path), "--model", "column", "--model-option", "n_nodes=4", "--free", "EI",
                             "--out", str(out), "--quiet"]) == 0
    assert json.loads(out.read_text())["values"]["EI"] == pytest.approx(0.09, rel=1e-5)


def test_fit_help_and_errors(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        socbjax.cli.main(["fit", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for option in ("--free", "--fixed", "--model", "--out", "--max-compression", "--spring-constant"):
        assert option in text
    assert "µm" in text and "pN" in text and "N/m" in text
    path = tmp_path / "curve.csv"
    path.write_text("compression_um,force_pN\n0.01,1\n0.02,2\n0.03,3\n0.04,4\n")
    capsys.readouterr()
    for argv, words in ((["--model", "column", "--free", "EJ"], "unknown parameter 'EJ'"), (["--fixed", "EI"], "name=value")):
        assert socbjax.cli.main(["fit", str(path), *argv, "--out", str(tmp_path / "f.json")]) == 2  # a user error
        last = capsys.readouterr().err.strip().splitlines()[-1]
        assert last.startswith("socbjax: error: ") and words in last
    assert not (tmp_path / "f.json").exists()
