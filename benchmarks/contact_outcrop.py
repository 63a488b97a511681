"""3D contact with the probe face and the substrate (issue 15): a dendritic outcrop compressed
and withdrawn with ``Contact(self_contact=False)`` against the same run without contact.

The outcrop (actin: EI 0.06 pN·µm², twist GJ 8e-3 pN·µm², d = 7 nm, seed 0) is compressed by
``U`` µm by pseudo-arclength and withdrawn, once with contact on the two surfaces and once
without (the contact-free run passes through them and ends with ``surface_crossed``).
Reported: path status, steps, Newton iterations, wall time of each run (first call, so
including compilation, and the compiled time per Newton iteration), the contact count against
the compression, the smallest gap (the stated bound: −1 % of d), and the force curves: how
much stiffer with contact and from which compression (first |ΔF| > 1 % of the peak).

Filament–filament contact in 3D is built, also with the sparse solver (socbjax.PairedSparseLU),
but not used here: with it the 4-generation outcrop completes 1.5 µm and back (154 steps,
2,424 s on 2 cores, about 10 s per step; docs/equations.md, "Sparse solver with pairs"), and
the 8-generation one was not run with it, so strands still pass through each other in these
runs.

Writes ``contact_outcrop.json`` and ``contact_outcrop.png``.

Run:  PYTHONPATH=. python benchmarks/contact_outcrop.py [--quick] [--out DIR]
(default: 8 generations, 6 µm gap, 3 µm and back, 2026-12-07 on 2 cores: with contact
completed, 271 steps, 1,338 Newton iterations, 625 s first call (1,519 s before the near
list of ``Contact(slot_capacity=...)``), up to 27 contacts,
smallest gap +0.664 nm, force 1.51× the contact-free one at 3 µm; without, 55 s, strands
crossing the surfaces from u = 0.342 µm (dotted in the figure from there); --quick: 6
generations, 1.5 µm and back, 2026-12-07 on 2 cores: with contact completed, 232 steps, 492
Newton iterations, 279 s first call, at most 3 contacts, smallest gap +0.687 nm, force 1.04×
at 1.5 µm; without, 47 s, crossing from u = 1.062 µm).
"""

from __future__ import annotations

import time

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np

import socbjax as sj


def run(net, U, contact) -> dict:
    settings = sj.PathSettings(max_step=0.05, initial_step=0.02)
    t0 = time.perf_counter()
    res = sj.compress(net, U, unload=True, method="arclength", settings=settings, throw=False, contact=contact,
                      progress=True)
    wall = time.perf_counter() - t0
    iterations = int(np.sum(res.iterations))
    print(f"  {'contact' if contact else 'contact-free'}: {res.summary()}", flush=True)
    return {"status": res.status_message.split(":")[0], "completed": bool(res.completed), "steps": int(res.n_steps),
            "newton_iterations": iterations, "wall_s": wall, "s_per_iteration": wall / max(iterations, 1),
            "u": np.asarray(res.displacement), "F": np.asarray(res.force), "phase": np.asarray(res.phase),
            "crossing": None if res.first_crossing is None else int(res.first_crossing.step),
            "count": None if contact is None else np.asarray(res.contact_count),
            "min_gap": None if contact is None else np.asarray(res.min_gap)}


def departure(with_contact: dict, free: dict) -> tuple[float, float]:
    """(first compression where the loading forces differ by > 1 % of the peak, force ratio at
    the largest compression both loading branches reach)."""
    load_c, load_f = with_contact["phase"] == with_contact["phase"][1], free["phase"] == free["phase"][1]
    u_c, F_c = with_contact["u"][load_c], with_contact["F"][load_c]
    u_f, F_f = free["u"][load_f], free["F"][load_f]
    order = np.argsort(u_f)
    common = u_c <= u_f.max()
    diff = np.abs(F_c[common] - np.interp(u_c[common], u_f[order], F_f[order]))
    peak = max(np.abs(F_c).max(), 1e-12)
    where = np.flatnonzero(diff > 0.01 * peak)
    u_dep = float(u_c[common][where[0]]) if where.size else float("nan")
    u_top = float(min(u_c.max(), u_f.max()))
    ratio = float(np.interp(u_top, u_c[np.argsort(u_c)], F_c[np.argsort(u_c)])
                  / np.interp(u_top, u_f[order], F_f[order]))
    return u_dep, ratio


