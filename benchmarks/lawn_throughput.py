"""Throughput of the lawn model (socbjax.LawnModel): forward and forward + gradient of a lawn
force curve, and how the cost grows with the number of outcrop realisations.

For n outcrops (seeds 0 … n−1) of the given generations, the loss L(EI) = ½ Σ (F(cᵢ) − dᵢ)²
over M compressions is timed three times: the first call of ``jax.value_and_grad`` (compile
+ run; every seed is padded to the universal tree, :func:`socbjax.pad_outcrop`, so this is
one compiled program per batch size), the median of further calls (run only), and the first
call of a lawn of n *new* seeds (seeds 1000 …): with padding it reuses the compiled program,
so it costs a run, not a compile.  Printed as a table and written to JSON with the number of
compiled programs and the real and padded segment counts.

Run:  PYTHONPATH=. python benchmarks/lawn_throughput.py [--quick] [--out DIR]
      (full: 3D outcrops of 6 generations, n = 1, 4, 16, 64; --quick: 2D, 3 generations, n = 1, 2, 4;
      LAWN_COUNTS=1,2,4 overrides the outcrop counts)
"""

from __future__ import annotations

import os
import time

import _common
import jax
import jax.numpy as jnp
import numpy as np

import socbjax as sj


def _loss_and_grad(model, c):
    data = 1.01 * model.predict({"EI": 0.071}, c, reach=0.3)
    return jax.value_and_grad(lambda EI: 0.5 * jnp.sum((model.predict({"EI": EI}, c, reach=0.3) - data) ** 2))


def _timed(f, *args) -> float:
    t0 = time.perf_counter()
    jax.block_until_ready(f(*args))
    return time.perf_counter() - t0


def _time_case(n: int, builder: dict, samples: int, repeat: int) -> dict:
    model = sj.LawnModel(n_outcrops=n, **builder)
    c = jnp.linspace(0.02, 0.3, samples)
    value_and_grad = _loss_and_grad(model, c)
    first = _timed(value_and_grad, 0.08)
    run = float(np.median([_timed(value_and_grad, 0.08 + 1e-3 * k) for k in range(repeat)]))
    fresh = sj.LawnModel(n_outcrops=n, seed=1000, **builder)
    new_seeds = _timed(_loss_and_grad(fresh, c), 0.08)  # includes its data's forward pass: 2 runs
    padded = sum(int(sj.pad_outcrop(model.members[k], model.generations)[0].n_segments) for k in model.padded)
    return {"outcrops": n, "programs": len(model.topology_groups), "padded": len(model.padded),
            "segments_real": int(sum(m.n_segments for m in model.members)), "segments_padded": padded,
            "first_call_s": first, "run_s": run, "run_per_outcrop_s": run / n, "new_seeds_first_call_s": new_seeds}


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    if args.quick:
        builder, counts, samples, repeat = dict(generations=3, film_height=3.0, dim=2), (1, 2, 4), 6, 2
    else:
        builder, counts, samples, repeat = dict(generations=6, film_height=3.0, dim=3, GJ=None), (1, 4, 16, 64), 12, 3
    if os.environ.get("LAWN_COUNTS"):
        counts = tuple(int(n) for n in os.environ["LAWN_COUNTS"].split(","))
    rows = []
    for n in counts:
        rows.append(_time_case(n, builder, samples, repeat))
        print(f"  n = {n}: first call {rows[-1]['first_call_s']:.3g} s, run {rows[-1]['run_s']:.3g} s", flush=True)
    _common.print_table(["outcrops", "programs", "segments real/padded", "first call (s)", "run (s)",
                         "run/outcrop (s)", "new seeds, first call (s)"],
                        [[r["outcrops"], r["programs"], f"{r['segments_real']}/{r['segments_padded']}",
                          _common.fmt(r["first_call_s"], ".3g"), _common.fmt(r["run_s"], ".3g"),
                          _common.fmt(r["run_per_outcrop_s"], ".3g"), _common.fmt(r["new_seeds_first_call_s"], ".3g")]
                         for r in rows],
                        title=f"lawn forward + gradient, {samples} compressions, {builder}")
    _common.write_json(args.out, "lawn_throughput", args, {"builder": builder, "samples": samples, "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
