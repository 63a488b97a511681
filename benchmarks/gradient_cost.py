"""Cost of a gradient through a whole compression path, against the forward path (issue:
gradient at most 3× the forward cost), and a finite-difference check of the gradient in 3D.

For each case a loss L(θ) = ½ Σᵢ (F(uᵢ; θ) − dᵢ)² over M sampled probe displacements uᵢ
(``compress(..., at=u)``: adaptive path on the host, then M exact equilibria) is timed:

* forward  : ``jit(L)(θ)``  — the path and the M sampled equilibria;
* gradient : ``jit(value_and_grad(L))(θ)`` — the same plus one transposed solve per sample
  (implicit function theorem);
* path only: ``compress(network, U)`` without samples, for reference ("/path": gradient
  time over this).

Each is run once to compile, then timed ``--repeat`` times; medians and the ratio
gradient/forward are printed and written to JSON.  The 3D outcrop case also compares the
gradient with central finite differences of the whole pipeline.

Run:  PYTHONPATH=. python benchmarks/gradient_cost.py [--quick] [--out DIR]
"""

from __future__ import annotations


import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import jax
import jax.numpy as jnp
import numpy as np

import socbjax as sj

REPEAT = 5


def _case(name, model, names, theta, displacement, samples, fd_check, repeat):
    u = jnp.linspace(displacement / samples, displacement, samples)
    theta = jnp.asarray(theta, jnp.float64)

    def forces(t):
        network = model.network(dict(zip(names, t)))
        return sj.compress(network, displacement, at=u, method="arclength", throw=False).force

    data = forces(theta) * 1.01
    loss = jax.jit(lambda t: 0.5 * jnp.sum((forces(t) - data) ** 2))
    value_and_grad = jax.jit(jax.value_and_grad(lambda t: 0.5 * jnp.sum((forces(t) - data) ** 2)))
    forward = _common.median_ms(lambda: loss(theta), repeat) / 1e3
    gradient = _common.median_ms(lambda: value_and_grad(theta), repeat) / 1e3
    path = _common.median_ms(lambda: sj.compress(model.base, displacement, method="arclength", throw=False).force,
                             repeat) / 1e3
    row = {"case": name, "segments": model.base.n_segments, "parameters": len(names), "samples": samples,
           "forward_s": forward, "gradient_s": gradient, "path_only_s": path, "ratio": gradient / forward,
           "ratio_to_path": gradient / path}
    if fd_check:
        g = np.asarray(value_and_grad(theta)[1])
        fd = []
        for i in range(len(names)):
            h = 1e-5 * abs(float(theta[i]))
            fd.append((float(loss(theta.at[i].add(h))) - float(loss(theta.at[i].add(-h)))) / (2 * h))
        row["fd_max_rel_error"] = float(np.max(np.abs(g - np.asarray(fd))) / np.max(np.abs(g)))
    return row


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    repeat = 2 if args.quick else REPEAT
    unit = sj.UnitMeshModel(dim=2)
    cases = [("unit mesh 2D (EI, angle)", unit, ("EI", "branch_angle"), (0.071, 65.0), 0.5, 32, False)]
    if not args.quick:
        small = sj.OutcropModel(generations=6, gap=6.0, dim=3, seed=0, GJ=None)  # as measured: torsion-free
        big = sj.OutcropModel(generations=7, gap=6.0, dim=3, seed=0, GJ=None)
        cases += [
            ("outcrop 3D gen 6 (EI per order)", small, tuple(small.groups), np.full(len(small.groups), 0.071), 2.0, 32, True),
            ("outcrop 3D gen 7 (EI per order)", big, tuple(big.groups), np.full(len(big.groups), 0.071), 2.0, 32, False),
        ]
    rows = [_case(*c, repeat) for c in cases]
    print(f"{'case':<34} {'segs':>5} {'p':>2} {'M':>3} {'path s':>7} {'forward s':>9} {'grad s':>7} {'ratio':>6} {'/path':>6} {'FD err':>8}")
    for r in rows:
        fd = f"{r['fd_max_rel_error']:.1e}" if "fd_max_rel_error" in r else ""
        print(f"{r['case']:<34} {r['segments']:>5} {r['parameters']:>2} {r['samples']:>3} {r['path_only_s']:>7.3f} "
              f"{r['forward_s']:>9.3f} {r['gradient_s']:>7.3f} {r['ratio']:>6.2f} {r['ratio_to_path']:>6.2f} {fd:>8}")
    worst = max(r["ratio"] for r in rows)
    worst_path = max(r["ratio_to_path"] for r in rows)
    print(f"\nworst gradient/forward ratio {worst:.2f} ({'meets' if worst <= 3 else 'misses'} the ≤ 3 target); "
          f"against the bare adaptive path (no samples) {worst_path:.2f}")
    _common.write_json(args.out, "gradient_cost", args, {"repeat": repeat, "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
