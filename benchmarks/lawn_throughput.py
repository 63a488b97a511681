"""Throughput of the lawn model (socbjax.LawnModel): forward and forward + gradient of a lawn
force curve, and how the cost grows with the number of outcrop realisations.

For n outcrops (seeds 0 … n−1) of the given generations, the loss L(EI) = ½ Σ (F(cᵢ) − dᵢ)²
over M compressions is timed twice: the first call (compile + run: one compiled program per
distinct outcrop topology, so this grows with the number of topologies) and the median of
``--repeat`` further calls of ``value_and_grad`` (run only).  Printed as a table and written
to JSON with the number of distinct topologies and the segment counts.

Run:  PYTHONPATH=. python benchmarks/lawn_throughput.py [--quick] [--out DIR]
      (full: 3D outcrops of 6 generations, n = 1, 4, 16, 64; --quick: 2D, 3 generations, n = 1, 2, 4)
"""

from __future__ import annotations

import time

import _common
import jax
import jax.numpy as jnp
import numpy as np

import socbjax as sj


def _time_case(n: int, builder: dict, samples: int, repeat: int) -> dict:
    model = sj.LawnModel(n_outcrops=n, **builder)
    c = jnp.linspace(0.02, 0.3, samples)
    data = 1.01 * model.predict({"EI": 0.071}, c, reach=0.3)

    def loss(EI):
        return 0.5 * jnp.sum((model.predict({"EI": EI}, c, reach=0.3) - data) ** 2)

    value_and_grad = jax.value_and_grad(loss)
    t0 = time.perf_counter()
    jax.block_until_ready(value_and_grad(0.08))
    first = time.perf_counter() - t0
    runs = []
    for k in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(value_and_grad(0.08 + 1e-3 * k))
        runs.append(time.perf_counter() - t0)
    segments = [m.n_segments for m in model.members]
    run = float(np.median(runs))
    return {"outcrops": n, "topologies": len(model.topology_groups), "segments_total": int(sum(segments)),
            "first_call_s": first, "run_s": run, "run_per_outcrop_s": run / n}


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    if args.quick:
        builder, counts, samples, repeat = dict(generations=3, film_height=3.0, dim=2), (1, 2, 4), 6, 2
    else:
        builder, counts, samples, repeat = dict(generations=6, film_height=3.0, dim=3), (1, 4, 16, 64), 12, 3
    rows = [_time_case(n, builder, samples, repeat) for n in counts]
    _common.print_table(["outcrops", "topologies", "segments", "first call (s)", "run (s)", "run/outcrop (s)"],
                        [[r["outcrops"], r["topologies"], r["segments_total"], _common.fmt(r["first_call_s"], ".3g"),
                          _common.fmt(r["run_s"], ".3g"), _common.fmt(r["run_per_outcrop_s"], ".3g")] for r in rows],
                        title=f"lawn forward + gradient, {samples} compressions, {builder}")
    _common.write_json(args.out, "lawn_throughput", args, {"builder": builder, "samples": samples, "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
