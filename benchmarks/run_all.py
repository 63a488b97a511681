"""Run every socbjax benchmark, each in its own Python process (so that compile times are
measured from a cold start and one crash does not stop the others).

Run:  PYTHONPATH=. python benchmarks/run_all.py [--quick] [--out DIR] [--only NAME ...]
Exit status is non-zero if any benchmark fails (non-zero exit or a timeout).  ``pytest -m slow``
runs ``run_all.py --quick`` as a smoke test (in its own process group, killed on timeout).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
SCRIPTS = [
    "fig4a_cantilever_error",
    "fig4b_nodes_for_accuracy",
    "fig5c_buckling_error",
    "solve_timing",
    "linear_timing",
    "scaling",
    "outcrop_compression",
    "ensemble_throughput",
    "gradient_cost",
    "solve_gradient_cost",
    "fit_recovery",
    "lawn_throughput",
    "thermal_compression",
    "thermal_compression_3d",
    "twist_unit_mesh",
    "twist_outcrop",
    "contact_planar",
    "contact_outcrop",
    "contact_cost",
    "peers/elastica_comparison",  # PyElastica columns only with the extra socbjax[peers]
]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="Run all socbjax benchmarks.")
    p.add_argument("--quick", action="store_true", help="small settings (smoke test)")
    p.add_argument("--out", type=Path, default=HERE / "results", help="output folder")
    p.add_argument("--only", nargs="*", choices=SCRIPTS, help="run only these benchmarks")
    p.add_argument("--timeout", type=float, default=None, help="seconds per benchmark (default none)")
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH", "")]))
    summary = []
    for name in args.only or SCRIPTS:
        cmd = [sys.executable, str(HERE / f"{name}.py"), "--out", str(args.out)] + (["--quick"] if args.quick else [])
        print(f"\n=== {name} {'(quick)' if args.quick else ''}", flush=True)
        t0 = time.perf_counter()
        try:
            rc = subprocess.run(cmd, env=env, cwd=ROOT, timeout=args.timeout).returncode
        except subprocess.TimeoutExpired:
            rc = "timeout"
        summary.append((name, rc, time.perf_counter() - t0))

    print("\nbenchmark                   status   seconds")
    for name, rc, sec in summary:
        print(f"{name:<26}  {'ok' if rc == 0 else f'FAIL({rc})':<7}  {sec:7.1f}")
    return 0 if all(rc == 0 for _, rc, _ in summary) else 1


if __name__ == "__main__":
    sys.exit(main())
