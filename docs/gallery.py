"""Regenerate the socbjax figure gallery: every figure type the library, the command line,
the demo, the fit and the benchmarks draw, each from a small but real run.

Run from anywhere:  .venv/bin/python docs/gallery.py [--only NAME ...]
Writes docs/gallery/*.png and docs/gallery.md (a few minutes on 2 cores; compiled programs
are kept in socbjax's compilation cache, so a second run is faster).

Benchmark figures are drawn by the benchmarks' own ``figure`` functions: from
``benchmarks/results/<name>.json`` when a full benchmark run left one there; otherwise the
cantilever and buckling error figures (Figs 4A, 5C) from the demo's own table, and the others
from the benchmark's ``--quick`` run, in two child processes (into a temporary folder) that run
while this process computes the library's figures.  The PyElastica comparison is
drawn only from a stored run or with PyElastica installed (``socbjax[peers]``).  Units: µm, pN, s.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: OpenBLAS threads fight XLA's on small machines

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "gallery"
BENCHMARKS = ROOT / "benchmarks"
sys.path.insert(0, str(ROOT))

import numpy as np

import socbjax as sj

DPI = 130
# benchmark -> how its figure is drawn from its JSON payload (None: its force curves are not
# in the JSON, so the PNG of its run); the longest --quick runs first
BENCHMARK_FIGURES = {
    "scaling": lambda m, p: m.figure(p),
    "ensemble_throughput": None,
    "solve_timing": lambda m, p: m.figure(p),
    "fig4b_nodes_for_accuracy": lambda m, p: m.figure(p),
    "fig4a_cantilever_error": lambda m, p: m.figure(p),
    "fig5c_buckling_error": lambda m, p: m.figure(p),
    "peers/elastica_comparison": lambda m, p: m.figure(p["socbjax"], p["pyelastica"]),
}
FROM_DEMO = ("fig4a_cantilever_error", "fig5c_buckling_error")  # drawn from the demo's table unless stored


class Gallery:
    """Collects figures (PNG in docs/gallery/) and their sections of docs/gallery.md."""

    def __init__(self):
        OUT.mkdir(parents=True, exist_ok=True)
        self.sections: list[tuple[str, str, str, str, float]] = []
        self.demo_report: dict | None = None  # the demo's table, for the Fig. 4A / 5C benchmark figures

    def add(self, name: str, title: str, what: str, how: str, fig=None, source: Path | None = None, seconds=0.0):
        path = OUT / f"{name}.png"
        if fig is not None:
            fig.savefig(path, dpi=DPI, bbox_inches="tight")
        else:
            shutil.copyfile(source, path)
        self.sections.append((name, title, what, how, seconds))
        print(f"  wrote {path.relative_to(ROOT)}", flush=True)


def _has_pyelastica() -> bool:
    import importlib.util

    return importlib.util.find_spec("elastica") is not None


def _to_run(names, demo: bool) -> list[str]:
    """Benchmarks whose figure needs a --quick run here: no stored full run, and not drawn
    from the demo's table (``demo``: the demo is part of this gallery run)."""
    out = []
    for name in names:
        if (BENCHMARKS / "results" / f"{Path(name).name}.json").exists() or (demo and name in FROM_DEMO):
            continue
        if name.startswith("peers/") and not _has_pyelastica():
            continue
        out.append(name)
    return out


# rough wall time (s) of each --quick run on 2 cores, to share them between two child processes
QUICK_SECONDS = {"scaling": 190, "ensemble_throughput": 100, "solve_timing": 90, "fig4a_cantilever_error": 70,
                 "fig5c_buckling_error": 65, "peers/elastica_comparison": 60, "fig4b_nodes_for_accuracy": 45}


