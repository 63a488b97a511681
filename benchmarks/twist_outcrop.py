"""The paper's 8-generation 3D outcrop with actin's twist against the torsion-free rod (issue 16).

The torsion-free rod of the paper drops, at every branch junction, the daughter's moment
about the mother's axis.  With actin's torsional stiffness (GJ = 8e-3 pN·µm², Tsuda et al.
PNAS 1996; socbjax's default for the actin builders) the mother's twist carries it.  This
script builds ``dendritic_outcrop(generations=8, gap=6.0, seed=0)`` (paper Fig. 7a, 493
segments) both ways and reports:

* the probe force at u = 0.05, 0.1, 0.2, 0.3 µm and its ratio (twist / torsion-free), from an
  arclength path to 0.6 µm with the default perturbation;
* the first surface crossing (no contact model yet: the path is physical only before it);
* the cost: unknowns, and the median wall time of a compiled 0.2 µm arclength run (the
  command line's default travel) over 3 repeats, per run and per Newton iteration.

Writes ``twist_outcrop.json`` and ``twist_outcrop.png`` (force curves, shaded beyond each
crossing, and the force ratio).

Run:  PYTHONPATH=. python benchmarks/twist_outcrop.py [--quick] [--out DIR]
(--quick: the 4-generation outcrop of a 3 µm gap, one timing repeat).
"""

from __future__ import annotations

import time

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np

import socbjax as sj

PROBES = (0.05, 0.1, 0.2, 0.3)  # µm: travels at which the forces are compared


def run(GJ, builder: dict, U: float, repeats: int) -> dict:
    net = sj.dendritic_outcrop(**builder, GJ=GJ)
    t0 = time.perf_counter()
    path = sj.compress(net, U, method="arclength", throw=False)
    first = time.perf_counter() - t0
    loading = np.asarray(path.phase) == 1
    u, F = np.asarray(path.displacement)[loading], np.asarray(path.force)[loading]
    crossing = path.first_crossing
    walls, iterations = [], 0
    for _ in range(repeats):  # compiled by now: the same program at a shorter travel
        t0 = time.perf_counter()
        timed = sj.compress(net, 0.2, method="arclength", throw=False)
        walls.append(time.perf_counter() - t0)
        iterations = int(np.sum(np.asarray(timed.iterations)))
    wall = float(np.median(walls))
    return {"GJ": GJ, "unknowns": int(sj.make_model(net).n_unknowns), "n_segments": int(net.n_segments),
            "crossing_um": None if crossing is None else crossing.displacement, "first_run_s": first,
            "forces_pN": {str(p): float(np.interp(p, u, F)) for p in PROBES}, "run_0.2um_s": wall,
            "iterations_0.2um": iterations, "ms_per_iteration": 1000 * wall / max(iterations, 1),
            "timed_status": timed.status_message.split(":")[0], "u": u, "F": F}


def figure(rows, args, title: str) -> None:
    fig, (ax, ratio) = _common.new_figure((11.0, 4.2), ncols=2)
    for r, color in zip(rows, ("k", "C3")):
        label = "torsion-free (paper)" if r["GJ"] is None else f"actin twist, GJ = {r['GJ']:g} pN·µm²"
        ax.plot(r["u"], r["F"], color=color, lw=1.6, label=label)
        if r["crossing_um"] is not None:
            ax.axvline(r["crossing_um"], color=color, lw=0.8, ls=":")
            ax.axvspan(r["crossing_um"], r["u"][-1], color=color, alpha=0.07)
    ax.set_xlabel("probe displacement u (µm)")
    ax.set_ylabel("probe force F (pN)")
    ax.set_title(title + "\n(dotted: first surface crossing; shaded: not physical without contact)", fontsize=9)
    ax.set_xlim(0, max(r["u"][-1] for r in rows))
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8, loc="lower right")
    free, twist = rows
    end = min(c for c in (free["crossing_um"], twist["crossing_um"], free["u"][-1], twist["u"][-1]) if c is not None)
    grid = np.linspace(0.01, end, 200)
    ratio.plot(grid, np.interp(grid, twist["u"], twist["F"]) / np.interp(grid, free["u"], free["F"]), color="C3")
    ratio.axhline(1.0, color="k", lw=0.8)
    ratio.set_xlabel("probe displacement u (µm)")
    ratio.set_ylabel("F(actin twist) / F(torsion-free)")
    ratio.set_title("before the first crossing", fontsize=9)
    ratio.set_xlim(0, end)
    ratio.set_ylim(0, 1.2)
    _common.save_figure(fig, args.out, "twist_outcrop")


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    builder, U, repeats = ((dict(generations=4, gap=3.0, seed=0), 0.8, 1) if args.quick
                           else (dict(generations=8, gap=6.0, seed=0), 0.6, 3))
    rows = []
    for GJ in (None, sj.ACTIN_GJ):
        r = run(GJ, builder, U, repeats)
        rows.append(r)
        print(f"  GJ = {GJ}: crossing at {r['crossing_um']} µm, 0.2 µm run {r['run_0.2um_s']:.2f} s "
              f"({r['ms_per_iteration']:.0f} ms per iteration)", flush=True)
    free = rows[0]
    headers = ["model", "unknowns"] + [f"F({p}) pN" for p in PROBES] + ["crossing µm", "0.2 µm run s", "ms/iter"]
    table = [["torsion-free" if r["GJ"] is None else f"GJ {r['GJ']:g}", r["unknowns"]]
             + [f"{r['forces_pN'][str(p)]:.4f}" for p in PROBES]
             + ["-" if r["crossing_um"] is None else f"{r['crossing_um']:.3f}", f"{r['run_0.2um_s']:.2f}",
                f"{r['ms_per_iteration']:.0f}"] for r in rows]
    twist = rows[1]
    table.append(["ratio", f"{twist['unknowns'] / free['unknowns']:.3f}"]
                 + [f"{twist['forces_pN'][str(p)] / free['forces_pN'][str(p)]:.3f}" for p in PROBES]
                 + ["", f"{twist['run_0.2um_s'] / free['run_0.2um_s']:.2f}",
                    f"{twist['ms_per_iteration'] / free['ms_per_iteration']:.2f}"])
    title = f"3D outcrop {builder}: actin twist against torsion-free"
    _common.print_table(headers, table, title=title)
    figure(rows, args, f"3D outcrop, {builder['generations']} generations, gap {builder['gap']} µm, seed 0")
    _common.write_json(args.out, "twist_outcrop", args, {"builder": builder, "path_um": U, "repeats": repeats,
                                                         "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
