"""Smoke run of every benchmark with small settings (no timing is asserted)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_all_benchmarks_run_quick(tmp_path):
    out = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "run_all.py"), "--quick", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=900,
        cwd=ROOT,
    )
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    for name in ("fig4a_cantilever_error", "fig4b_nodes_for_accuracy", "fig5c_buckling_error", "solve_timing", "scaling",
                 "elastica_comparison", "ensemble_throughput"):
        assert json.loads((tmp_path / f"{name}.json").read_text())
        assert (tmp_path / f"{name}.png").stat().st_size > 5_000
    versus = json.loads((tmp_path / "outcrop_compression.json").read_text())["versus_dense"]
    assert all(v["same_steps"] and v["max_force_difference_rel"] < 1e-9 for v in versus)  # sparse = dense path
