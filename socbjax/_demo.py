"""``socbjax demo``: the cantilever (Fig. 4A) and buckling (Fig. 5c) validations, printed as a
table, written as JSON, and drawn as a figure of deformed shapes."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from ._buckling import buckling_load
from ._builders import cantilever, column
from ._solve import solve
from ._version import __version__
from .testing import elastica_cantilever

__all__ = ["run_demo"]

EULER = {
    "clamped-free": np.pi**2 / 4,
    "pinned-pinned": np.pi**2,
    "clamped-pinned": 20.190728556426,  # x², tan x = x (checked in tests/test_validation.py)
    "clamped-clamped": 4 * np.pi**2,
}


def _say(msg: str) -> None:
    print(msg, flush=True)


def _cantilever_rows(load: float, exact: np.ndarray, quick: bool):
    rows, solutions = [], {}
    cases = [("socb", n) for n in ((2, 3, 5) if quick else (2, 3, 4, 5, 8))]
    cases += [("jointed", n) for n in ((5, 20) if quick else (5, 10, 20, 50))]
    for model, n in cases:
        t0 = time.perf_counter()
        net = cantilever(n, dim=2)
        sol = solve(net, {-1: [0.0, load]}, model=model)
        d = np.asarray(sol.positions[-1]) - [1.0, 0.0]
        err = float(np.linalg.norm(d - exact) / np.linalg.norm(exact))
        rows.append(dict(model=model, nodes=n, dX=float(-d[0]), dY=float(d[1]), rel_error=err, seconds=time.perf_counter() - t0))
        solutions[(model, n)] = sol
        _say(f"  {model:8s} {n:3d} nodes  ΔX/L={-d[0]:.6f}  ΔY/L={d[1]:.6f}  rel. error {err:.2e}")
    return rows, solutions


def _buckling_rows(quick: bool):
    rows = []
    counts = [("socb", 3), ("socb", 5), ("jointed", 5), ("jointed", 20)]
    for name, exact in EULER.items():
        supports = tuple(name.split("-"))
        row = dict(supports=name, exact=exact)
        for model, n in counts if not quick else counts[:3]:
            P = float(buckling_load(column(n, supports=supports, dim=2), model=model))
            row[f"{model}_{n}"] = P
            row[f"{model}_{n}_error"] = abs(P - exact) / exact
        rows.append(row)
        errs = "  ".join(f"{k[:-6]} {v:.1e}" for k, v in row.items() if k.endswith("_error"))
        _say(f"  {name:16s} exact {exact:9.5f}   rel. errors: {errs}")
    return rows


def _post_buckling(quick: bool):
    rows, shapes = [], []
    pcr = EULER["clamped-free"]
    net = column(5, dim=2)
    for ratio in (1.05, 1.5) if quick else (1.02, 1.1, 1.5, 2.5):
        force = (-ratio * pcr, 1e-3 * ratio * pcr)
        sol = solve(net, {-1: list(force)})
        ref = elastica_cantilever(force, base_moment_guess=float(sol.moments[0]))
        d = np.asarray(sol.positions[-1]) - [1.0, 0.0]
        e = np.asarray(ref.tip_position) - [1.0, 0.0]
        err = float(np.linalg.norm(d - e) / np.linalg.norm(e))
        rows.append(dict(load_over_critical=ratio, tip_deflection=float(d[1]), exact=float(e[1]), rel_error=err))
        shapes.append((ratio, sol, np.asarray(ref.positions)))
        _say(f"  P/Pcr={ratio:4.2f}  tip deflection {d[1]:.6f}  elastica {e[1]:.6f}  rel. error {err:.1e}")
    return rows, shapes


def _figure(path: Path, exact_profile, solutions, cant_rows, shapes):
    """demo.png: the cantilever (Fig. 4A) and buckled columns as smooth SOCB curves over the
    exact elastica, and the tip error against node count (µm, relative error)."""
    from matplotlib.ticker import NullFormatter

    from ._io import atomic_path
    from ._mplfigure import new_figure
    from ._plot import plot_shapes

    fig = new_figure((15, 4.8))
    axes = fig.subplots(1, 3)
    ax = axes[0]
    ax.plot(exact_profile[:, 0], exact_profile[:, 1], "k-", lw=5, alpha=0.25, label="exact elastica")
    items = [("SOCB, 2 nodes (one segment: its smooth curve)", solutions[("socb", 2)], {"color": "C0", "lw": 1.5})]
    items.append(("jointed, 5 nodes (rigid bars)", solutions[("jointed", 5)], {"color": "C3", "lw": 1.0, "ls": "--"}))
    plot_shapes(ax, items)
    ax.set_aspect("equal", adjustable="datalim")  # equal scales, panel the same height as the others
    ax.set_title("Cantilever, tip load PL²/EI = 2 (paper Fig. 4A)")
    ax.legend(loc="upper left", fontsize=9)
    ax = axes[1]
    for k, (ratio, sol, ref) in enumerate(shapes):
        ax.plot(ref[:, 0], ref[:, 1], "k-", lw=5, alpha=0.2, label="exact elastica" if k == 0 else None)
        plot_shapes(ax, [(f"SOCB, P/P_cr = {ratio}", sol, {"color": f"C{k}"})])
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("Buckled clamped–free column, SOCB 5 nodes")
    ax.legend(loc="upper right", fontsize=9)
    ax = axes[2]
    counts = []
    for model, marker, name in (("socb", "o-", "SOCB"), ("jointed", "s--", "jointed (Eq. 4)")):
        rows = [r for r in cant_rows if r["model"] == model]
        counts += [r["nodes"] for r in rows]
        ax.loglog([r["nodes"] for r in rows], [r["rel_error"] for r in rows], marker, label=name)
    ticks = sorted(set(counts))
    ax.set_xticks(ticks, [str(t) for t in ticks])
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("nodes")
    ax.set_ylabel("relative error of the tip deflection")
    ax.set_title("Cantilever tip error against nodes, PL²/EI = 2")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    atomic_path(path, lambda tmp: fig.savefig(tmp, format="png", dpi=120))


def run_demo(out: str | os.PathLike = "socbjax-demo", *, quick: bool = False) -> dict:
    """Run the validations, print tables, write ``demo.json`` and ``demo.png`` into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    _say(f"socbjax {__version__} demo (units: µm, pN, pN·µm²; unit length and EI)")
    _say("[1/3] Cantilever, perpendicular tip load PL²/EI = 2, against the exact elastica")
    exact = elastica_cantilever((0.0, 2.0))
    exact_tip = np.asarray(exact.tip_position) - [1.0, 0.0]
    _say(f"  exact elastica  ΔX/L={-exact_tip[0]:.6f}  ΔY/L={exact_tip[1]:.6f}  (Mattiasson 1981: 0.16064, 0.49346)")
    cant_rows, solutions = _cantilever_rows(2.0, exact_tip, quick)
    _say("[2/3] Critical loads (EI/L²) against Euler's values")
    buck_rows = _buckling_rows(quick)
    _say("[3/3] Post-buckling of the clamped–free column (lateral imperfection 1e-3 P)")
    post_rows, shapes = _post_buckling(quick)
    report = dict(version=__version__, cantilever=cant_rows, buckling=buck_rows, post_buckling=post_rows)
    from ._io import atomic_path

    atomic_path(out / "demo.json", lambda tmp: tmp.write_text(json.dumps(report, indent=2)))
    _figure(out / "demo.png", np.asarray(exact.positions), solutions, cant_rows, shapes)
    _say(f"wrote {out / 'demo.json'} and {out / 'demo.png'} in {time.perf_counter() - t0:.1f} s")
    return report