def start_benchmarks(names, folder: Path) -> list[subprocess.Popen]:
    """The --quick runs of ``names`` in two child processes, each running its share one after
    the other (longest first, balanced by :data:`QUICK_SECONDS`), while this process draws
    the library's figures; each run with socbjax's compilation cache."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH", "")])))
    runner = ("import os, runpy, sys, socbjax; socbjax.enable_compilation_cache(); script = sys.argv[1]; "
              "sys.argv = [script] + sys.argv[2:]; sys.path.insert(0, os.path.dirname(script)); "
              "runpy.run_path(script, run_name='__main__')")  # as `python script.py` would, with the cache
    shares: list[list[str]] = [[], []]
    for name in sorted(names, key=lambda n: -QUICK_SECONDS.get(n, 60)):
        min(shares, key=lambda share: sum(QUICK_SECONDS.get(n, 60) for n in share)).append(name)
    children = []
    for share in (share for share in shares if share):
        cmd = " ; ".join(f"{sys.executable} -c \"{runner}\" {BENCHMARKS / (n + '.py')} --quick --out {folder} "
                         f"> {folder / (Path(n).name + '.log')} 2>&1" for n in share)
        print(f"benchmarks (--quick, in the background): {', '.join(share)}", flush=True)
        children.append(subprocess.Popen(["bash", "-c", cmd], env=env, cwd=ROOT))
    return children


def _demo_payloads(report: dict) -> dict:
    """The payloads of the Fig. 4A and 5C benchmark figures from the demo's table (the same
    cantilever and critical-load errors at the demo's node counts)."""
    import _common as C

    from socbjax.testing import elastica_cantilever

    tip = np.asarray(elastica_cantilever((0.0, 2.0)).tip_position) - [1.0, 0.0]
    exact = {"dX": float(-tip[0]), "dY": float(tip[1])}
    results, orders = {}, {}
    for model in ("socb", "jointed"):
        rows = [{"n": r["nodes"], "err_dY": abs(r["dY"] - exact["dY"]) / exact["dY"], "err_dX": abs(r["dX"] - exact["dX"]) / exact["dX"],
                     "err_vec": r["rel_error"]} for r in report["cantilever"] if r["model"] == model]
        results[model] = rows
        orders[model] = {"dY": C.fit_order([r["n"] for r in rows], [r["err_dY"] for r in rows]) if len(rows) > 1 else None}
    buckling = [{"supports": row["supports"].split("-"), "model": key.split("_")[0], "n": int(key.split("_")[1]), "rel_error": value}
                for row in report["buckling"] for key, value in row.items() if key.endswith("_error")]
    return {"fig4a_cantilever_error": {"load_parameter": 2.0, "results": results, "fitted_order": orders},
            "fig5c_buckling_error": {"exact": {row["supports"]: row["exact"] for row in report["buckling"]},
                                     "results": buckling}}


def timed(function, *args, **kwargs):
    t0 = time.perf_counter()
    value = function(*args, **kwargs)
    return value, time.perf_counter() - t0


