"""Fig. 5C of Simhadri & Chandran (2019): critical (buckling) load error vs node count.

``socbjax.buckling_load`` gives the smallest compressive axial load at the last node at
which the straight planar column (L = 1 µm, EI = 1 pN·µm²) loses stability.  Its relative
error against the Euler load is measured for the SOCB model (n = 2..10) and the jointed
model (n = 3, 5, 10, 20, 40, 80) for all four end conditions of ``socbjax.column``:

* ("clamped", "free")    P_cr L²/EI = π²/4   (the cantilever of the paper's Fig. 5a)
* ("pinned", "pinned")   π²
* ("clamped", "pinned")  x² = 20.1907...,  x the first positive root of tan x = x
  (computed here by bisection of sin x - x cos x on [π, 3π/2])
* ("clamped", "clamped") 4π²

Note: the paper's Fig. 5 reports a scaled "tipping force" F L²/EI = 23.3 compared against
Sitar et al.; that value matches none of these classical Euler loads (2.467, 9.870, 20.19,
39.48), so the paper's value is not reproduced here; every support pair above is used.
Failures (e.g. degenerate two-node columns) are caught and recorded, not hidden.

Run:  PYTHONPATH=. python benchmarks/fig5c_buckling_error.py [--quick] [--out DIR]
Writes fig5c_buckling_error.json / .png to benchmarks/results/ (or DIR).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import _common as C  # noqa: E402  (first: sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np  # noqa: E402

NAME = "fig5c_buckling_error"


def tan_x_equals_x_root() -> float:
    """First positive root of tan x = x, by bisection of f(x) = sin x - x cos x."""
    f = lambda x: np.sin(x) - x * np.cos(x)  # noqa: E731   f(π) = π > 0, f(3π/2) = -1 < 0
    lo, hi = np.pi, 1.5 * np.pi
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if f(mid) > 0:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-15:
            break
    return 0.5 * (lo + hi)


def exact_loads() -> dict:
    x = tan_x_equals_x_root()
    return {("clamped", "free"): np.pi**2 / 4, ("pinned", "pinned"): np.pi**2,
            ("clamped", "pinned"): x**2, ("clamped", "clamped"): 4 * np.pi**2}


def figure(payload: dict):
    """|relative error| of the critical load against node count for the four supports
    (colours), SOCB (filled circles, solid) and jointed (open squares, dashed); from the
    benchmark's JSON payload (or its file)."""
    from matplotlib.lines import Line2D

    fig, ax = C.new_figure((6.6, 4.6))
    counts, handles = [], []
    for i, key in enumerate(payload["exact"]):
        for model, style in (("socb", "o-"), ("jointed", "s--")):
            ok = [r for r in payload["results"] if "-".join(r["supports"]) == key and r["model"] == model
                  and r.get("rel_error") is not None]
            counts += [r["n"] for r in ok]
            ax.loglog([r["n"] for r in ok], [max(abs(r["rel_error"]), 1e-16) for r in ok], style, color=f"C{i}",
                      mfc="none" if model == "jointed" else None)
        handles.append(Line2D([], [], color=f"C{i}", lw=2, label=key.replace("-", "–")))
    handles += [Line2D([], [], color="0.3", marker="o", label="SOCB"),
                Line2D([], [], color="0.3", marker="s", mfc="none", ls="--", label="jointed (Eq. 4)"),
                Line2D([], [], color="0.5", lw=0.8, ls=":", label="1 % error")]
    ax.axhline(0.01, color="0.5", lw=0.8, ls=":")
    C.log_node_axis(ax, counts)
    ax.set_xlabel("nodes n")
    ax.set_ylabel("|relative error of the critical load P_cr|")
    ax.set_title("Critical axial load against Euler's (paper Fig. 5C)")
    fig.legend(handles=handles, fontsize=8, ncols=4, loc="outside lower center", frameon=False)
    return fig


def main(argv=None) -> int:
    import socbjax as sj

    args = C.parse_args(__doc__, argv)
    socb_ns = [2, 3, 4, 5] if args.quick else list(range(2, 11))
    jointed_ns = [3, 5, 10] if args.quick else [3, 5, 10, 20, 40, 80]
    exact = exact_loads()
    print(f"first positive root of tan x = x: {tan_x_equals_x_root():.12f}; x² = {exact[('clamped', 'pinned')]:.9f}")

    results = []
    for supports, p_exact in exact.items():
        for model, ns in (("socb", socb_ns), ("jointed", jointed_ns)):
            for n in ns:
                rec = {"supports": list(supports), "model": model, "n": n, "exact": p_exact}
                with C.Timer() as t:
                    try:
                        p = float(sj.buckling_load(sj.column(n, supports=supports, dim=2), model=model))
                        rec.update(P_cr=p, rel_error=(p - p_exact) / p_exact)
                    except Exception as exc:
                        rec["error"] = f"{type(exc).__name__}: {exc}"
                rec["seconds"] = t.seconds
                results.append(rec)

    orders = {}
    for supports, p_exact in exact.items():
        key = "-".join(supports)
        rows = [r for r in results if tuple(r["supports"]) == supports]
        for model in ("socb", "jointed"):
            ok = [r for r in rows if r["model"] == model and "rel_error" in r]
            orders[f"{key}/{model}"] = C.fit_order([r["n"] for r in ok], [abs(r["rel_error"]) for r in ok])
        C.print_table(
            ["model", "n", "P_cr L²/EI", "rel. error", "s"],
            [[r["model"], r["n"], C.fmt(r.get("P_cr"), ".8f"), C.fmt(r.get("rel_error"), "+.3e") if "error" not in r
              else "ERROR " + r["error"][:80], C.fmt(r["seconds"], ".2f")] for r in rows],
            title=f"supports {supports}: exact P_cr L²/EI = {p_exact:.9f}")
        print(f"fitted order |err| ~ h^p: socb {orders[key + '/socb']:.2f}, jointed {orders[key + '/jointed']:.2f}")

    payload = {
        "exact": {"-".join(k): v for k, v in exact.items()}, "tan_x_root": tan_x_equals_x_root(),
        "fitted_order": orders, "results": results,
        "note": "paper's tipping force 23.3 matches no classical Euler load; all four supports used",
    }
    C.save_figure(figure(payload), args.out, NAME)
    C.write_json(args.out, NAME, args, payload)
    return 0


if __name__ == "__main__":
    sys.exit(main())
