"""Planar contact (issue 15): interior point forces against a shooting reference, and a
clamped–clamped column through self-contact against the elliptic-integral elastica.

Part A: a cantilever (L = 1 µm, EI = 1 pN·µm², tip load 3 pN down) pressed onto a point
obstacle at (0.6, −0.12) µm, d = 0.01 µm.  Reference: the Kirchhoff elastica integrated
(scipy DOP853, rtol 1e-13) across the jump of the internal force at the contact point, with
the same contact law.  Tip error for 2–16 segments with the exact interior force (SOCB with
jump corrections) and with the force lumped to the segment's two nodes (what node-based codes
do).

Part B: a clamped–clamped column (16 segments, d = 0.01 µm) compressed to Δ/L = 0.9 by
pseudo-arclength, with and without contact.  Reported: the gap between its lobes against the
elastica's (axis distance 2(x(L/2) − x(s₉₀)), zero-thickness touch at Δ/L = 0.84865), where
the force departs, how much stiffer it ends, the smallest gap, and the wall time of both runs
(second, compiled run; the first includes compilation).

Writes ``contact_planar.json`` and ``contact_planar.png``.

Run:  PYTHONPATH=. python benchmarks/contact_planar.py [--quick] [--out DIR]
(--quick: part A up to 8 segments, part B to Δ/L = 0.86).
"""

from __future__ import annotations

import time

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np
from scipy.optimize import brentq

import socbjax as sj
from socbjax.testing import clamped_elastica_lobe_gap, elastica_end_shortening, elastica_on_point_obstacle

L, EI, D = 1.0, 1.0, 0.01
TIP, OBSTACLE = np.array([0.0, -3.0]), np.array([0.6, -0.12])


def obstacle_solve(n_segments: int, lumped: bool):
    contact = sj.Contact(diameter=D, obstacles=(sj.Sphere(OBSTACLE, 0.0),), self_contact=False, surfaces=False,
                         lumped=lumped)
    return sj.solve(sj.cantilever(n_segments + 1, length=L, EI=EI, dim=2), forces={-1: TIP}, contact=contact)


def part_a(segments) -> dict:
    sol = obstacle_solve(4, False)
    slots = np.asarray(sol.state.contacts)[:, 0]
    j = int(np.argmax(np.linalg.norm(slots[:, 1:3], axis=1)))
    ref = elastica_on_point_obstacle(TIP, OBSTACLE, D, sj.Contact(diameter=D).law(EI),
                                     [float(sol.moments[0]), (j + slots[j, 0]) / 4, np.linalg.norm(slots[j, 1:3]),
                                      np.arctan2(slots[j, 2], slots[j, 1])], length=L, EI=EI)
    tip, sc = ref["tip"], ref["contact_s"]
    rows = []
    for n in segments:
        errors = [float(np.abs(np.asarray(obstacle_solve(n, lumped).positions[-1]) - tip[:2]).max())
                  for lumped in (False, True)]
        rows.append({"segments": n, "exact_um": errors[0], "lumped_um": errors[1]})
        print(f"  {n} segments: exact {errors[0]:.2e} µm, lumped {errors[1]:.2e} µm", flush=True)
    return {"reference_tip_um": tip[:2].tolist(), "contact_s_um": float(sc), "rows": rows}


def elastica_gap(u: float) -> float:
    """Surface-to-surface gap (µm) between the elastica's lobes at end shortening u (µm)."""
    return clamped_elastica_lobe_gap(brentq(lambda k: elastica_end_shortening(k) - u, 0.5, 0.9999)) - D


def timed(net, U, contact):
    sj.compress(net, U, contact=contact, method="arclength", throw=False)  # compiles
    t0 = time.perf_counter()
    res = sj.compress(net, U, contact=contact, method="arclength", throw=False)
    return res, time.perf_counter() - t0


def part_b(U: float) -> dict:
    net = sj.column(17, length=L, EI=EI, dim=2, supports=("clamped", "clamped"))
    t0 = time.perf_counter()
    res, wall = timed(net, U, sj.Contact(diameter=D, surfaces=False))
    first = time.perf_counter() - t0 - wall
    free, wall_free = timed(net, U, None)
    touch = elastica_end_shortening(brentq(lambda k: clamped_elastica_lobe_gap(k), 0.75, 0.9999))
    onset = elastica_end_shortening(brentq(lambda k: clamped_elastica_lobe_gap(k) - D - D / 10, 0.75, 0.9999))
    u, gap, F = (np.asarray(a) for a in (res.displacement, res.min_gap, res.force))
    # min_gap is the closest-point gap once a pair is within its band (max(10 δ, l/20) of its
    # lowest possible gap), the gap at the slot's resting point before: compare from 0.02 µm
    close = np.isfinite(gap) & (gap < 0.02) & (u < onset - 2e-3)
    elastica = np.array([elastica_gap(v) for v in u[close]])
    u_line = np.linspace(0.76, onset, 60)
    line = np.array([elastica_gap(v) for v in u_line])
    f_free = np.interp(u, np.asarray(free.displacement), np.asarray(free.force))
    print(f"  self-contact: {res.summary()}", flush=True)
    return {"touch_zero_thickness": touch, "onset_elastica": onset, "status": res.status_message.split(":")[0],
            "steps": int(res.n_steps), "min_gap_um": float(np.nanmin(gap)), "end_force_pN": float(F[-1]),
            "end_force_free_pN": float(f_free[-1]), "gap_error_um": float(np.max(np.abs(gap[close] - elastica))),
            "wall_s": wall, "wall_free_s": wall_free, "first_run_compile_s": first, "u": u, "F": F, "gap": gap,
            "u_free": np.asarray(free.displacement), "F_free": np.asarray(free.force), "u_line": u_line,
            "gap_elastica": line, "result": res}


