"""The 3D unit dendritic mesh with twist against the torsion-free one (issue 16).

In the torsion-free rod a branch junction drops the daughter's moment about the mother's
axis, and the daughter's azimuth follows the mother's tangent by parallel transport.  With a
torsional stiffness GJ the junction fixes the daughter's frame in the mother's material
frame, and the mother's twist carries that moment.  This script compresses the 3D unit
mesh (paper Fig. 6a, actin EI = 0.071 pN·µm², 70° branch) by 0.5 µm with GJ = None
(torsion-free), 8e-3 pN·µm² (actin, Tsuda et al. PNAS 1996), 0.071 (GJ = EI) and 1e-3 (a
soft filament), with the same continuation settings and the same out-of-plane perturbation
(a lateral load of 1e-3 pN along y on each strand's middle node, the out-of-plane direction
of the x–z mesh).

Reported per GJ: the first force maximum (the out-of-plane buckling of the mesh), the force
at the end, the largest twist angle along the mother and the largest out-of-plane (y)
excursion at the end of the loading.  Writes ``twist_unit_mesh.json`` and
``twist_unit_mesh.png``.

Run:  PYTHONPATH=. python benchmarks/twist_unit_mesh.py [--quick] [--out DIR]
(--quick: torsion-free and actin only, 0.2 µm).
"""

from __future__ import annotations

import time

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np

import socbjax as sj

PERTURBATION = 1e-3  # pN, along y on each strand's middle node


def run(GJ, U: float) -> dict:
    mesh = sj.unit_dendritic_mesh(dim=3, GJ=GJ)
    middle = np.linalg.norm(np.asarray(sj.strand_perturbation(mesh, 1.0, seed=0)), axis=1) > 0  # strand middles
    loads = np.zeros((mesh.n_nodes, 3))
    loads[middle, 1] = PERTURBATION
    mesh = mesh.replace(loads=loads)
    t0 = time.perf_counter()
    result = sj.compress(mesh, U, method="arclength", settings=sj.PathSettings(max_step=0.01, initial_step=0.005),
                         throw=False)
    wall = time.perf_counter() - t0
    loading = np.asarray(result.phase) == 1
    u, F = np.asarray(result.displacement)[loading], np.asarray(result.force)[loading]
    peaks = [p for p in result.limit_points if p.kind == "force_maximum" and p.displacement > 1e-6]
    last = np.flatnonzero(loading)[-1]
    twist_moment = np.sum(np.asarray(result.moments)[last] * np.asarray(result.tangents)[last], axis=1)
    return {"GJ": GJ, "steps": int(result.n_steps), "completed": bool(result.completed), "wall_s": wall,
            "peak_u_um": peaks[0].displacement if peaks else None, "peak_force_pN": peaks[0].force if peaks else None,
            "end_force_pN": float(F[-1]), "max_twisting_moment_pNum": float(np.abs(twist_moment).max()),
            "max_out_of_plane_um": float(np.abs(np.asarray(result.positions)[last][:, 1]).max()),
            "status": result.status_message.split(":")[0], "u": u, "F": F}


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    cases, U = ((None, 8e-3), 0.2) if args.quick else ((None, 8e-3, 0.071, 1e-3), 0.5)
    rows = []
    for GJ in cases:
        r = run(GJ, U)
        rows.append(r)
        print(f"  GJ = {GJ}: {r['steps']} steps, peak {r['peak_force_pN']} pN at {r['peak_u_um']} µm, "
              f"{r['wall_s']:.1f} s", flush=True)
    headers = ["GJ pN·µm²", "steps", "peak F pN", "at u µm", "F end pN", "max |m·t| pN·µm", "max |y| µm", "s"]
    table = [["torsion-free" if r["GJ"] is None else f"{r['GJ']:g}", r["steps"],
              "-" if r["peak_force_pN"] is None else f"{r['peak_force_pN']:.4f}",
              "-" if r["peak_u_um"] is None else f"{r['peak_u_um']:.4f}", f"{r['end_force_pN']:.4f}",
              f"{r['max_twisting_moment_pNum']:.3g}", f"{r['max_out_of_plane_um']:.3g}", f"{r['wall_s']:.1f}"]
             for r in rows]
    _common.print_table(headers, table, title=f"3D unit mesh compressed by {U} µm: twist against torsion-free")
    fig, (ax, diff) = _common.new_figure((11.0, 4.2), ncols=2)
    free = rows[0]
    for k, r in enumerate(rows):
        label = "torsion-free" if r["GJ"] is None else f"GJ = {r['GJ']:g} pN·µm²" + (" (actin)" if r["GJ"] == 8e-3 else "")
        style = dict(color="k" if r["GJ"] is None else f"C{k}", lw=2.0 if r["GJ"] is None else 1.2,
                     ls="-" if r["GJ"] is None else "--", label=label)
        ax.plot(r["u"], r["F"], **style)
        if r["GJ"] is not None and np.all(np.diff(r["u"]) > 0) and np.all(np.diff(free["u"]) > 0):
            grid = np.linspace(0.01 * U, min(r["u"][-1], free["u"][-1]), 200)  # both paths are monotone in u here
            diff.plot(grid, np.interp(grid, r["u"], r["F"]) - np.interp(grid, free["u"], free["F"]), **style)
    ax.set_xlabel("probe displacement u (µm)")
    ax.set_ylabel("probe force F (pN)")
    ax.set_title("3D unit mesh (EI 0.071 pN·µm², 70°)")
    ax.set_xlim(0, U)
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8, loc="lower right")
    diff.axhline(0.0, color="k", lw=0.8)
    diff.set_xlabel("probe displacement u (µm)")
    diff.set_ylabel("F(GJ) − F(torsion-free) (pN)")
    diff.set_title("the change that twist makes")
    diff.set_xlim(0, U)
    _common.save_figure(fig, args.out, "twist_unit_mesh")
    _common.write_json(args.out, "twist_unit_mesh", args, {"displacement_um": U, "perturbation_pN": PERTURBATION,
                                                           "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
