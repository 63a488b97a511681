"""Smoke runs of the benchmarks with small settings (no timing is asserted: speed is the
benchmarks' business, not the tests').

The default suite runs one benchmark in-process (under a minute); ``pytest -m slow`` runs
every benchmark's ``--quick`` mode through ``run_all.py``, in its own process group so that a
timeout kills the benchmark children too.
"""

import importlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"


def _benchmark(name: str):
    if str(BENCHMARKS) not in sys.path:
        sys.path.insert(0, str(BENCHMARKS))
    return importlib.import_module(name)


def test_solve_gradient_cost_benchmark_runs_quick(tmp_path):
    """The gradient of a static solve: the script's own pass criterion (grad ≤ 3× the solve)
    and the exact identity EI ∂y/∂EI = −P ∂y/∂P that it records."""
    rc = _benchmark("solve_gradient_cost").main(["--quick", "--out", str(tmp_path)])
    report = json.loads((tmp_path / "solve_gradient_cost.json").read_text())
    (row,) = report["results"]
    assert row["identity_rel_error"] < 1e-8
    assert row["solve_s"] > 0 and row["grad_s"] > 0
    assert rc in (0, 1)  # 1 only if the timing criterion failed on a noisy machine; not asserted here


def _run_in_own_group(cmd, timeout):
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # the benchmark children live in the same group
        out, _ = proc.communicate()
        pytest.fail(f"benchmarks timed out after {timeout} s:\n{out[-3000:]}")
    return proc.returncode, out


@pytest.mark.slow
def test_all_benchmarks_run_quick(tmp_path):
    rc, out = _run_in_own_group(
        [sys.executable, str(BENCHMARKS / "run_all.py"), "--quick", "--out", str(tmp_path)], timeout=1800)
    assert rc == 0, out[-6000:]
    for name in ("fig4a_cantilever_error", "fig4b_nodes_for_accuracy", "fig5c_buckling_error", "solve_timing", "scaling",
                 "elastica_comparison", "ensemble_throughput"):
        assert json.loads((tmp_path / f"{name}.json").read_text())
        assert (tmp_path / f"{name}.png").stat().st_size > 5_000
    versus = json.loads((tmp_path / "outcrop_compression.json").read_text())["versus_dense"]
    assert all(v["same_steps"] and v["max_force_difference_rel"] < 1e-9 for v in versus)  # sparse = dense path
