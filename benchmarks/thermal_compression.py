"""Thermal shapes under compression (issue 16): does the 'pre-stress' region disappear?

The paper (Simhadri & Chandran 2019, Fig. 7c) finds an initial region of convex force rise
('pre-stress') where straight strands are compressed into curved shapes, and suggests that
it is missing in experiments "because strands start out already curved there from Brownian
forces".  Here the 2D unit dendritic mesh and the 2D 8-generation outcrop are compressed
straight and with frozen thermal shapes (``socbjax.thermal_network``, actin EI = 0.071
pN·µm² at 298 K, Lp = 17.3 µm) for several seeds, with the same continuation settings.

Reported per run: the force at the first step off zero (the straight networks jump there: an
inextensible straight strand carries load at zero displacement until it buckles), the
largest force within the first 5 % of the displacement (the pre-stress peak), the secant
stiffness over the first 10 %, the first force maximum after that (collapse onset), the
first surface crossing (no contact model: strands pass through the planes beyond it), and
the wall time.  Writes ``thermal_compression.json`` and ``thermal_compression.png``.

Run:  PYTHONPATH=. python benchmarks/thermal_compression.py [--quick] [--out DIR]
(--quick: the unit mesh only, two seeds).
"""

from __future__ import annotations

import time

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np

import socbjax as sj


def metrics(result, U: float) -> dict:
    loading = np.asarray(result.phase) == 1
    u, F = np.asarray(result.displacement)[loading], np.asarray(result.force)[loading]
    first = int(np.argmax(u > 1e-9)) if np.any(u > 1e-9) else 0
    early = u <= 0.05 * U
    tenth = int(np.argmin(np.abs(u - 0.1 * U)))
    later = np.flatnonzero(u > 0.05 * U)
    peaks = [p for p in result.limit_points if p.kind == "force_maximum" and p.displacement > 0.05 * U]
    crossing = [p for p in result.limit_points if p.kind == "surface_crossing"]
    return {
        "steps": int(result.n_steps),
        "first_step_u_um": float(u[first]), "first_step_force_pN": float(F[first]),
        "early_peak_force_pN": float(F[early].max()),
        "secant_stiffness_pN_per_um": float(F[tenth] / u[tenth]) if u[tenth] > 0 else None,
        "collapse_u_um": peaks[0].displacement if peaks else None,
        "collapse_force_pN": peaks[0].force if peaks else None,
        "max_force_pN": float(F[later].max()) if later.size else float(F.max()),
        "first_crossing_u_um": crossing[0].displacement if crossing else None,
        "status": result.status_message.split(":")[0],
        "u": u, "F": F,
    }


def study(name: str, network, U: float, seeds, max_step: float) -> list[dict]:
    settings = sj.PathSettings(max_step=max_step, initial_step=min(0.02, max_step))
    rows = []
    for seed in (None, *seeds):
        net = network if seed is None else sj.thermal_network(network, temperature=298.0, seed=seed)
        t0 = time.perf_counter()
        result = sj.compress(net, U, method="arclength", settings=settings, throw=False)
        row = {"network": name, "seed": seed, "wall_s": time.perf_counter() - t0, **metrics(result, U)}
        rows.append(row)
        print(f"  {name:8s} {'straight' if seed is None else f'seed {seed}':>8}: {row['steps']:4d} steps, first step "
              f"{row['first_step_force_pN']:.3f} pN at {row['first_step_u_um']:.3g} µm, early peak "
              f"{row['early_peak_force_pN']:.3f} pN, collapse {row['collapse_u_um']} µm, {row['wall_s']:.1f} s", flush=True)
    return rows


def figure(studies: dict, out, name: str = "thermal_compression", straight_label: str = "straight (paper)"):
    fig, axes = _common.new_figure((5.5 * len(studies), 4.6), ncols=len(studies))
    axes = np.atleast_1d(axes)
    for ax, (label, (rows, U)) in zip(axes, studies.items()):
        for k, r in enumerate(rows):
            straight = r["seed"] is None
            ax.plot(r["u"], r["F"], color="k" if straight else f"C{k % 10}", lw=2.0 if straight else 1.0,
                    label=straight_label if straight else f"thermal, seed {r['seed']}", zorder=3 if straight else 2)
            if r["first_crossing_u_um"] is not None:
                i = int(np.argmin(np.abs(r["u"] - r["first_crossing_u_um"])))
                ax.plot(r["u"][i], r["F"][i], "x", color="k" if straight else f"C{k % 10}", ms=7, mew=1.5, zorder=4)
        ax.axvspan(0, 0.05 * U, color="0.9", zorder=0, label="first 5 % (pre-stress window)")
        ax.set_xlabel("probe displacement u (µm)")
        ax.set_ylabel("probe force F (pN)")
        ax.set_title(f"{label}: straight vs frozen thermal shapes (298 K)")
        ax.set_xlim(0, U)
        ax.set_ylim(bottom=0)
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=3, frameon=False)
    fig.text(0.01, -0.11, "×: first surface crossing (no contact model; the path beyond it is not physical). "
             "Thermal: actin EI 0.071 pN·µm², Lp 17.3 µm.", fontsize=7)
    return _common.save_figure(fig, out, name)


HEADERS = ["network", "shape", "steps", "F first step pN", "early peak pN", "secant pN/µm", "collapse µm", "max F pN",
           "crossing µm", "s"]


def table(studies: dict) -> list[list]:
    return [[r["network"], "straight" if r["seed"] is None else f"seed {r['seed']}", r["steps"],
             f"{r['first_step_force_pN']:.3f}", f"{r['early_peak_force_pN']:.3f}",
             "-" if r["secant_stiffness_pN_per_um"] is None else f"{r['secant_stiffness_pN_per_um']:.3g}",
             "-" if r["collapse_u_um"] is None else f"{r['collapse_u_um']:.3f}", f"{r['max_force_pN']:.3f}",
             "-" if r["first_crossing_u_um"] is None else f"{r['first_crossing_u_um']:.3f}", f"{r['wall_s']:.1f}"]
            for rows, _ in studies.values() for r in rows]


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    plan = {"unit mesh": (sj.unit_dendritic_mesh(dim=2), 0.5, range(2) if args.quick else range(6), 0.01)}
    if not args.quick:
        plan["outcrop"] = (sj.dendritic_outcrop(dim=2), 3.0, range(4), 0.03)
    studies = {name: (study(name, net, U, seeds, step), U) for name, (net, U, seeds, step) in plan.items()}
    _common.print_table(HEADERS, table(studies), title="thermal shapes under compression (2D)")
    figure(studies, args.out)
    _common.write_json(args.out, "thermal_compression", args,
                       {name: {"displacement_um": U, "rows": rows} for name, (rows, U) in studies.items()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
