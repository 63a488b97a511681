"""The command line and the demo job (quick settings)."""

import json
import subprocess
import sys

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
    assert "completed" in capsys.readouterr().out
    result = socbjax.load(out)
    assert result.completed and result.parameters["network"] == "column" and (result.phase == 2).any()
    assert not (tmp_path / "column.h5.ckpt.h5").exists()  # removed after a completed run
    assert socbjax.cli.main(["plot", str(out), "--out", str(tmp_path / "figs")]) == 0
    pngs = sorted(p.name for p in (tmp_path / "figs").glob("*.png"))
    assert pngs == ["end_forces.png", "force_curve.png", "snapshots.png", "strand_forces.png"]
    assert all((tmp_path / "figs" / p).stat().st_size > 5_000 for p in pngs)
