"""Timing of the Jacobian linear solvers of socbjax (``socbjax.ColouredSparseLU`` and
``socbjax.DenseLU``, lineax solvers).

Test function: a random tree of m blocks of b = 10 unknowns (each block's parent is the
previous block with probability 0.8, else a uniformly random earlier block), with residual

    F_i = M_i x_i + 0.3 sin(x_i) exp(0.01 sum x_i) + sum_{k ~ i} W_ik sin(x_k) (1 + 0.1 cos(sum x_i))

so J is a tree of dense 10 x 10 blocks with ~30 nonzeros per row on average (more at
branch points).  For n = m b = 1000, 4000, 10000 (quick: 1000, 4000) it reports

* prepare: the one-off host set-up ``ColouredSparseLU.probe(F, x)`` (dense probing of the
  pattern at two points, O(n) evaluations of F, plus the greedy column colouring);
* assembly: the jitted colour-compressed Jacobian ``ColouredSparseLU.values(F, x)`` (one
  vmapped JVP over the colour seeds and the gather of the nonzeros);
* factor+solve: the host SciPy part alone (``scipy.sparse.linalg.splu`` with ``permc_spec``
  MMD_AT_PLUS_A and COLAMD, and its solve with one right-hand side) on the assembled values;
* sparse total: jitted ``factor`` (assembly from the JVP of F) + ``compute`` (the SuperLU
  callback) of ``ColouredSparseLU``, with its default ordering ``permc_spec`` (COLAMD; the
  removed ``SparseJacobianSolver`` defaulted to MMD_AT_PLUS_A);
* dense: the same with ``DenseLU`` (J from n unit-vector JVPs, i.e. ``jax.jacfwd``, + LU,
  n <= 4000 only).

Every time is the median of ``--repeats`` (>= 5) calls after a first, compiling call.
The machine used for the recorded results has 2 CPU cores; OPENBLAS_NUM_THREADS=1 is set
below before numpy loads (threaded OpenBLAS oversubscribes 2 cores).

Run:  PYTHONPATH=. python benchmarks/linear_timing.py [--quick] [--out DIR]
Writes linear_timing.json to benchmarks/results/ (or DIR).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy / jaxlib load OpenBLAS

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import _common as C
import numpy as np

NAME = "linear_timing"
BLOCK = 10


def tree_function(m: int, b: int = BLOCK, seed: int = 0):
    """Residual x [m b] -> [m b] on a random tree of m blocks of size b (see module doc)."""
    import jax
    import jax.numpy as jnp

    rng = np.random.default_rng(seed)
    parent = np.array([i - 1 if rng.random() < 0.8 else rng.integers(0, i) for i in range(1, m)], int)
    child = np.arange(1, m)
    dst, src = np.concatenate([child, parent]), np.concatenate([parent, child])  # edge src -> dst
    M = jnp.asarray(4.0 * np.eye(b) + 0.3 * rng.standard_normal((m, b, b)))
    W = jnp.asarray(0.3 * rng.standard_normal((dst.size, b, b)))

    def fn(x):
        X = x.reshape(m, b)
        own = jnp.einsum("mij,mj->mi", M, X) + 0.3 * jnp.sin(X) * jnp.exp(0.01 * X.sum(1, keepdims=True))
        cpl = jnp.einsum("eij,ej->ei", W, jnp.sin(X[src])) * (1 + 0.1 * jnp.cos(X[dst].sum(1, keepdims=True)))
        return (own + jax.ops.segment_sum(cpl, dst, m)).reshape(-1)

    return fn


def jacobian_solve(solver, fn):
    """(x, rhs [n, k]) -> (J(x)^-1 rhs [n, k], sign det J): one ``factor`` of J = dfn/dx from
    its JVP and ``compute`` for every right-hand side (vmapped: one factorisation)."""
    import jax

    def solve(x, rhs):
        state = solver.factor(lambda v: jax.jvp(fn, (x,), (v,))[1], x.shape[0], x.dtype, {})
        X, _, stats = jax.vmap(lambda b: solver.compute(state, b, {}))(rhs.T)
        return X.T, stats["sign"][0]

    return solve


def time_case(n: int, repeats: int, dense: bool) -> dict:
    import jax
    import jax.numpy as jnp
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    import socbjax as sj

    fn = tree_function(n // BLOCK)
    x = jnp.asarray(np.random.default_rng(1).standard_normal(n))
    rhs = jnp.asarray(np.random.default_rng(2).standard_normal((n, 1)))

    t0 = time.perf_counter()
    sparse = sj.ColouredSparseLU.probe(fn, x)
    prepare_s = time.perf_counter() - t0

    assemble = jax.jit(lambda x: sparse.values(fn, x))
    solve = jax.jit(jacobian_solve(sparse, fn))
    vals = np.asarray(assemble(x))
    A = sp.csc_matrix((vals, sparse.rows.a, sparse.indptr.a), shape=(n, n))
    b = np.asarray(rhs)
    host = {spec: C.median_ms(lambda spec=spec: spla.splu(A, permc_spec=spec).solve(b), repeats)
            for spec in ("MMD_AT_PLUS_A", "COLAMD")}
    row_nnz = np.bincount(sparse.rows.a, minlength=n)
    rec = {"n": n, "nnz": sparse.nnz, "mean_row_nnz": float(row_nnz.mean()), "max_row_nnz": int(row_nnz.max()),
           "n_colors": sparse.n_colors, "permc_spec": sparse.permc_spec, "prepare_s": prepare_s,
           "assembly_ms": C.median_ms(lambda: assemble(x), repeats),
           "factor_solve_ms": host["MMD_AT_PLUS_A"], "factor_solve_colamd_ms": host["COLAMD"],
           "sparse_total_ms": C.median_ms(lambda: solve(x, rhs), repeats), "dense_ms": None, "max_rel_diff": None}
    X, sign = solve(x, rhs)
    if dense:
        dsolve = jax.jit(jacobian_solve(sj.DenseLU(), fn))
        rec["dense_ms"] = C.median_ms(lambda: dsolve(x, rhs), repeats)
        Xd, sign_d = dsolve(x, rhs)
        rec["max_rel_diff"] = float(jnp.max(jnp.abs(X - Xd)) / jnp.max(jnp.abs(Xd)))
        rec["sign_agrees"] = bool(sign == sign_d)
    return rec


def main(argv=None) -> dict:
    args = C.parse_args(__doc__, argv)
    sizes = (1000, 4000) if args.quick else (1000, 4000, 10000)
    repeats = 5 if args.quick else 7
    rows = []
    for n in sizes:
        rec = time_case(n, repeats, dense=n <= 4000)
        rows.append(rec)
        print(f"n={n}: done ({rec['prepare_s']:.1f} s prepare)", flush=True)
    C.print_table(["n", "nnz", "colors", "prepare s", "assembly ms", "factor+solve ms", "(COLAMD) ms",
                   "sparse total ms", "dense ms", "rel diff"],
                  [[r["n"], r["nnz"], r["n_colors"], r["prepare_s"], r["assembly_ms"], r["factor_solve_ms"],
                    r["factor_solve_colamd_ms"], r["sparse_total_ms"], r["dense_ms"], r["max_rel_diff"]]
                   for r in rows], title="Jacobian solve back ends (median ms after compilation)", spec=".3g")
    payload = {"block": BLOCK, "repeats": repeats, "cases": rows}
    C.write_json(args.out, NAME, args, payload)
    return payload


if __name__ == "__main__":
    main()
