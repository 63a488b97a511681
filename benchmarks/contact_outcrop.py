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
runs.  How much is counted (:func:`strand_overlaps`, third panel): at every recorded step
the segment pairs whose centre lines come closer than d, and the deepest overlap.  The
as-built 8-generation outcrop (seed 0) already has one: the centre lines of segments 162
and 487, of different strands, pass 1.2 nm apart.

Writes ``contact_outcrop.json`` and ``contact_outcrop.png``.

Run:  PYTHONPATH=. python benchmarks/contact_outcrop.py [--quick] [--out DIR]
(default: 8 generations, 6 µm gap, 3 µm and back, 2026-12-08 on 2 cores, after fast returns
to the step size past the path's corners: with contact completed, 238 steps, 1,159 Newton
iterations, 494 s first call against 48 s without (10.3×; before that change 271 steps,
1,338 iterations, 598 s against 53 s; 625 s on 2026-12-07, 1,519 s before the near list of
``Contact(slot_capacity=...)``), up to 27 contacts, smallest gap
+0.664 nm, force 1.51× the contact-free one at 3 µm, up to 7 pairs of segments that share
no node closer than d at one step, the deepest 6.99 nm (centre lines crossing); without,
53 s, strands crossing the surfaces from u = 0.342 µm (dotted in the figure from there); --quick: 6
generations, 1.5 µm and back, 2026-12-08 on 2 cores: with contact completed, 237 steps, 505
Newton iterations, 171 s first call (179 steps and 427 iterations after the fast returns,
timed beside another run), at most 3 contacts, smallest gap
+0.687 nm, force 1.04× at 1.5 µm, up to 2 segment pairs closer than d (deepest 5.68 nm);
without, 23 s, crossing from u = 1.044 µm).
"""

from __future__ import annotations

import time

import _common  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads)
import jax
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
    pairs, depth = strand_overlaps(res, contact.diameter) if contact is not None else (None, None)
    return {"overlap_pairs": pairs, "overlap_depth": depth, "status": res.status_message.split(":")[0], "completed": bool(res.completed), "steps": int(res.n_steps),
            "newton_iterations": iterations, "wall_s": wall, "s_per_iteration": wall / max(iterations, 1),
            "u": np.asarray(res.displacement), "F": np.asarray(res.force), "phase": np.asarray(res.phase),
            "crossing": None if res.first_crossing is None else int(res.first_crossing.step),
            "count": None if contact is None else np.asarray(res.contact_count),
            "min_gap": None if contact is None else np.asarray(res.min_gap)}


def _piece_distances(p1, q1, p2, q2):
    """Exact distances [M] between the straight pieces p1–q1 and p2–q2 ([M, 3] each, µm)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e = np.einsum("ij,ij->i", d1, d1), np.einsum("ij,ij->i", d2, d2)
    b, c, f = np.einsum("ij,ij->i", d1, d2), np.einsum("ij,ij->i", d1, r), np.einsum("ij,ij->i", d2, r)
    denom = a * e - b * b
    s = np.where(denom > 1e-14 * a * e, np.clip((b * f - c * e) / np.where(denom > 0, denom, 1.0), 0.0, 1.0), 0.0)
    t = (b * s + f) / e
    s = np.where(t < 0.0, np.clip(-c / a, 0.0, 1.0), np.where(t > 1.0, np.clip((b - c) / a, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(p1 + s[:, None] * d1 - p2 - t[:, None] * d2, axis=1)


def strand_overlaps(res, d: float, points: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Per recorded step: (segment pairs whose centre lines come closer than the diameter d,
    deepest such overlap d − distance in µm, 0 where none).  Without filament–filament
    contact nothing keeps strands apart; this counts where they overlap at the recorded
    steps (a strand that passed through another between two steps is not counted).  Centre
    lines: ``sj.filament_curve`` of the nodal state at ``points`` points per segment (the
    contact-free interpolant: a surface contact's point force bends its segment slightly
    differently), exact distances between the straight pieces (scipy KD-tree broad phase).
    Segments that share a node (junction daughters: their mother node) are skipped."""
    from scipy.spatial import cKDTree

    net = res.network
    node_of = np.asarray(net.attach)[np.asarray(net.segments)]  # [S, 2]
    curve = jax.jit(lambda r, t, m, n: sj.filament_curve(net, r, t, m, n, points_per_segment=points).positions)
    count, deepest = np.zeros(len(res.displacement), int), np.zeros(len(res.displacement))
    for k in range(len(res.displacement)):
        P = np.asarray(curve(res.positions[k], res.tangents[k], res.moments[k], res.segment_forces[k]))
        start, end = P[:, :-1].reshape(-1, 3), P[:, 1:].reshape(-1, 3)
        owner = np.repeat(np.arange(P.shape[0]), points - 1)
        reach = np.linalg.norm(end - start, axis=1).max() + d
        pairs = cKDTree(0.5 * (start + end)).query_pairs(reach, output_type="ndarray")
        i, j = owner[pairs[:, 0]], owner[pairs[:, 1]]
        apart = (i != j) & ~np.any(node_of[i][:, :, None] == node_of[j][:, None, :], axis=(1, 2))
        pairs, i, j = pairs[apart], i[apart], j[apart]
        dist = _piece_distances(start[pairs[:, 0]], end[pairs[:, 0]], start[pairs[:, 1]], end[pairs[:, 1]])
        close = dist < d
        if close.any():
            count[k] = len({(min(a, b), max(a, b)) for a, b in zip(i[close], j[close])})
            deepest[k] = d - dist[close].min()
    return count, deepest


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
    fig, axes = _common.new_figure((16.0, 4.2), ncols=3)
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
    ax = axes[2]  # what the surfaces-only contact leaves out
    ax.plot(c["u"], c["overlap_pairs"], ".", ms=3, color="C1")
    ax.set_xlabel("probe displacement u (µm)")
    ax.set_ylabel("segment pairs closer than d", color="C1")
    ax.yaxis.get_major_locator().set_params(integer=True)
    ax.set_title("strands through each other (no filament–filament contact here)", fontsize=9)
    ax3 = ax.twinx()
    ax3.plot(c["u"], c["overlap_depth"] * 1e3, ".", ms=2, color="C4")
    ax3.set_ylabel("deepest overlap d − distance (nm)", color="C4")
    ax3.set_ylim(0, d * 1e3 * 1.05)
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
        ["strand pairs closer than d, most at one step", int(np.max(c["overlap_pairs"])), "—"],
        ["deepest strand overlap (nm)", f"{np.max(c['overlap_depth']) * 1e3:.2f}", "—"],
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
