"""Fig. 4B of Simhadri & Chandran (2019): nodes needed for a given accuracy vs % deflection.

The planar unit cantilever (L = 1 µm, EI = 1 pN·µm²) carries a perpendicular tip force with
P L²/EI on a geometric grid from 0.1 to 10 (10 values; ΔY/L from ~3% to ~81%).  For the
SOCB and the jointed model the script finds the smallest node count n whose relative error
of ΔY (against the exact elastica) is below 1%, 5% and 10%.  Every node count is a new
compiled shape, so n is searched on the geometric grid 2, 3, 4, 5, 6, 8, 10, 13, 16, 20,
25, 32, 40, 50, 64, 80, 100, 128, 160, 200 and the first grid value that passes is
reported (">200" if none does); the search for a load stops once 1% is reached.

Run:  PYTHONPATH=. python benchmarks/fig4b_nodes_for_accuracy.py [--quick] [--out DIR]
Writes fig4b_nodes_for_accuracy.json / .png to benchmarks/results/ (or DIR).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import _common as C  # noqa: E402  (first: sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np  # noqa: E402

NAME = "fig4b_nodes_for_accuracy"
GRID = [2, 3, 4, 5, 6, 8, 10, 13, 16, 20, 25, 32, 40, 50, 64, 80, 100, 128, 160, 200]
LEVELS = (0.01, 0.05, 0.10)


def search(model: str, load: float, exact_dY: float, grid) -> dict:
    """Errors along the grid until the tightest level passes; first passing n per level."""
    import socbjax as sj

    tried, needed = [], {lv: None for lv in LEVELS}
    for n in grid:
        rec = {"n": n}
        try:
            sol = sj.solve(sj.cantilever(n, dim=2), {-1: [0.0, load]}, model=model, throw=True)
            rec["err_dY"] = abs(float(sol.positions[-1, 1]) - exact_dY) / exact_dY
        except Exception as exc:
            rec["error"] = f"{type(exc).__name__}: {exc}"
            print(f"  {model} P={load:.3g} n={n} FAILED: {rec['error'][:200]}")
        tried.append(rec)
        for lv in LEVELS:
            if needed[lv] is None and rec.get("err_dY", np.inf) <= lv:
                needed[lv] = n
        if needed[min(LEVELS)] is not None:
            break
    return {"needed": {f"{lv:.0%}": needed[lv] for lv in LEVELS}, "tried": tried}


def figure(payload: dict):
    """Smallest node count (first passing grid value) for each ΔY accuracy level against the
    tip deflection, SOCB and jointed; a level not reached on the grid is drawn as an open
    triangle above the largest grid value.  From the benchmark's JSON payload (or its file)."""
    from matplotlib.lines import Line2D

    fig, ax = C.new_figure((6.6, 4.4))
    top = max(payload["grid"])
    used = set()
    for model, color, name in (("socb", "C0", "SOCB"), ("jointed", "C3", "jointed")):
        rows = payload["results"][model]
        x = [r["percent_deflection"] for r in rows]
        # the levels often need the same n: concentric markers (small filled 1 %, larger open 5 % and 10 %) keep each visible
        for level, style, size in zip(payload["levels"], ("-", "--", ":"), (4, 7, 10)):
            y = [r["needed"][level] if r["needed"][level] else np.nan for r in rows]
            used |= {v for v in y if np.isfinite(v)}
            ax.semilogy(x, y, style, color=color, marker="o" if model == "socb" else "s", ms=size, lw=1.0,
                        mfc=color if size == 4 else "none", label=f"{name}, error ≤ {level}")
            missing = [xi for xi, yi in zip(x, y) if not np.isfinite(yi)]
            ax.semilogy(missing, [1.25 * top] * len(missing), "^", ls="none", color=color, mfc="none", ms=7)
    ticks = sorted(used | {top})
    ax.set_yticks(ticks, [str(v) for v in ticks], minor=False)
    ax.set_yticks([], minor=True)
    ax.set_ylim(0.8 * min(ticks), 1.6 * top)
    ax.set_xlabel("tip deflection ΔY/L (%)")
    ax.set_ylabel("nodes needed (first passing grid value)")
    ax.set_title("Nodes for a given accuracy of ΔY (paper Fig. 4B)")
    handles, names = ax.get_legend_handles_labels()
    handles.append(Line2D([], [], marker="^", ls="none", color="0.4", mfc="none", ms=7))
    names.append(f"not reached with n ≤ {top}")
    fig.legend(handles, names, fontsize=8, ncols=3, loc="outside lower center", frameon=False)
    return fig


def main(argv=None) -> int:
    args = C.parse_args(__doc__, argv)
    loads = np.array([0.3, 2.0, 8.0]) if args.quick else np.geomspace(0.1, 10.0, 10)
    grid = [2, 3, 5, 10, 20] if args.quick else GRID
    ref = C.exact_cantilever(loads)
    print(f"exact ΔY/L from {ref['source']} (numpy cross-check diff {C.fmt(ref['crosscheck_max_abs_diff'], '.1e')})")

    results = {"socb": [], "jointed": []}
    with C.Timer() as total:
        for model in results:
            for load, dY, dX in zip(loads, ref["dY"], ref["dX"]):
                with C.Timer() as t:
                    rec = search(model, float(load), float(dY), grid)
                results[model].append({"load": float(load), "exact_dY": float(dY), "exact_dX": float(dX),
                                       "percent_deflection": 100 * float(dY), "seconds": t.seconds, **rec})

    labels = [f"{lv:.0%}" for lv in LEVELS]
    big = f">{grid[-1]}"
    for model, rows in results.items():
        C.print_table(
            ["P L²/EI", "ΔY/L %", *[f"n({lb})" for lb in labels], "err at n=2", "err at last n", "s"],
            [[C.fmt(r["load"], ".3g"), C.fmt(r["percent_deflection"], ".1f"),
              *[r["needed"][lb] or big for lb in labels],
              C.fmt(r["tried"][0].get("err_dY"), ".2e"), C.fmt(r["tried"][-1].get("err_dY"), ".2e") + f" (n={r['tried'][-1]['n']})",
              C.fmt(r["seconds"], ".1f")] for r in rows],
            title=f"{model}: smallest grid n with relative ΔY error below each level")
    print(f"total search time {total.seconds:.1f} s")

    payload = {"levels": labels, "grid": grid, "loads": loads, "exact_source": ref["source"],
               "crosscheck_max_abs_diff": ref["crosscheck_max_abs_diff"], "results": results,
               "total_seconds": total.seconds}
    C.save_figure(figure(payload), args.out, NAME)
    C.write_json(args.out, NAME, args, payload)
    failed = [t for rows in results.values() for r in rows for t in r["tried"] if "error" in t]
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
