"""Outcrop compression benchmark (issue: 8-generation outcrop, 3 µm in and back, ≥ 200
continuation steps, < 60 s after compilation on a 2-core CPU).

For each outcrop size (generations 6..8 — the mother reaches the 6 µm surface at 6 — same gap 6 µm and seed) the full protocol —
settle, compress by 3 µm, withdraw — runs twice in one process: the first run includes
compilation, the second is timed (everything compiled).  Reported: unknowns, segments,
steps, Newton iterations, wall time after compilation and the time per Newton iteration
(each iteration = one coloured sparse Jacobian + one SuperLU factorisation and solve;
per-step tangent solves are included in the total).

**Sparse against dense Jacobian** (same protocol, same steps; both timed after compilation
in the same process): the dense path (``PathSettings(linear_solver="dense")``: n jvps,
+ dense LU) costs O(n²)–O(n³) per Newton iteration, ~10 s at the 8-generation outcrop's
6,858 unknowns, so its full ~500-iteration run would take over an hour here.  The full
load–unload run is compared at 6 generations (1,800 unknowns), and at 8 generations both
solvers run the same capped protocol (``PathSettings.max_attempts`` per phase: the settle
phase and the first attempts of the loading phase), which gives the per-step ratio at full
size.  The runs must take the same steps (checked: step count and the force curves agree).

Run:  PYTHONPATH=. python benchmarks/outcrop_compression.py [--quick] [--out DIR]
(--quick: 6 generations, 1 µm, one run including compilation, and a 4-generation dense
comparison — a smoke test; the machine has 2 cores, OPENBLAS_NUM_THREADS=1).
"""

from __future__ import annotations

import time

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np

import socbjax as sj


def run(generations: int, displacement: float, max_step: float, repeat: bool = True) -> dict:
    net = sj.dendritic_outcrop(generations=generations, gap=6.0, seed=0, GJ=None)  # the paper: torsion-free
    settings = sj.PathSettings(max_step=max_step, initial_step=min(0.02, max_step))
    t0 = time.perf_counter()
    # throw=False: the timed path runs past the first surface crossing (no contact model yet); its status is reported
    result = sj.compress(net, displacement, unload=True, method="arclength", settings=settings, throw=False)
    first = wall = time.perf_counter() - t0
    if repeat:  # the timed run: everything compiled
        t0 = time.perf_counter()
        result = sj.compress(net, displacement, unload=True, method="arclength", settings=settings, throw=False)
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
        "path_followed": bool(result.completed or result.result == sj.RESULTS.surface_crossed),
        "status": result.status_message,
        "first_run_s": first,
        "wall_s": wall,
        "compile_s": first - wall if repeat else None,
        "ms_per_iteration": 1e3 * wall / max(iterations, 1),
        "peak_force_pN": float(result.force.max()),
        "displacement_at_peak_um": float(result.displacement[int(np.argmax(result.force))]),
        "force_at_max_displacement_pN": float(result.force[result.phase == 1][-1]),
        "events": [(p.kind, p.phase, round(p.displacement, 4), round(p.force, 5)) for p in result.limit_points],
    }


def versus_dense(generations: int, displacement: float, max_step: float, max_attempts: int | None, gap: float = 6.0) -> dict:
    """The protocol with the sparse and with the dense Jacobian solver, each timed after a
    compiling warm-up (one attempt per phase); ``max_attempts`` caps every phase."""
    net = sj.dendritic_outcrop(generations=generations, gap=gap, seed=0, GJ=None)  # the paper: torsion-free
    base = sj.PathSettings(max_step=max_step, initial_step=min(0.02, max_step))
    capped = base.replace(max_attempts=max_attempts)  # None: compress's default budget
    out = {"generations": generations, "segments": net.n_segments, "max_attempts_per_phase": max_attempts}
    for kind in ("sparse", "dense"):
        warm = base.replace(max_attempts=1, linear_solver=kind)
        t0 = time.perf_counter()
        sj.compress(net, displacement, unload=True, method="arclength", settings=warm, throw=False)
        compile_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        result = sj.compress(net, displacement, unload=True, method="arclength", settings=capped.replace(linear_solver=kind),
                             throw=False)
        wall = time.perf_counter() - t0
        iterations = int(result.iterations.sum())
        out[kind] = {"wall_s": wall, "warmup_s": compile_s, "steps": result.n_steps, "newton_iterations": iterations,
                     "completed": result.completed, "ms_per_iteration": 1e3 * wall / max(iterations, 1),
                     "force": result.force}
        print(f"  {generations} generations, {kind:6s}: {result.n_steps} steps, {iterations} iterations, {wall:.1f} s "
              f"(warm-up {compile_s:.1f} s){'' if result.completed else ' (capped)'}", flush=True)
    s_, d_ = out["sparse"], out["dense"]
    out["same_steps"] = s_["steps"] == d_["steps"]
    m = min(len(s_["force"]), len(d_["force"]))
    scale = max(float(np.abs(s_["force"][:m]).max()), 1e-300)
    out["max_force_difference_rel"] = float(np.abs(s_["force"][:m] - d_["force"][:m]).max()) / scale
    out["ratio_wall"] = d_["wall_s"] / s_["wall_s"]
    out["ratio_per_iteration"] = d_["ms_per_iteration"] / s_["ms_per_iteration"]
    for kind in ("sparse", "dense"):
        out[kind]["force"] = None  # keep the JSON small
    return out


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
    verdict = big["path_followed"] and big["steps"] >= 200 and big["wall_s"] < 60
    print(f"\nlargest: {big['segments']} segments, {big['steps']} steps in {big['wall_s']:.1f} s after compilation "
          f"({'meets' if verdict else 'misses'} the ≥200 steps / <60 s target); status: {big['status']}")
    print("\nsparse vs dense Jacobian (same protocol, after compilation):")
    plan = [(3, 0.5, 0.05, None, 2.0)] if args.quick else [(6, disp, step, None), (8, disp, step, 12)]
    dense = [versus_dense(*p) for p in plan]
    print(f"{'gen':>3} {'segments':>8} {'cap/phase':>9} {'steps':>5} {'iters':>5} {'sparse s':>8} {'dense s':>8} "
          f"{'dense/sparse':>12} {'per iteration':>13} {'same steps':>10} {'max dF/F':>8}")
    for d in dense:
        print(f"{d['generations']:>3} {d['segments']:>8} {str(d['max_attempts_per_phase'] or 'full'):>9} {d['sparse']['steps']:>5} "
              f"{d['sparse']['newton_iterations']:>5} {d['sparse']['wall_s']:>8.2f} {d['dense']['wall_s']:>8.2f} "
              f"{d['ratio_wall']:>12.1f} {d['ratio_per_iteration']:>13.1f} {str(d['same_steps']):>10} {d['max_force_difference_rel']:>8.1e}")
    _common.write_json(args.out, "outcrop_compression", args,
                       {"displacement_um": disp, "max_step_um": step, "rows": rows, "versus_dense": dense})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