def figure(a: dict, b: dict, args) -> None:
    fig, axes = _common.new_figure((14.0, 4.2), ncols=3)
    ax = axes[0]
    n = [r["segments"] for r in a["rows"]]
    ax.loglog(n, [r["exact_um"] for r in a["rows"]], "o-", color="C0", label="interior force, exact (jump-corrected)")
    ax.loglog(n, [r["lumped_um"] for r in a["rows"]], "s--", color="C3", label="force lumped to the two nodes")
    ax.set_xlabel("segments")
    ax.set_ylabel("tip error vs shooting reference (µm)")
    ax.set_title("cantilever on a point obstacle mid-segment", fontsize=9)
    _common.log_node_axis(ax, n)
    ax.legend(fontsize=8)
    ax = axes[1]
    ax.plot(b["u_free"], b["F_free"], color="0.5", lw=1.2, label="contact-free (lobes pass through)")
    ax.plot(b["u"], b["F"], color="C0", lw=1.6, label=f"contact, d = {D} µm")
    ax.axvline(b["touch_zero_thickness"], color="k", lw=0.8, ls=":", label="elastica touch, d = 0 (Δ/L = 0.8487)")
    ax.axvline(b["onset_elastica"], color="C3", lw=0.8, ls="--", label="elastica, lobes at d + δ")
    ax.set_xlabel("end shortening Δ (µm), L = 1 µm")
    ax.set_ylabel("axial force (pN)")
    ax.set_xlim(0.75, b["u"][-1])
    ax.set_ylim(60, max(b["F"][-1], 100) * 1.05)
    ax.set_title("clamped–clamped column through self-contact", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    ax = axes[2]
    ax.plot(b["u_line"], b["gap_elastica"], color="k", lw=1.0, label="elastica (elliptic integrals)")
    ax.plot(b["u"][np.isfinite(b["gap"])], b["gap"][np.isfinite(b["gap"])], "o", ms=3, color="C0", label="socbjax min_gap")
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_xlim(0.78, b["u"][-1])
    ax.set_ylim(-0.005, 0.06)
    ax.set_xlabel("end shortening Δ (µm)")
    ax.set_ylabel("gap between the lobes, surface to surface (µm)")
    ax.set_title("lobe gap before and after the touch\n(above 0.02 µm the pair slots rest at their segments' "
                 "middles: an upper bound)", fontsize=9)
    ax.legend(fontsize=8)
    _common.save_figure(fig, args.out, "contact_planar")


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    segments, U = ((2, 3, 4, 8), 0.86) if args.quick else ((2, 3, 4, 6, 8, 16), 0.9)
    a = part_a(segments)
    _common.print_table(["segments", "exact µm", "lumped µm", "lumped / exact"],
                        [[r["segments"], _common.fmt(r["exact_um"]), _common.fmt(r["lumped_um"]),
                          f"{r['lumped_um'] / r['exact_um']:.0f}"] for r in a["rows"]],
                        title="A. point obstacle mid-segment: tip error against shooting")
    b = part_b(U)
    _common.print_table(["quantity", "value"], [
        ["elastica touch, d = 0 (Δ/L)", f"{b['touch_zero_thickness']:.5f}"],
        ["elastica lobes at d + δ (Δ/L)", f"{b['onset_elastica']:.5f}"],
        ["max |gap − elastica| before (µm)", _common.fmt(b["gap_error_um"])],
        ["smallest gap (µm; −1 % d = −1e-4)", _common.fmt(b["min_gap_um"])],
        [f"force at Δ = {U} with / without contact (pN)", f"{b['end_force_pN']:.1f} / {b['end_force_free_pN']:.1f}"],
        ["path", f"{b['status']}, {b['steps']} steps"],
        ["wall time with / without contact (s)", f"{b['wall_s']:.1f} / {b['wall_free_s']:.1f} "
                                                 f"({b['wall_s'] / b['wall_free_s']:.1f}×)"],
    ], title="B. clamped–clamped column, 16 segments, d = 0.01 µm")
    figure(a, b, args)
    b = {k: v for k, v in b.items() if k != "result"}
    _common.write_json(args.out, "contact_planar", args, {"obstacle": a, "self_contact": b})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
