"""The command line and the demo job (quick settings)."""

import json
import subprocess
import sys

import socbjax.cli


def test_help_lists_the_demo(capsys):
    try:
        socbjax.cli.main(["--help"])
    except SystemExit as exc:
        assert exc.code == 0
    assert "demo" in capsys.readouterr().out


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
