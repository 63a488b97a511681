"""Cost of one Newton iteration against network size: linear in the number of segments.

Two families, each size measured in its own Python process (so memory is that size's own):

* **chain**: a 2D cantilever of S segments (10 µm, EI = 1 pN·µm²), S = 100 … 10,000; at
  each size the large-deflection tip load P L²/EI = 2 is solved by :func:`socbjax.solve`
  with the sparse Jacobian solver (time after compilation, steps, Newton iterations, tip
  error against the exact elastica) and one Newton iteration is timed at the solution;
* **branched**: random 3D dendritic outcrops (:func:`socbjax.dendritic_outcrop`, gap 30 µm so
  no strand reaches the surface: every generation doubles the strands; seed 0),
  6 … 12 generations = 126 … 8,190 segments (13 generations, 16,382 segments, in full mode
  too); one Newton iteration is timed at the straight state plus 1e-3 noise.

One Newton iteration = residual and its linearisation (``jax.linearize``) + colour-compressed
sparse Jacobian (``ColouredSparseLU.factor``: one vmapped jvp over the column colours) +
SuperLU factorisation (COLAMD ordering) and solve (``ColouredSparseLU.compute``), i.e. what
``socbjax.DampedNewton`` does per iteration with the solver of
``socbjax.linear_solver_for(model, "sparse")`` (prepared from the network graph).  Reported
per size: unknowns, Jacobian non-zeros, colours, one-off host preparation (that
``linear_solver_for`` call, including its compilations), compile, medians (of 7) of the whole
iteration and of its two parts, memory (XLA buffers of the compiled iteration + the L and U
factors, and the process's peak RSS), and the log-log slopes of time and memory against
segments between 1,000 and 10,000 segments.  Acceptance (issue 5): slope ≤ 1.2 and the
10,000-segment chain solved in < 10 s after compilation.

Run:  PYTHONPATH=. python benchmarks/scaling.py [--quick] [--out DIR]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import json
import resource
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import _common as C
import numpy as np

NAME = "scaling"
LENGTH, EI, LOAD = 10.0, 1.0, 2.0  # µm, pN·µm², P L²/EI
REPEATS = 7


def _network(family: str, size: int):
    import socbjax as sj

    if family == "chain":
        return sj.cantilever(n_nodes=size + 1, length=LENGTH, EI=EI, dim=2)
    return sj.dendritic_outcrop(generations=size, gap=30.0, dim=3, seed=0, GJ=None)  # as measured: torsion-free


def _solve_chain(net, out: dict) -> None:
    """The large-deflection load, after compilation; tip error against the exact elastica."""
    import jax

    import socbjax as sj

    P = LOAD * EI / LENGTH**2
    settings = sj.PathSettings(linear_solver="sparse")
    t0 = time.perf_counter()
    sol = sj.solve(net, {-1: [0.0, -P]}, settings=settings)
    jax.block_until_ready(sol.positions)
    out["solve_first_s"] = time.perf_counter() - t0
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        sol = sj.solve(net, {-1: [0.0, -P]}, settings=settings)
        jax.block_until_ready(sol.positions)
        times.append(time.perf_counter() - t0)
    exact = C.exact_cantilever([LOAD])
    tip = np.asarray(sol.positions[-1]) / LENGTH
    err = np.hypot(1.0 - tip[0] - exact["dX"][0], -tip[1] - exact["dY"][0]) / np.hypot(exact["dX"][0], exact["dY"][0])
    out.update(solve_s=float(np.median(times)), steps=int(sol.steps), iterations=int(sol.iterations),
               residual=float(sol.residual_norm), tip_error=float(err), x0=sol.state)


def measure(family: str, size: int) -> dict:
    """One size, in this process (see module doc)."""
    import jax
    import jax.numpy as jnp
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    import socbjax as sj

    net = _network(family, size)
    disc = sj.make_model(net)
    state0 = disc.initial_state()
    x_init, unravel = jax.flatten_util.ravel_pytree(state0)
    out = dict(family=family, size=size, segments=int(net.n_segments), unknowns=int(x_init.size))
    t0 = time.perf_counter()
    js = sj.linear_solver_for(disc, "sparse")
    out.update(prepare_s=time.perf_counter() - t0, nnz=js.nnz, colors=js.n_colors)
    if family == "chain":
        _solve_chain(net, out)
        x = jax.flatten_util.ravel_pytree(out.pop("x0"))[0]
        loads = jnp.zeros_like(net.positions).at[-1, 1].set(-LOAD * EI / LENGTH**2)
    else:
        x = x_init + 1e-3 * jnp.asarray(np.random.default_rng(0).standard_normal(x_init.size))
        loads = jnp.zeros_like(net.positions)
    disc = sj.make_model(net.replace(loads=loads))  # loads live in the network; same topology, same solver
    control = sj.Control.make(1.0)  # full load, probe (if any) held at zero displacement
    frames = disc.frames(unravel(x))

    def fn(y):
        return disc.residual(unravel(y), control, frames)

    def newton_iteration(y):  # residual + linearisation, coloured Jacobian, SuperLU factor + solve
        f, lin = jax.linearize(fn, y)
        state = js.factor(lin, y.shape[0], y.dtype, {})
        step, _, stats = js.compute(state, -f, {})
        return step, stats["sign"]

    iteration = jax.jit(newton_iteration)
    assemble = jax.jit(lambda y: js.values(fn, y))
    t0 = time.perf_counter()
    compiled = iteration.lower(x).compile()
    out["compile_s"] = time.perf_counter() - t0
    mem = compiled.memory_analysis()
    xla_bytes = sum(int(getattr(mem, k, 0) or 0) for k in ("temp_size_in_bytes", "argument_size_in_bytes", "output_size_in_bytes"))
    step, sign = iteration(x)
    out["step_finite"] = bool(np.all(np.isfinite(np.asarray(step)))) and float(sign) != 0.0
    jax.block_until_ready(assemble(x))
    out["iteration_ms"] = C.median_ms(lambda: iteration(x), REPEATS)
    out["assembly_ms"] = C.median_ms(lambda: assemble(x), REPEATS)
    vals = np.asarray(assemble(x))
    rhs = np.asarray(-fn(x))
    A = sp.csc_matrix((vals, js.rows.a, js.indptr.a), shape=(js.n, js.n))
    out["factor_solve_ms"] = C.median_ms(lambda: spla.splu(A, permc_spec=js.permc_spec).solve(rhs), REPEATS)
    lu = spla.splu(A, permc_spec=js.permc_spec)
    out["lu_nnz"] = int(lu.L.nnz + lu.U.nnz)
    out["memory_mb"] = (xla_bytes + 12 * out["lu_nnz"] + 12 * js.nnz) / 2**20
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def _run_child(family: str, size: int) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(Path(__file__).resolve().parents[1]), env.get("PYTHONPATH", "")]))
    cmd = [sys.executable, __file__, "--child", family, str(size)]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{family} {size} failed:\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def slope(rows, key, lo=1000, hi=10000):
    pts = [(r["segments"], r[key]) for r in rows if lo * 0.9 <= r["segments"] <= hi * 1.7 and r.get(key)]
    if len(pts) < 2:
        return None
    s, v = np.log(np.array(pts, float)).T
    return float(np.polyfit(s, v, 1)[0])


def figure(payload: dict):
    """Newton-iteration cost (left) and memory (right) against segments, log–log, for the
    chain and branched families, with a slope-1 guide; from the JSON payload (or its file)."""
    fig, axes = C.new_figure((10.5, 4.4), ncols=2)
    results = payload["results"]
    for family, marker in (("chain", "o"), ("branched", "s")):
        rows = results.get(family, [])
        s = [r["segments"] for r in rows]
        axes[0].loglog(s, [r["iteration_ms"] for r in rows], marker + "-", color="C0", mfc="none" if family == "branched" else None,
                       label=f"{family}: Newton iteration")
        axes[0].loglog(s, [r["assembly_ms"] for r in rows], marker + ":", color="C1", mfc="none" if family == "branched" else None,
                       label=f"{family}: Jacobian assembly")
        axes[0].loglog(s, [r["factor_solve_ms"] for r in rows], marker + "--", color="C2",
                       mfc="none" if family == "branched" else None, label=f"{family}: SuperLU factor + solve")
        axes[1].loglog(s, [r["memory_mb"] for r in rows], marker + "-", color="C0", mfc="none" if family == "branched" else None,
                       label=family)
    every = [r["segments"] for rows in results.values() for r in rows]
    cost = [r["iteration_ms"] for rows in results.values() for r in rows]
    if every:  # a slope-1 guide through the geometric middle of the iteration costs
        ref = np.array([min(every), max(every)], float)
        mid = np.exp(np.mean(np.log(cost))) / np.exp(np.mean(np.log(every)))
        axes[0].loglog(ref, mid * ref, "k-", lw=0.6, label="slope 1 (linear cost)")
    axes[0].set(xlabel="segments", ylabel="wall time per Newton iteration (ms)", title="Newton iteration cost")
    axes[1].set(xlabel="segments", ylabel="memory of one iteration (MiB)", title="memory (XLA buffers + LU factors)")
    for ax in axes:
        C.plain_log_labels(ax)
        ax.grid(True, which="both", alpha=0.3)
    handles, names = axes[0].get_legend_handles_labels()  # one legend below both panels: the data keep the axes
    fig.legend(handles, names, fontsize=8, ncols=4, loc="outside lower center", frameon=False)
    axes[1].legend(fontsize=8, loc="upper left")
    return fig


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "--child":
        print(json.dumps(C._jsonable(measure(argv[1], int(argv[2])))))
        return 0
    args = C.parse_args(__doc__, argv)
    sizes = {"chain": [100, 200] if args.quick else [100, 300, 1000, 3000, 10000],
             "branched": [3] if args.quick else [6, 7, 8, 9, 10, 11, 12, 13]}
    results = {}
    for family, family_sizes in sizes.items():
        results[family] = []
        for size in family_sizes:
            row = _run_child(family, size)
            results[family].append(row)
            print(f"{family} {row['segments']:>6} segments: {row['iteration_ms']:8.1f} ms/iteration "
                  f"(assembly {row['assembly_ms']:.1f}, SuperLU {row['factor_solve_ms']:.1f}), compile {row['compile_s']:.1f} s"
                  + (f", solve {row['solve_s']:.2f} s, tip error {row['tip_error']:.1e}" if family == "chain" else ""), flush=True)
    headers = ["family", "segments", "unknowns", "nnz(J)", "colours", "prepare s", "compile s", "iteration ms",
               "assembly ms", "SuperLU ms", "memory MiB", "peak RSS MiB", "solve s", "steps/its", "tip error"]
    rows = [[r["family"], r["segments"], r["unknowns"], r["nnz"], r["colors"], r["prepare_s"], r["compile_s"], r["iteration_ms"],
             r["assembly_ms"], r["factor_solve_ms"], r["memory_mb"], r["peak_rss_mb"], r.get("solve_s"),
             f"{r['steps']}/{r['iterations']}" if "steps" in r else None, r.get("tip_error")]
            for fam in results.values() for r in fam]
    C.print_table(headers, rows, "Newton iteration cost against size (medians of 7, after compilation)", spec=".3g")
    slopes = {fam: {k: slope(results[fam], k) for k in ("iteration_ms", "assembly_ms", "factor_solve_ms", "memory_mb")}
              for fam in results}
    print("\nlog-log slopes against segments, 1,000 - 10,000 segments (+ the 16,382-segment outcrop):")
    for fam, s in slopes.items():
        print(f"  {fam:9s}: " + ", ".join(f"{k} {C.fmt(v, '.3f')}" for k, v in s.items()))
    checks = {}
    if not args.quick:
        big = next(r for r in results["chain"] if r["segments"] == 10000)
        checks = {"slope_iteration_le_1.2": all(s["iteration_ms"] is not None and s["iteration_ms"] <= 1.2 for s in slopes.values()),
                  "chain_10000_solve_lt_10s": big["solve_s"] < 10.0}
        for k, v in checks.items():
            print(f"{'PASS' if v else 'FAIL'}: {k}")
    payload = {"results": results, "slopes": slopes, "checks": checks}
    C.write_json(args.out, NAME, args, payload)
    C.save_figure(figure(payload), args.out, NAME)
    return 0


if __name__ == "__main__":
    sys.exit(main())