def unit_mesh(g: Gallery) -> None:
    """The planar unit mesh (paper Fig. 6a) through its buckling and back, and past the
    first surface crossing."""
    net = sj.unit_dendritic_mesh(dim=2)
    res, s = timed(sj.compress, net, 0.35, unload=True, method="arclength")
    print(f"  unit mesh: {res.summary()} ({s:.1f} s)", flush=True)
    how = "`sj.plot_{}(result)` (or `sj.save_figures`, `socbjax simulate unit-mesh --dim 2 --figures DIR`, `socbjax plot`)"
    g.add("unit_mesh_force_curve", "Force–displacement curve (planar unit mesh)",
          "Probe force against probe displacement for the unit dendritic mesh compressed by 0.35 µm and withdrawn "
          "(pseudo-arclength): the near-vertical rise at u ≈ 0 is explained in the figure (the strands, straight but for "
          "the perturbation loads, cannot shorten before they buckle), each limit point is labelled once, loading and "
          "unloading are drawn separately and the legend follows the path.", how.format("force_curve"),
          sj.plot_force_curve(res), seconds=s)
    g.add("unit_mesh_snapshots", "Network shapes, planar (small multiples)",
          "One panel per state in path order (settled start, peak, half and full travel, half-way back, end), shared "
          "axes and equal aspect, each filament drawn as the smooth SOCB curve between its nodes (dots), with the as-built "
          "network, the surface and the probe plane.", how.format("snapshots"), sj.plot_snapshots(res))
    g.add("unit_mesh_end_forces", "Strand-end force distribution (paper Fig. 7d)",
          "Axial force on every strand end on the surface, labelled by node number, at the loading regimes "
          "(pre-stress, linear, peak, collapse).", how.format("end_forces"), sj.plot_end_forces(res))
    g.add("unit_mesh_strand_forces", "Probe and strand-end forces against displacement (paper Fig. 7c)",
          "The probe force and the force on each strand end over the loading steps.", how.format("strand_forces"),
          sj.plot_strand_forces(res))
    far, s = timed(sj.compress, net, 0.45, unload=True, method="arclength", throw=False)
    g.add("unit_mesh_crossing_force_curve", "Force curve past the first surface crossing",
          "The same mesh pushed to 0.45 µm: the mother crosses the surface at u ≈ 0.40 µm (no contact model yet), so "
          "the path from there on is shaded and the result is `RESULTS.surface_crossed`, not a success.",
          "`sj.compress(..., throw=False)`, then `sj.plot_force_curve(result)`", sj.plot_force_curve(far), seconds=s)


def column(g: Gallery) -> None:
    """The clamped–free column compressed by its last node (paper Fig. 5d)."""
    res, s = timed(sj.compress, sj.column(5, dim=2), 0.3, unload=True, method="arclength")
    print(f"  column: {res.summary()} ({s:.1f} s)", flush=True)
    how = "`sj.plot_{}(sj.compress(sj.column(5, dim=2), 0.3, unload=True))` (`socbjax simulate column --dim 2`)"
    g.add("column_force_curve", "Force curve of a column",
          "A clamped–free column of 5 nodes compressed by 0.3 µm and back: the force jumps to the Euler load π²EI/4L² "
          "= 2.47 pN at u ≈ 0 (explained in the figure), then rises slowly along the post-buckled branch.",
          how.format("force_curve"), sj.plot_force_curve(res), seconds=s)
    g.add("column_snapshots", "Column shapes",
          "The buckled column in path order: 4 segments, each a smooth SOCB curve, bending into the elastica.",
          how.format("snapshots"), sj.plot_snapshots(res))


def outcrop(g: Gallery) -> None:
    """A spatial dendritic outcrop of 4 generations (paper Fig. 7a, smaller)."""
    net = sj.dendritic_outcrop(generations=4, gap=2.5, seed=1)
    res, s = timed(sj.compress, net, 0.3, unload=True, method="arclength", throw=False)
    print(f"  outcrop: {res.summary()} ({s:.1f} s)", flush=True)
    how = "`sj.plot_{}(result)` for `sj.compress(sj.dendritic_outcrop(generations=4, gap=2.5, seed=1), 0.3, unload=True)`"
    g.add("outcrop_snapshots", "Network shapes, spatial (3D small multiples)",
          f"A 4-generation outcrop ({net.n_segments} segments) in 3D: one panel per state with common limits, equal "
          "aspect and few ticks; the smooth curves are coloured by each point's displacement from the settled start, "
          "which shows where the network deforms.", how.format("snapshots"), sj.plot_snapshots(res), seconds=s)
    g.add("outcrop_force_curve", "Force curve of a spatial outcrop", "Its force–displacement curve.",
          how.format("force_curve"), sj.plot_force_curve(res))
    g.add("outcrop_end_forces", "Strand-end forces of the outcrop", "Its strand-end force distribution (Fig. 7d).",
          how.format("end_forces"), sj.plot_end_forces(res))


