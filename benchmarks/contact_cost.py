"""Where the time of a Newton iteration goes with contact (issue 15): the residual, the
coloured sparse Jacobian and SuperLU, for a dendritic outcrop without contact, with the probe
face and the substrate on every segment's kernel (``Contact(self_contact=False,
slot_capacity=S)``) and with the default near list (only the K segments nearest a surface
carry the contact kernel, ``socbjax._contact_near``), at the same generic state (the
straight reference state plus 1e-3 random noise, where J is regular).

Each part is timed three times after compilation (median).  The Jacobian is one JVP per
colour (socbjax.ColouredSparseLU.values); the LU is scipy.sparse.linalg.splu on its
non-zeros with COLAMD, the pattern's exact zeros dropped as the solver does, plus one solve.

Writes ``contact_cost.json``.

Run:  PYTHONPATH=. python benchmarks/contact_cost.py [--quick] [--out DIR]
(default: 8 generations, 493 segments; --quick: 6 generations.  2026-12-07 on 2 cores,
nothing else running, 8 generations, no contact / every segment / near list with K = 165:
residual 1.4 / 6.7 / 3.8 ms, Jacobian 48 / 483 / 233 ms with 26 / 46 / 46 colours, SuperLU
and a solve 9 / 26 / 15 ms with 91,133 / 396,543 / 198,578 non-zeros factored (of 96,064 /
636,846 / 636,846 in the pattern), 7,659 / 17,519 / 17,519 unknowns.)
"""

from __future__ import annotations

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import jax
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from jax.flatten_util import ravel_pytree

import socbjax as sj


def measure(net, contact) -> dict:
    model = sj.make_model(net, contact=contact)
    flat, unravel = ravel_pytree(model.initial_state())
    x = flat + 1e-3 * jax.random.normal(jax.random.PRNGKey(0), flat.shape)
    frames, control = model.frames(unravel(x)), sj.Control.make()

    def fn(z):
        return model.residual(unravel(z), control, frames)

    lin = sj.linear_solver_for(model, "sparse")
    residual, jacobian = jax.jit(fn), jax.jit(lambda z: lin.values(fn, z))
    matrix = sp.csc_matrix((np.asarray(jacobian(x)), lin.rows.a, lin.indptr.a), shape=(lin.n, lin.n), copy=True)
    matrix.eliminate_zeros()  # as the solver does (socbjax._linear.factor_solve): idle slots add no fill
    measured_nnz = matrix.nnz
    return {"unknowns": lin.n, "nnz": lin.nnz, "factored_nnz": measured_nnz, "colours": lin.n_colors,
            "residual_ms": _common.median_ms(lambda: residual(x), 3),
            "jacobian_ms": _common.median_ms(lambda: jacobian(x), 3),
            "lu_ms": _common.median_ms(lambda: spla.splu(matrix, permc_spec="COLAMD").solve(np.ones(lin.n)), 3)}


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    generations = 6 if args.quick else 8
    net = sj.dendritic_outcrop(generations=generations, gap=6.0, seed=0)
    near = sj.Contact(self_contact=False)  # the default near list (slot_capacity)
    K = near.near_capacity(net.n_segments) or net.n_segments
    free = measure(net, None)
    every = measure(net, sj.Contact(self_contact=False, slot_capacity=net.n_segments))
    listed = measure(net, near)
    rows = [[name, f"{free[key]:.{digits}f}", f"{every[key]:.{digits}f}", f"{listed[key]:.{digits}f}",
             f"{every[key] / free[key]:.1f}", f"{listed[key] / free[key]:.1f}"]
            for name, key, digits in (("unknowns", "unknowns", 0), ("pattern non-zeros", "nnz", 0),
                                      ("non-zeros factored", "factored_nnz", 0),
                                      ("colours (JVPs per Jacobian)", "colours", 0), ("residual (ms)", "residual_ms", 1),
                                      ("coloured Jacobian (ms)", "jacobian_ms", 0), ("SuperLU + solve (ms)", "lu_ms", 0))]
    _common.print_table(["per Newton iteration", "no contact", "every segment's kernel", f"near list (K = {K})",
                         "ratio every", "ratio near"], rows,
                        title=f"{generations}-generation outcrop ({net.n_segments} segments), probe face + substrate")
    _common.write_json(args.out, "contact_cost", args, {"generations": generations, "segments": net.n_segments,
                                                         "slot_capacity": K, "free": free, "contact": every,
                                                         "near_list": listed})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
