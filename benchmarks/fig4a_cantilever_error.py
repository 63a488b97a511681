"""Fig. 4A of Simhadri & Chandran (2019): cantilever tip-deflection error vs node count.

A planar unit cantilever (L = 1 µm, EI = 1 pN·µm², clamped along +x at the origin) carries
a fixed-direction perpendicular tip force P = 2 pN, i.e. P L²/EI = 2.  For the SOCB and the
jointed model at several node counts n the script measures the relative error of the tip
deflection against the exact elastica:

* ΔY/L (transverse deflection), ΔX/L (shortening, 1 - x_tip/L), and the vector norm
  |u - u_exact| / |u_exact| of the tip displacement u = r_tip - (L, 0);
* the convergence order p (error ~ h^p, h = L/(n-1)), fitted over the points with error
  above 1e-12, plus the local slope between consecutive n.

Ground truth: ``socbjax.testing`` (cross-checked with the numpy shooting solver of
``_common.py``); Mattiasson (1981) tabulates ΔY/L = 0.49346, ΔX/L = 0.16064.

Run:  PYTHONPATH=. python benchmarks/fig4a_cantilever_error.py [--quick] [--out DIR]
Writes fig4a_cantilever_error.json / .png to benchmarks/results/ (or DIR).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import _common as C  # noqa: E402  (first: sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np  # noqa: E402

NAME = "fig4a_cantilever_error"
LOAD = 2.0  # P L²/EI
MATTIASSON = {"dY": 0.49346, "dX": 0.16064}


def run_model(model: str, ns, exact) -> list[dict]:
    import socbjax as sj

    ux, uy = -exact["dX"], exact["dY"]
    rows = []
    for n in ns:
        rec = {"model": model, "n": n}
        with C.Timer() as t:
            try:
                sol = sj.solve(sj.cantilever(n, dim=2), {-1: [0.0, LOAD]}, model=model, throw=True)
                tip = np.asarray(sol.positions[-1])
                dX, dY = 1.0 - tip[0], tip[1]
                rec.update(dX=dX, dY=dY, err_dY=abs(dY - exact["dY"]) / exact["dY"],
                           err_dX=abs(dX - exact["dX"]) / exact["dX"],
                           err_vec=float(np.hypot(tip[0] - 1.0 - ux, tip[1] - uy) / np.hypot(ux, uy)),
                           signed_dY=(dY - exact["dY"]) / exact["dY"],
                           iterations=int(sol.iterations), steps=int(sol.steps))
            except Exception as exc:
                rec["error"] = f"{type(exc).__name__}: {exc}"
                print(f"  {model} n={n} FAILED: {rec['error']}")
        rec["seconds"] = t.seconds
        rows.append(rec)
    ok = [r for r in rows if "err_vec" in r]
    for key in ("err_dY", "err_dX", "err_vec"):
        lo = C.local_orders([r["n"] for r in ok], [r[key] for r in ok])
        for r, v in zip(ok, lo):
            r["local_order_" + key[4:]] = v
    return rows


def figure(payload: dict):
    """Relative tip-deflection errors (ΔY and ΔX) against node count, SOCB and jointed,
    log–log, with the fitted orders; from the benchmark's JSON payload (or its file)."""
    fig, ax = C.new_figure((6.4, 4.4))
    counts = []
    for model, color, name in (("socb", "C0", "SOCB"), ("jointed", "C3", "jointed (Eq. 4)")):
        ok = [r for r in payload["results"][model] if r.get("err_vec") is not None]
        n = [r["n"] for r in ok]
        counts += n
        order = (payload.get("fitted_order") or {}).get(model, {})
        slope = f", order {order['dY']:.1f}" if order.get("dY") is not None and np.isfinite(order["dY"]) else ""
        ax.loglog(n, [max(r["err_dY"], 1e-16) for r in ok], "o-", color=color, label=f"{name}: ΔY{slope}")
        ax.loglog(n, [max(r["err_dX"], 1e-16) for r in ok], "s--", color=color, mfc="none", label=f"{name}: ΔX")
    ax.axhline(0.01, color="0.5", lw=0.8, ls=":", label="1 % error")
    C.log_node_axis(ax, counts)
    ax.set_xlabel("nodes n (segment length L/(n − 1))")
    ax.set_ylabel("relative error of the tip deflection")
    ax.set_title(f"Cantilever, tip load P L²/EI = {payload['load_parameter']:g} (paper Fig. 4A)")
    fig.legend(fontsize=8, ncols=3, loc="outside lower center", frameon=False)  # below: the full run fills the corners
    return fig


def main(argv=None) -> int:
    args = C.parse_args(__doc__, argv)
    socb_ns = [2, 3, 5] if args.quick else list(range(2, 11))
    jointed_ns = [2, 5, 10] if args.quick else [2, 3, 5, 10, 20, 50, 100]
    ref = C.exact_cantilever([LOAD])
    exact = {"dX": float(ref["dX"][0]), "dY": float(ref["dY"][0])}
    print(f"exact elastica P L²/EI = {LOAD}: ΔY/L = {exact['dY']:.12f}, ΔX/L = {exact['dX']:.12f} "
          f"({ref['source']}; numpy cross-check diff {C.fmt(ref['crosscheck_max_abs_diff'], '.1e')})")
    print(f"Mattiasson 1981: ΔY/L = {MATTIASSON['dY']}, ΔX/L = {MATTIASSON['dX']}")

    results, orders = {}, {}
    for model, ns in (("socb", socb_ns), ("jointed", jointed_ns)):
        rows = run_model(model, ns, exact)
        results[model] = rows
        ok = [r for r in rows if "err_vec" in r]
        orders[model] = {k: C.fit_order([r["n"] for r in ok], [r["err_" + k] for r in ok]) for k in ("dY", "dX", "vec")}
        C.print_table(
            ["n", "ΔY/L", "ΔX/L", "err ΔY", "err ΔX", "err |u|", "order ΔY", "order |u|", "Newton it", "s"],
            [[r["n"], C.fmt(r.get("dY"), ".9f"), C.fmt(r.get("dX"), ".9f"), r.get("err_dY"), r.get("err_dX"), r.get("err_vec"),
              r.get("local_order_dY"), r.get("local_order_vec"), r.get("iterations", r.get("error", "")), r["seconds"]]
             for r in rows],
            title=f"{model}: relative tip error vs nodes (P L²/EI = {LOAD}); order = local log-log slope vs h = L/(n-1)",
            spec=".3g")
        print("fitted order (err > 1e-12): " + ", ".join(f"{k}: {v:.2f}" for k, v in orders[model].items()))

    payload = {
        "load_parameter": LOAD, "exact": exact, "exact_source": ref["source"],
        "crosscheck_max_abs_diff": ref["crosscheck_max_abs_diff"], "mattiasson_1981": MATTIASSON,
        "order_definition": "slope of log(error) vs log(h), h = L/(n-1), points with error > 1e-12",
        "fitted_order": orders, "results": results,
    }
    C.save_figure(figure(payload), args.out, NAME)
    C.write_json(args.out, NAME, args, payload)
    failed = [r for rows in results.values() for r in rows if "error" in r]
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
