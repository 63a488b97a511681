"""Cost of ``jax.grad`` of a static solve against the solve itself (implicit derivatives).

For a cantilever under a tip load P (P L²/EI = 2) the loss is the tip deflection y(EI, P).
Timed after compilation, medians of the repeats: the jitted solve, ``jax.jit(jax.grad(y,
argnums=(0, 1)))`` (the forward ramp plus one transposed linear solve at the solution, by
``socbjax.ImplicitAdjoint``) and ``jax.jit(jax.jacfwd(...))``.  The gradient is also checked
against the exact identity EI ∂y/∂EI = −P ∂y/∂P (the shape depends on P L²/EI only).
Issue target: the gradient of a 50-node solve costs at most 3× the solve.

Run: ``PYTHONPATH=. python benchmarks/solve_gradient_cost.py [--quick]``.
"""

from __future__ import annotations

import sys

import _common as C  # noqa: I001  (sets OPENBLAS_NUM_THREADS before numpy)

NAME = "solve_gradient_cost"


def case(n: int, dim: int, kind: str, repeats: int) -> dict:
    import jax
    import jax.numpy as jnp

    import socbjax as sj

    settings = sj.PathSettings(linear_solver=kind)
    length = 1.0 if n < 500 else 10.0

    def tip(EI, P):
        net = sj.cantilever(n, dim=dim, EI=EI, length=length)
        force = jnp.stack([0.0, P] + [0.0] * (dim - 2))
        return sj.solve(net, {-1: force}, settings=settings).positions[-1, 1]

    EI, P = 1.0, 2.0 / length**2
    solve = jax.jit(tip)
    grad = jax.jit(jax.grad(tip, argnums=(0, 1)))
    jacfwd = jax.jit(jax.jacfwd(tip, argnums=(0, 1)))
    t_solve = C.median_ms(lambda: solve(EI, P), repeats) / 1e3
    t_grad = C.median_ms(lambda: grad(EI, P), repeats) / 1e3
    t_fwd = C.median_ms(lambda: jacfwd(EI, P), repeats) / 1e3
    dEI, dP = (float(g) for g in grad(EI, P))
    return {"n": n, "dim": dim, "linear_solver": kind, "solve_s": t_solve, "grad_s": t_grad, "jacfwd_s": t_fwd,
            "grad_over_solve": t_grad / t_solve, "jacfwd_over_solve": t_fwd / t_solve,
            "identity_rel_error": abs(EI * dEI + P * dP) / abs(P * dP)}


def main(argv=None) -> int:
    args = C.parse_args(__doc__, argv)
    repeats = 5 if args.quick else 9
    cases = [(10, 2, "dense")] if args.quick else [(50, 2, "dense"), (50, 3, "dense"), (1001, 2, "sparse")]
    results = []
    for n, dim, kind in cases:
        results.append(case(n, dim, kind, repeats))
        print(f"  done n={n} {dim}D {kind}", flush=True)
    C.print_table(
        ["nodes", "dim", "linear solver", "solve ms", "grad ms", "jacfwd ms", "grad / solve", "jacfwd / solve",
         "|EI∂EI + P∂P| / |P∂P|"],
        [[r["n"], r["dim"], r["linear_solver"], C.fmt(1e3 * r["solve_s"], ".3g"), C.fmt(1e3 * r["grad_s"], ".3g"),
          C.fmt(1e3 * r["jacfwd_s"], ".3g"), C.fmt(r["grad_over_solve"], ".2f"), C.fmt(r["jacfwd_over_solve"], ".2f"),
          C.fmt(r["identity_rel_error"], ".1e")] for r in results],
        title=f"gradient of a static solve (tip deflection, P L²/EI = 2), medians of {repeats} after compilation")
    C.write_json(args.out, NAME, args, {"results": results})
    return 0 if all(r["grad_over_solve"] <= 3.0 for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
