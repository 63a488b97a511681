"""The misfit warning on lawn curves of realistic point density (issue 17): does it fire when the
single column is fitted to a lawn curve, and stay silent when the lawn model is?

Companion of ``lawn_recovery.py`` (same lawn, same truth: EI = 0.09 pN·µm², ρ = 1.5 µm⁻², a
20 µm² flat probe pressing 30 screened planar outcrops of 4 generations on a 3 µm film, contact
point 0.05 µm, 2 % noise, experiment i's truth outcrops from seed 1000 (i + 1)).  The curve here
is what :func:`socbjax.fit` makes of a real AFM curve: 80 points (``FitSettings.max_points``)
from −¼ of the largest compression (``min_compression``'s default) to 0.25 µm, so 16 points
before contact and 50 in contact.  Like a measured curve it is a ``ForceCurve`` whose approach
starts APPROACH = 2 µm before the window, at the same point spacing and noise (505 more
points at zero force): ``fit`` crops them away but estimates the noise from them too (before
2026-12-03 it used only the window's 16, ν ≈ 4.5 effective degrees of freedom, and the χ²
test had no power).  ``lawn_recovery.py``'s curve has 34 points before contact and only 14 in
contact: there even the true noise level leaves the column's misfit at p ≈ 0.02 (runs test
and χ²), short of the warning's p < 1e-3.

Fits per experiment: the column (free EI, contact point, baseline) and the lawn model of
N_MODEL other realisations (``LawnModel(seed=1000 (i + 1) + 500, screen=0.3)``; free EI,
contact point, baseline, density known).  Reported: each fit's misfit verdict, χ²_red, runs-test
p-value and noise estimate.

Run:  PYTHONPATH=. python benchmarks/lawn_misfit.py [--quick] [--out DIR]
      (full: 10 experiments; --quick: 1; LAWN_MISFIT_SEEDS=3,7 runs those only; one
      experiment ≈ 5 min on 2 cores)
"""

from __future__ import annotations

import os
import time

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np

import socbjax as sj
from lawn_recovery import LAWN, MODEL_SEED_OFFSET, N_TRUTH, REACH, SCREEN, TRUTH, TRUTH_SEED_BLOCK

N_MODEL = 8  # realisations of the lawn model (lawn_recovery.py: 16; the misfit verdict does not need the SE)
COMPRESSION = np.linspace(-0.25 * REACH, REACH, 80)  # µm: a real curve as fit() bins and crops it
APPROACH = 2.0  # µm of approach before the fitted window (cropped by fit, used for the noise)


def _row(seed: int, name: str, result, seconds: float) -> dict:
    g = result.goodness or {}
    return {"experiment": seed, "fit": name, "converged": bool(result.converged), "misfit": bool(result.misfit),
            "chi2_reduced": float(result.chi2_reduced), "chi2_p": g.get("chi2_p"),
            "runs_p": (g.get("runs") or {}).get("p_value"), "noise_pN": float(result.noise),
            "n_baseline": g.get("n_baseline"),
            "EI": float(result.values["EI"]), "seconds": seconds}


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    chosen = os.environ.get("LAWN_MISFIT_SEEDS")  # e.g. "3,7": run these experiments only
    seeds = [int(k) for k in chosen.split(",")] if chosen else [0] if args.quick else list(range(10))
    c, rows = COMPRESSION, []
    for seed in seeds:
        t0 = time.perf_counter()
        block = TRUTH_SEED_BLOCK * (seed + 1)
        truth = sj.LawnModel(seed=block, n_outcrops=N_TRUTH, screen=SCREEN, **LAWN)
        model = sj.LawnModel(seed=block + MODEL_SEED_OFFSET, n_outcrops=N_MODEL, screen=SCREEN, **LAWN)
        clean = np.asarray(truth.predict(TRUTH, c, reach=REACH))
        rng = np.random.default_rng(seed)
        window = clean + 0.02 * clean.max() * rng.standard_normal(c.size)  # drawn first: the window as before
        far = c[0] - (c[1] - c[0]) * np.arange(int(APPROACH / (c[1] - c[0])), 0, -1)
        curve = sj.ForceCurve(np.concatenate([far, c]),
                              np.concatenate([0.02 * clean.max() * rng.standard_normal(far.size), window]))
        print(f"experiment {seed}: truth and model screened, curve simulated ({time.perf_counter() - t0:.0f} s)", flush=True)
        for name in ("column", "lawn"):
            t1 = time.perf_counter()
            if name == "column":
                result = sj.fit(curve, "column", free=("EI", "contact_point", "baseline"), model_options={"dim": 2})
            else:
                result = sj.fit(curve, model, free=("EI", "contact_point", "baseline"),
                                fixed={"density": TRUTH["density"]})
            rows.append(_row(seed, name, result, time.perf_counter() - t1))
            r = rows[-1]
            print(f"  experiment {seed} {name:<7s} misfit {r['misfit']!s:<5s} chi2_red {r['chi2_reduced']:.2f} "
                  f"(p {_common.fmt(r['chi2_p'], '.2g')}) runs p {_common.fmt(r['runs_p'], '.2g')} "
                  f"noise {r['noise_pN']:.3g} pN  {r['seconds']:.0f} s", flush=True)
        summary = {name: {"n": sum(r["fit"] == name for r in rows),
                          "misfit": sum(r["misfit"] for r in rows if r["fit"] == name)} for name in ("column", "lawn")}
        _common.write_json(args.out, "lawn_misfit", args, {"truth": TRUTH, "lawn": LAWN, "compression_um": c,
                                                           "n_model": N_MODEL, "n_truth": N_TRUTH, "approach_um": APPROACH, "rows": rows,
                                                           "summary": summary})
    table = [[r["experiment"], r["fit"], r["misfit"], _common.fmt(r["chi2_reduced"], ".2f"),
              _common.fmt(r["chi2_p"], ".2g"), _common.fmt(r["runs_p"], ".2g"), _common.fmt(r["noise_pN"], ".3g"),
              _common.fmt(r["seconds"], ".0f")] for r in rows]
    _common.print_table(["experiment", "fit", "misfit", "chi2_red", "chi2 p", "runs p", "noise (pN)", "s"], table,
                        title="misfit warning on 80-point lawn curves (16 before contact, 50 in contact; noise from the "
                              f"whole {APPROACH:g} µm approach), 2 % noise")
    for name, s in summary.items():
        print(f"{name}: misfit warning on {s['misfit']} of {s['n']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
