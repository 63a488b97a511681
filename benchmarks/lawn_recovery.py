"""Recovery from synthetic lawn experiments (issue 17): a flat probe on a film of random
planar outcrops, the curve simulated with *other* outcrops than the model's, 2 % noise and a
shifted contact point, fitted jointly with the contact point and the baseline.

The experiment.  A flat disc of 12 µm² on a 3 µm film of outcrops (4 generations) at density
ρ = 1.5 µm⁻² presses ρA = 18 outcrops: the truth is ``LawnModel(seeds=<18 seeds>)`` at
EI = 0.09 pN·µm², ρ = 1.5 µm⁻², contact point 0.0437 µm (between two data points: the force
of inextensible filaments jumps at contact); 25 compressions from −0.1 to 0.25 µm (10 before
contact: the baseline from which the noise is estimated); noise N(0, (0.02 F_max)²), one draw
per noise seed.  The model: ``LawnModel(seeds=<8 other seeds>)`` (8: one fit of 16
realisations took > 20 min on this 2-core machine).

The seed pool.  Without a contact model a realisation whose nodes cross the substrate or the
probe plane before the largest travel a fit needs cannot be evaluated (in this 2D pool
about half of them, at 0.3 µm); ``LawnModel(screen=0.3)`` keeps the realisations that can
be followed that far: the model's are the first 8 that pass from seed 0 (seeds 2 … 20), the
truth's the next 18 (seeds 22 … 58).  The recovery is therefore that of the screened
population, stated as such.  (Planar outcrops: a forward pass over 32 3D outcrops did not
finish in 15 min on this 2-core machine, against 63 s for 32 planar ones.)

Fits per noise seed.  At fixed geometry the force is exactly proportional to EI · ρ, so one
curve determines only their product and the fit refuses both free; each is recovered with
the other held at its independently known value:

* "EI": free EI, contact_point, baseline; density fixed at the truth;
* "density": free density, contact_point, baseline; EI fixed at the truth (on the first
  noise seed: it is the EI fit reparametrised, see DENSITY_EVERY_SEED);
* "column": the single column (free EI, contact_point, baseline) fitted to the same lawn
  curve, a misspecified model whose misfit warning should fire.

The z-score is error / total SE, the total SE the quadrature sum of the Gauss–Newton SE and
the realisation SE (the model's 8 realisations and the experiment's 18 outcrops,
``LawnModel.realisation_covariance``).  The truth's outcrops are one draw shared by all noise
seeds, so their share of the error is common to every row.

Run:  PYTHONPATH=. python benchmarks/lawn_recovery.py [--quick] [--out DIR]
      (full: 10 noise seeds; --quick: 1; LAWN_RECOVERY_SEEDS=3,4 runs those only; prints
      each fit as it finishes; one lawn fit ≈ 5 min on 2 cores)
"""

from __future__ import annotations

import os
import time

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np

import socbjax as sj

TRUTH = {"EI": 0.09, "density": 1.5, "contact_point": 0.0437}
REACH, SCREEN = 0.25, 0.3
LAWN = {"generations": 4, "film_height": 3.0, "dim": 2, "probe_area": 12.0}
N_MODEL, N_TRUTH = 8, 18  # the truth: ρ A = 1.5 µm⁻² × 12 µm² outcrops under the probe
# At fixed geometry F ∝ EI · ρ exactly, so the density fit at known EI is the EI fit at known
# ρ reparametrised: the same Levenberg–Marquardt path, ρ̂/ρ = ÊI/EI (measured: identical to
# 6 digits).  It is run on the first noise seed to show that, on every seed with this True.
DENSITY_EVERY_SEED = False


def _fit(curve, model, target: str, fixed: dict) -> dict:
    t0 = time.perf_counter()
    result = sj.fit(curve, model, free=(target, "contact_point", "baseline"), fixed=fixed, progress=True)
    se = float(result.standard_errors[target])
    rel = float((result.realisation_errors or {}).get(target, 0.0))
    total = float(np.hypot(se, rel))
    error = float(result.values[target] - TRUTH[target])
    return {"fit": target, "seconds": time.perf_counter() - t0, "converged": bool(result.converged),
            "value": float(result.values[target]), "rel_error": error / TRUTH[target], "se": se,
            "realisation_se": rel, "z": error / total if total > 0 else float("inf"),
            "contact_point_error_um": float(result.values["contact_point"] - TRUTH["contact_point"]),
            "misfit": bool(result.misfit), "chi2_reduced": float(result.chi2_reduced),
            "noise_pN": float(result.noise)}