def figure(c: dict, f: dict, d: float, args, title: str) -> None:
    fig, axes = _common.new_figure((11.0, 4.2), ncols=2)
    ax = axes[0]
    k = len(f["u"]) if f["crossing"] is None else f["crossing"] + 1
    ax.plot(f["u"][:k], f["F"][:k], color="0.5", lw=1.2, label="no contact")
    if k < len(f["u"]):  # beyond its first crossing the contact-free path is not physical
        ax.plot(f["u"][k - 1:], f["F"][k - 1:], color="0.5", lw=0.8, ls=":",
                label="no contact, after strands cross a surface")
        ax.plot(f["u"][k - 1], f["F"][k - 1], "x", color="0.3", ms=6)
    ax.plot(c["u"], c["F"], color="C0", lw=1.6, label="contact with probe face and substrate")
    ax.set_xlabel("probe displacement u (µm)")
    ax.set_ylabel("probe force (pN)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    ax2 = ax.twinx()
    ax2.plot(c["u"], c["count"], color="C3", lw=0.9, ls="--")
    ax2.set_ylim(0, max(1, int(np.max(c["count"]))) * 1.1)
    ax2.yaxis.get_major_locator().set_params(integer=True)
    ax2.set_ylabel("contacts carrying force (dashed)", color="C3")
    ax = axes[1]
    gap = np.where(np.isfinite(c["min_gap"]), c["min_gap"], np.nan) * 1e3
    ax.plot(c["u"], gap, ".", ms=3, color="C0")
    ax.axhline(-0.01 * d * 1e3, color="C3", lw=0.8, ls="--", label="bound: −1 % of d")
    ax.axhline(0.1 * d * 1e3, color="0.4", lw=0.8, ls=":", label="activation δ = d/10 (force on below)")
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_yscale("symlog", linthresh=0.1)
    ax.set_xlabel("probe displacement u (µm)")
    ax.set_ylabel("smallest surface gap (nm)")
    ax.set_title("smallest gap to the probe face or substrate", fontsize=9)
    ax.legend(fontsize=8)
    _common.save_figure(fig, args.out, "contact_outcrop")


def main(argv=None) -> int:
    args = _common.parse_args(__doc__, argv)
    generations, U = (6, 1.5) if args.quick else (8, 3.0)
    net = sj.dendritic_outcrop(generations=generations, gap=6.0, seed=0)
    contact = sj.Contact(self_contact=False)
    print(f"{generations}-generation outcrop: {net.n_segments} segments; {U} µm and back", flush=True)
    c = run(net, U, contact)
    f = run(net, U, None)
    u_dep, ratio = departure(c, f)
    _common.print_table(["quantity", "with contact", "without"], [
        ["path", f"{c['status']}, {c['steps']} steps", f"{f['status']}, {f['steps']} steps"],
        ["Newton iterations", c["newton_iterations"], f["newton_iterations"]],
        ["wall time, first call (s)", f"{c['wall_s']:.0f}", f"{f['wall_s']:.0f}"],
        ["time per Newton iteration (s)", f"{c['s_per_iteration']:.3f}", f"{f['s_per_iteration']:.3f}"],
        ["most contacts at once", int(np.max(c["count"])), "—"],
        ["smallest gap (nm; bound −0.07)", f"{np.nanmin(c['min_gap']) * 1e3:.3f}", "—"],
        ["forces differ by > 1 % from u (µm)", f"{u_dep:.3f}", ""],
        ["force ratio at the deepest common u", f"{ratio:.3f}", ""],
    ], title=f"{generations}-generation outcrop, {U} µm and back")
    figure(c, f, contact.diameter, args, f"{generations}-generation outcrop ({net.n_segments} segments), "
           f"{U} µm and back")
    _common.write_json(args.out, "contact_outcrop", args, {
        "generations": generations, "displacement_um": U, "segments": net.n_segments,
        "departure_u_um": u_dep, "force_ratio": ratio, "contact": c, "free": f,
        "wall_ratio": c["wall_s"] / f["wall_s"],
        "iteration_time_ratio": c["s_per_iteration"] / f["s_per_iteration"]})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