def demo(g: Gallery) -> None:
    from socbjax._demo import run_demo

    with tempfile.TemporaryDirectory() as folder:
        g.demo_report, s = timed(run_demo, folder, quick=True)
        g.add("demo", "The demo figure (`socbjax demo`)",
              "Left: the cantilever under PL²/EI = 2, where SOCB with 2 nodes (one segment, drawn as its smooth curve) "
              "lies on the exact elastica and the 5-node jointed chain does not; middle: buckled clamped–free columns "
              "over the exact elastica; right: the tip error against node count.",
              "`socbjax demo --quick` (`socbjax demo` for the full table)", source=Path(folder) / "demo.png", seconds=s)


def fit(g: Gallery) -> None:
    """A fit of EI and the branch angle to a simulated unit-mesh curve with 2 % noise."""
    model = sj.UnitMeshModel(dim=2)
    truth = {"EI": 0.071, "branch_angle": 70.0}
    c = np.linspace(0.005, 0.38, 20)
    t0 = time.perf_counter()
    clean = np.asarray(sj.compress(model.network(truth), 0.38, at=c).force)
    data = clean * (1 + 0.02 * np.random.default_rng(0).standard_normal(c.size))
    result = sj.fit((c, data), model, free=("EI", "branch_angle"), initial={"EI": 1.5 * truth["EI"], "branch_angle": 55.0},
                    settings=sj.FitSettings(max_iterations=20))
    print(f"  fit: {result.summary().splitlines()[0]}", flush=True)
    g.add("fit", "A fit of a force curve",
          "EI and the branch angle of the unit mesh fitted to a simulated curve with 2 % noise (truth: EI = 0.071 "
          "pN·µm², 70°): data, the model at the fitted values (known at the data's compressions), the values with their "
          "standard errors, and the residuals.",
          "`sj.save_fit_figure(sj.fit(curve, model, ...), path)` (`socbjax fit CURVE --out fit.json` writes fit.png)",
          sj.plot_fit(result, title="simulated unit mesh"), seconds=time.perf_counter() - t0)


BENCHMARK_TEXT = {
    "fig4a_cantilever_error": ("Benchmark: cantilever error against nodes (Fig. 4A)",
                               ("Relative error of the tip deflection against node count, SOCB (sixth order) and jointed "
                               "(second order), against the exact elastica.")),
    "fig4b_nodes_for_accuracy": ("Benchmark: nodes for a given accuracy (Fig. 4B)",
                                 ("The smallest node count reaching 1 %, 5 % and 10 % accuracy of ΔY, against the tip "
                                 "deflection.")),
    "fig5c_buckling_error": ("Benchmark: critical-load error (Fig. 5C)",
                             "Relative error of the critical load against node count for the four supports."),
    "solve_timing": ("Benchmark: time per solve", ("Median wall time of one static solve after compilation against the "
                     "number of unknowns.")),
    "scaling": ("Benchmark: cost against network size", ("Time and memory of one Newton iteration against segments, "
                "chains and branched outcrops, with a slope-1 guide (linear cost).")),
    "ensemble_throughput": ("Benchmark: ensembles", ("The force curves of one vmapped ensemble run and the throughput of "
                            "the sequential, vmapped and sharded modes.")),
    "elastica_comparison": ("Benchmark: against PyElastica", ("Relative tip error against wall time for socbjax and "
                            "PyElastica's Cosserat rods on the cantilever and the buckled column.")),
}