def _column(curve) -> dict:
    t0 = time.perf_counter()
    result = sj.fit(curve, "column", free=("EI", "contact_point", "baseline"), model_options={"dim": 2})
    return {"fit": "column", "seconds": time.perf_counter() - t0, "converged": bool(result.converged),
            "misfit": bool(result.misfit), "chi2_reduced": float(result.chi2_reduced),
            "contact_point_error_um": float(result.values["contact_point"] - TRUTH["contact_point"])}


def _summary(rows, n_seeds: int) -> dict:
    summary = {}
    for target, limit in (("EI", 0.05), ("density", 0.10)):
        sel = [r for r in rows if r["fit"] == target]
        summary[target] = {"n": len(sel), "within_limit": sum(abs(r["rel_error"]) < limit for r in sel),
                           "limit": limit, "within_2se": sum(abs(r["z"]) <= 2 for r in sel),
                           "misfit": sum(r["misfit"] for r in sel),
                           "median_rel_error": float(np.median([r["rel_error"] for r in sel])) if sel else None}
    summary["column"] = {"n": n_seeds, "misfit": sum(r["misfit"] for r in rows if r["fit"] == "column")}
    return summary


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    chosen = os.environ.get("LAWN_RECOVERY_SEEDS")  # e.g. "3,4,5": run these noise seeds only
    seeds = [int(k) for k in chosen.split(",")] if chosen else [0] if args.quick else list(range(10))
    t0 = time.perf_counter()
    model = sj.LawnModel(seed=0, n_outcrops=N_MODEL, screen=SCREEN, **LAWN)
    truth = sj.LawnModel(seed=model.seeds[-1] + 1, n_outcrops=N_TRUTH, screen=SCREEN, **LAWN)
    print(f"screened to {SCREEN} µm ({time.perf_counter() - t0:.0f} s): model seeds {model.seeds}, truth seeds "
          f"{truth.seeds}; refused {len(model.screened_out) + len(truth.screened_out)}", flush=True)
    c = np.linspace(-0.1, REACH, 25)
    clean = np.asarray(truth.predict(TRUTH, c, reach=REACH))
    lawn = {**LAWN, "model_seeds": model.seeds, "truth_seeds": truth.seeds, "screen_um": SCREEN,
            "screened_out": model.screened_out + truth.screened_out}
    rows = []
    for seed in seeds:
        noisy = clean + 0.02 * clean.max() * np.random.default_rng(seed).standard_normal(c.size)
        curve = (c, noisy)
        fits = [("EI", {"density": TRUTH["density"]}), ("column", None)]
        if seed == seeds[0] or DENSITY_EVERY_SEED:
            fits.insert(1, ("density", {"EI": TRUTH["EI"]}))
        for target, fixed in fits:
            row = _column(curve) if target == "column" else _fit(curve, model, target, fixed)
            rows.append({"noise_seed": seed, **row})
            rel, z = row.get("rel_error", float("nan")), row.get("z", float("nan"))
            print(f"  seed {seed} {row['fit']:<8s} {rel:+.4f}  z {z:+.2f}  misfit {row['misfit']}  "
                  f"chi2_red {row['chi2_reduced']:.2f}  {row['seconds']:.0f} s", flush=True)
        _common.write_json(args.out, "lawn_recovery", args, {"truth": TRUTH, "lawn": lawn, "rows": rows,
                                                             "summary": _summary(rows, seeds.index(seed) + 1)})
    table = [[r["noise_seed"], r["fit"], _common.fmt(r.get("rel_error"), "+.4f"), _common.fmt(r.get("z"), "+.2f"),
              _common.fmt(r.get("contact_point_error_um"), "+.4f"), r["misfit"], _common.fmt(r["chi2_reduced"], ".2f"),
              _common.fmt(r["seconds"], ".0f")] for r in rows]
    _common.print_table(["noise seed", "fit", "rel. error", "z", "contact pt err (µm)", "misfit", "chi2_red", "s"],
                        table, title=f"lawn recovery: {N_MODEL} model realisations fitting {N_TRUTH} other "
                                     "outcrops under the probe, 2 % noise")
    for name, s in _summary(rows, len(seeds)).items():
        print(f"{name}: " + ", ".join(f"{k} {v}" for k, v in s.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
