"""Wall time of one static solve with ``socbjax.solve``, after compilation.

Case: unit cantilever (L = 1 µm, EI = 1 pN·µm²) with a perpendicular tip force,
P L²/EI = 2, solved from the straight state by load continuation.  For SOCB 2D, SOCB 3D and
jointed 2D at n = 2, 5, 10, 20, 50 nodes (quick: 2, 5; 3D only 2) it reports

* the median and minimum wall time of ``sj.solve`` (full public call, including the host
  side set-up and packaging; ``jax.block_until_ready`` on the result) over ``--repeats``
  (≥ 7) calls after the first;
* the median of the same solve compiled as one program through the public API,
  ``jax.jit(lambda net, f: sj.solve(net, f, model=model).positions)`` (networks are pytrees:
  jit traces only their values), i.e. without the host-side set-up and packaging of a plain
  ``sj.solve`` call (column "jit ms", JSON ``jit_median_s``);
* compile time = first call minus median;
* Newton iterations and continuation steps, and the degrees of freedom (size of the flat
  state vector, ``ravel_pytree(sol.state)``).

3D shapes compile slowly (~30-40 s each here), so quick mode runs 3D at n = 2 only.
``_common`` sets OPENBLAS_NUM_THREADS=1 (unless set): with threaded OpenBLAS on a 2-CPU
machine the dense LU inside Newton was 10-50x slower and erratic from ~200 unknowns on.

Run:  PYTHONPATH=. python benchmarks/solve_timing.py [--quick] [--out DIR]
Writes solve_timing.json / .png to benchmarks/results/ (or DIR).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import _common as C  # noqa: E402  (first: sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np  # noqa: E402

NAME = "solve_timing"
LOAD = 2.0


def time_case(model: str, dim: int, n: int, repeats: int) -> dict:
    import jax
    import jax.numpy as jnp
    from jax.flatten_util import ravel_pytree

    import socbjax as sj

    net = sj.cantilever(n, dim=dim)
    force = [0.0, LOAD] + [0.0] * (dim - 2)

    first, times, sol = C.time_solve(net, {-1: force}, model=model, repeats=repeats)
    rec = {"model": model, "dim": dim, "n": n, "first_call_s": first, "median_s": float(np.median(times)),
           "min_s": float(np.min(times)), "times_s": times, "compile_s": first - float(np.median(times)),
           "iterations": int(sol.iterations), "steps": int(sol.steps), "cutbacks": int(sol.cutbacks),
           "dof": int(ravel_pytree(sol.state)[0].size), "converged": bool(sol.converged)}
    try:  # the same solve compiled as one program (public API): no host-side set-up or packaging
        core = jax.jit(lambda net, f: sj.solve(net, f, model=model).positions)
        loads = jnp.zeros((n, dim)).at[-1].set(jnp.asarray(force))
        t0 = time.perf_counter()
        jax.block_until_ready(core(net, loads))  # warm-up: compiles
        rec["jit_first_call_s"] = time.perf_counter() - t0
        jitted = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(core(net, loads))
            jitted.append(time.perf_counter() - t0)
        rec["jit_median_s"] = float(np.median(jitted))
    except Exception as exc:
        rec["jit_error"] = f"{type(exc).__name__}: {exc}"
        print(f"  {model} {dim}D n={n}: jit timing FAILED: {rec['jit_error'][:200]}")
    return rec


def figure(payload: dict):
    """Median wall time of one solve (after compilation) against unknowns, per model and
    dimension, each point labelled with its node count; from the JSON payload (or its file)."""
    fig, ax = C.new_figure((6.4, 4.4))
    cases = dict.fromkeys((r["model"], r["dim"]) for r in payload["results"])
    for (model, dim), color in zip(cases, ("C0", "C3", "C2", "C1")):
        ok = [r for r in payload["results"] if r["model"] == model and r["dim"] == dim and r.get("median_s") is not None]
        ax.loglog([r["dof"] for r in ok], [1e3 * r["median_s"] for r in ok], "o-", color=color,
                  label=f"{'SOCB' if model == 'socb' else model} {dim}D")
        for r in ok:
            ax.annotate(f"{r['n']} nodes", (r["dof"], 1e3 * r["median_s"]), textcoords="offset points", xytext=(4, -9),
                        fontsize=7, color=color)
    C.plain_log_labels(ax)
    ax.set_xlabel("unknowns of the Newton system")
    ax.set_ylabel("median wall time per solve (ms)")
    ax.set_title(f"socbjax.solve after compilation, cantilever P L²/EI = {payload['load_parameter']:g}")
    ax.legend(fontsize=8)
    return fig


def main(argv=None) -> int:
    args = C.parse_args(__doc__, argv)
    repeats = 7 if args.quick else 9
    ns = [2, 5] if args.quick else [2, 5, 10, 20, 50]
    cases = [("socb", 2, ns), ("jointed", 2, ns), ("socb", 3, [2] if args.quick else ns)]
    results = []
    for model, dim, case_ns in cases:
        for n in case_ns:
            try:
                rec = time_case(model, dim, n, repeats)
            except Exception as exc:
                rec = {"model": model, "dim": dim, "n": n, "error": f"{type(exc).__name__}: {exc}"}
                print(f"  {model} {dim}D n={n} FAILED: {rec['error'][:200]}")
            results.append(rec)
            print(f"  done {model} {dim}D n={n}", flush=True)

    ms = lambda v: C.fmt(None if v is None else 1e3 * v, ".3g")  # noqa: E731
    C.print_table(
        ["model", "dim", "n", "dof", "median ms", "min ms", "jit ms", "compile s", "Newton it", "steps", "cutbacks"],
        [[r["model"], r["dim"], r["n"], r.get("dof"), ms(r.get("median_s")), ms(r.get("min_s")),
          ms(r.get("jit_median_s")), C.fmt(r.get("compile_s"), ".2f"), r.get("iterations", r.get("error", "")),
          r.get("steps"), r.get("cutbacks")] for r in results],
        title=f"static solve, cantilever P L²/EI = {LOAD}, {repeats} repeats after the first call")

    payload = {"load_parameter": LOAD, "repeats": repeats, "results": results}
    C.save_figure(figure(payload), args.out, NAME)
    C.write_json(args.out, NAME, args, payload)
    return 1 if any("error" in r for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