def benchmarks(g: Gallery, names, folder: Path, children) -> None:
    if str(BENCHMARKS) not in sys.path:
        sys.path[:0] = [str(BENCHMARKS), str(BENCHMARKS / "peers")]
    if children:
        t0 = time.perf_counter()
        for child in children:
            child.wait()
        print(f"  benchmark runs finished (waited {time.perf_counter() - t0:.0f} s here)", flush=True)
    import importlib

    from_demo = _demo_payloads(g.demo_report) if g.demo_report else {}
    for name in names:
        short = Path(name).name
        title, what = BENCHMARK_TEXT[short]
        stored = BENCHMARKS / "results" / f"{short}.json"
        how = f"`PYTHONPATH=. python benchmarks/{name}.py [--quick]` (its `figure` function)"
        draw = BENCHMARK_FIGURES[name]
        if stored.exists() and draw is not None:
            payload = json.loads(stored.read_text())
            g.add(f"bench_{short}", title, what + " From the stored full run (benchmarks/results).", how,
                  draw(importlib.import_module(short), payload))
        elif short in from_demo:
            g.add(f"bench_{short}", title, what + " Drawn here from the demo's table (its node counts); the full "
                  "benchmark run covers more.", how, draw(importlib.import_module(short), from_demo[short]))
        elif (folder / f"{short}.png").exists():
            g.add(f"bench_{short}", title, what + " From the benchmark's --quick run (small settings).", how,
                  source=folder / f"{short}.png")
        else:
            log = folder / f"{short}.log"
            reason = log.read_text()[-600:] if log.exists() else "not run (PyElastica not installed: socbjax[peers])"
            print(f"  {short}: no figure: {reason}", flush=True)


def write_markdown(g: Gallery, total: float) -> None:
    lines = ["# Figure gallery", "",
             ("Every figure type socbjax draws — the compression figures of the library and the command line, the demo, "
             "the fit and the benchmarks — from small but real runs. Regenerate all of it with one command from the "
             "repository root:"), "", "```", ".venv/bin/python docs/gallery.py", "```", "",
             (f"(this run: {total:.0f} s on {os.cpu_count()} cores, {time.strftime('%Y-%m-%d')}). Shapes are always the "
             "smooth SOCB curve between nodes; planar problems are drawn on 2D axes, spatial ones on 3D axes. "
             "Units: µm, pN."), ""]
    for name, title, what, how, seconds in g.sections:
        lines += [f"## {title}", "", f"![{title}](gallery/{name}.png)", "", what, "", f"Produced by: {how}."
                  + (f" (Computed in {seconds:.0f} s.)" if seconds > 1 else ""), ""]
    if "bench_elastica_comparison" not in [section[0] for section in g.sections]:
        lines += ["## Benchmark: against PyElastica", "", ("Not drawn in this run: "
                  "`benchmarks/peers/elastica_comparison.py` needs PyElastica (`pip install -e \".[peers]\"`) or a stored "
                  "run in benchmarks/results."), ""]
    (ROOT / "docs" / "gallery.md").write_text("\n".join(lines))
    print(f"wrote {(ROOT / 'docs' / 'gallery.md').relative_to(ROOT)}")


def main(argv=None) -> int:
    parts = {"unit_mesh": unit_mesh, "column": column, "outcrop": outcrop, "demo": demo, "fit": fit}
    p = argparse.ArgumentParser(description="Regenerate docs/gallery.md and docs/gallery/*.png.")
    p.add_argument("--only", nargs="*", choices=[*parts, "benchmarks"], help="only these parts (docs/gallery.md then "
                   "lists only them)")
    args = p.parse_args(argv)
    chosen = args.only or [*parts, "benchmarks"]
    sj.enable_compilation_cache()
    t0 = time.perf_counter()
    g = Gallery()
    with tempfile.TemporaryDirectory() as folder:
        children = start_benchmarks(_to_run(BENCHMARK_FIGURES, "demo" in chosen), Path(folder)) if "benchmarks" in chosen else []
        for name in chosen:
            if name in parts:
                print(f"[{name}]", flush=True)
                parts[name](g)
        if "benchmarks" in chosen:
            print("[benchmarks]", flush=True)
            benchmarks(g, list(BENCHMARK_FIGURES), Path(folder), children)
    total = time.perf_counter() - t0
    write_markdown(g, total)
    print(f"gallery: {len(g.sections)} figures in {total:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
