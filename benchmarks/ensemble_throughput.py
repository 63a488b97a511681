"""Ensemble throughput (issue: "a batch of 64 outcrop compressions vmapped runs at higher
throughput than 64 sequential runs; sharded over 2 host devices gives the same numbers").

One small 3-D dendritic outcrop (3 generations, gap 3 µm) compressed by 0.5 µm and withdrawn,
under 64 random imperfection patterns (lateral 1e-4 pN per strand, directions from seeds
0..63).  Timed after compilation, in curves per second:

(a) 64 sequential ``socbjax.compress`` calls (a first pass compiles everything, including
    the per-path-length result observation; the second pass is timed);
(b) one ``socbjax.compress_ensemble`` of the 64 (sparse LU; and dense LU on a subset);
(c) the same ensemble sharded over 2 host devices (a subprocess with
    ``XLA_FLAGS=--xla_force_host_platform_device_count=2``), compared number for number
    with (b).

Why batching gains little or much is measured, not guessed: every SuperLU factorisation
runs on the host inside a ``jax.pure_callback`` (one callback call factors every batched
member); the factorisation itself (``socbjax._linear.factor_solve``, internal) is wrapped
here to count factorisations and their host seconds, and so are the compiled path loops
(``socbjax._protocol._chunk`` of ``compress``, ``socbjax._ensemble._phase`` of
``compress_ensemble``, private), to time what runs inside them.  Sequential runs factor only
what each path needs; the vmapped loop factors every member's Jacobian on every batched
Newton iteration until its slowest member is done, so (batched factorisations − sequential
factorisations) / batched factorisations is the fraction of member-iterations spent idle.
The rest of the time (JVPs, the while-loop machinery) is what vmap amortises: its cost per
batched iteration is compared with B × the cost per single iteration.

Run:  PYTHONPATH=. python benchmarks/ensemble_throughput.py [--quick] [--out DIR]
(--quick: a 2-D 3-generation outcrop, 8 members under 8 EI values, no dense run: a smoke
test under a minute.)
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import _common  # (sets OPENBLAS_NUM_THREADS before numpy loads)
import numpy as np

import socbjax as sj
from socbjax import _ensemble, _linear, _protocol

LU = {"calls": 0, "seconds": 0.0, "compiled_s": 0.0}
_factor_solve = _linear.factor_solve


def _counted_factor_solve(*args, **kwargs):  # one SuperLU factorisation (+ solve) on the host, counted
    t0 = time.perf_counter()
    try:
        return _factor_solve(*args, **kwargs)
    finally:
        LU["calls"] += 1
        LU["seconds"] += time.perf_counter() - t0


_linear.factor_solve = _counted_factor_solve  # looked up by the host callback at call time


def _in_compiled(fn):  # time spent in the compiled phases (the rest is host-side set-up and results)
    def timed(*args, **kwargs):
        import jax

        t0 = time.perf_counter()
        out = jax.block_until_ready(fn(*args, **kwargs))
        LU["compiled_s"] += time.perf_counter() - t0
        return out

    return timed


_protocol._chunk, _ensemble._phase = map(_in_compiled, (_protocol._chunk, _ensemble._phase))


def members(quick: bool):
    if quick:
        net = sj.dendritic_outcrop(generations=3, gap=3.0, seed=0, dim=2, perturbation=0.0)
        return [net.replace(EI=net.EI * s) for s in np.linspace(0.5, 2.0, 8)]
    net = sj.dendritic_outcrop(generations=3, gap=3.0, seed=0, dim=3, perturbation=0.0, GJ=None)  # as measured: torsion-free
    return [net.replace(loads=sj.strand_perturbation(net, 1e-4, seed=k)) for k in range(64)]


SETTINGS = sj.PathSettings(max_steps=200)
DISPLACEMENT = 0.45  # µm: below the first surface crossing of the 2-D members (u ≈ 0.47 µm; no contact model yet)


def options(linear_solver: str) -> dict:
    return dict(unload=True, settings=SETTINGS.replace(linear_solver=linear_solver))


def _timed(fn):
    """(fn(), wall s, sparse-LU counts with the process CPU seconds of the call)."""
    LU.update(calls=0, seconds=0.0, compiled_s=0.0)
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - t0, dict(LU, cpu_s=time.process_time() - c0)


def sequential(nets) -> dict:
    run = lambda: [sj.compress(n, DISPLACEMENT, **options("sparse")) for n in nets]
    _, first_one, _ = _timed(lambda: sj.compress(nets[0], DISPLACEMENT, **options("sparse")))
    _, first_pass, _ = _timed(run)
    results, wall, lu = _timed(run)
    return dict(first_call_s=first_one, first_pass_s=first_pass, wall_s=wall, lu=lu, results=results,
                iterations=int(sum(r.iterations.sum() for r in results)), steps=[r.n_steps for r in results])


def ensemble(nets, linear_solver: str, devices=None) -> dict:
    run = lambda: sj.compress_ensemble(nets, DISPLACEMENT, devices=devices, **options(linear_solver))
    _, first, _ = _timed(run)
    result, wall, lu = _timed(run)
    return dict(first_call_s=first, wall_s=wall, lu=lu, result=result, devices=list(result.devices))


def sharded_worker(path: Path) -> int:
    """Child process (2 host devices): the sharded ensemble, timed; forces written to ``path``."""
    import jax

    nets = members("--quick" in sys.argv)
    row = ensemble(nets, "sparse", devices=jax.devices())
    ens = row.pop("result")
    np.savez(path, force=ens.force, displacement=ens.displacement, n_steps=ens.n_steps, completed=ens.completed)
    print("RESULT " + json.dumps(dict(row, n_devices=len(jax.devices()))))
    return 0


def run_sharded(quick: bool, out: Path) -> dict:
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", OPENBLAS_NUM_THREADS="1")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(Path(__file__).resolve().parents[1]), env.get("PYTHONPATH")]))
    npz = out / "_ensemble_sharded.npz"
    cmd = [sys.executable, __file__, "--sharded-worker", str(npz)] + (["--quick"] if quick else [])
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, check=False, env=env, capture_output=True, text=True, timeout=900)
    if proc.returncode:
        raise RuntimeError(f"sharded worker failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}")
    row = json.loads(next(line[7:] for line in proc.stdout.splitlines() if line.startswith("RESULT ")))
    data = dict(np.load(npz))
    npz.unlink()
    return dict(row, process_s=time.perf_counter() - t0, **data)


def _rates(B, row):
    return B / row["wall_s"]


def analyse(B, seq, ens) -> dict:
    """Per-iteration costs and idle members (from the counted sparse factorisations and the
    members' attempted steps per phase)."""
    attempts = ens["result"].attempts  # [B, phases]
    outer_idle = 1.0 - attempts.sum() / (B * attempts.max(axis=0).sum())
    loop_seq, loop_ens = seq["lu"]["compiled_s"], ens["lu"]["compiled_s"]  # seconds inside the compiled phases
    per_single = loop_seq / seq["lu"]["calls"]  # one member, one factorisation (a Newton iteration; its tangent reuses it)
    batched_iters = ens["lu"]["calls"] / B  # every batched solve factors all B members
    per_batched = loop_ens / batched_iters
    non_lu_single = (loop_seq - seq["lu"]["seconds"]) / seq["lu"]["calls"]
    non_lu_batched = (loop_ens - ens["lu"]["seconds"]) / batched_iters
    return {
        "solves_sequential": seq["lu"]["calls"],
        "solves_batched_member": ens["lu"]["calls"],
        "batched_iterations": batched_iters,
        "idle_member_fraction": 1.0 - seq["lu"]["calls"] / ens["lu"]["calls"],
        "idle_fraction_from_unequal_attempts": outer_idle,
        "attempts_per_member_min_max": [int(attempts.sum(1).min()), int(attempts.sum(1).max())],
        "ms_per_single_iteration": 1e3 * per_single,
        "ms_per_batched_iteration": 1e3 * per_batched,
        "batched_over_B_single": per_batched / (B * per_single),
        "ms_lu_host_per_member_solve_sequential": 1e3 * seq["lu"]["seconds"] / seq["lu"]["calls"],
        "ms_lu_host_per_member_solve_batched": 1e3 * ens["lu"]["seconds"] / ens["lu"]["calls"],
        "ms_non_lu_per_single_iteration": 1e3 * non_lu_single,
        "ms_non_lu_per_batched_iteration": 1e3 * non_lu_batched,
        "non_lu_batched_over_B_single": non_lu_batched / (B * non_lu_single),
        "host_overhead_s_sequential": seq["wall_s"] - loop_seq,
        "host_overhead_s_batched": ens["wall_s"] - loop_ens,
        "lu_host_fraction_sequential": seq["lu"]["seconds"] / seq["wall_s"],
        "lu_host_fraction_batched": ens["lu"]["seconds"] / ens["wall_s"],
        "cores_busy_sequential": seq["lu"]["cpu_s"] / seq["wall_s"],
        "cores_busy_batched": ens["lu"]["cpu_s"] / ens["wall_s"],
    }


def _worst(rel, ens) -> dict:
    """Where two ensembles' forces differ most (relative to max |F|), and the median difference."""
    b, k = np.unravel_index(np.nanargmax(rel), rel.shape)
    return dict(median=float(np.nanmedian(rel)), member=int(b), step=int(k), phase=int(ens.phase[b, k]),
                u_um=float(ens.displacement[b, k]), force_pN=float(ens.force[b, k]))


def figure(displacement, force, rows, member_EI=None):
    """Left: the force curves of all members (probe displacement µm [B, K], force pN [B, K])
    from one vmapped run, coloured by the members' EI (pN·µm², ``member_EI`` [B]) when they
    differ in it, else by member; right: force curves per second of each mode (``rows``:
    dicts with "mode" and "curves_per_s").  Agg figure, no pyplot."""
    import matplotlib
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    fig, (ax, bx) = _common.new_figure((10.5, 3.9), ncols=2)
    B = len(force)
    by_EI = member_EI is not None and np.ptp(member_EI) > 0
    values = np.asarray(member_EI, float) if by_EI else np.arange(B, dtype=float)
    norm = Normalize(values.min(), max(values.max(), values.min() + 1e-12))
    cmap = matplotlib.colormaps["viridis"]
    for b in range(B):
        ax.plot(displacement[b], force[b], lw=0.8, color=cmap(norm(values[b])))
    fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, pad=0.01,
                 label="member EI (pN·µm²)" if by_EI else "member")
    ax.set(xlabel="probe displacement u (µm)", ylabel="probe force F (pN, compressive +)",
           title=f"{B} members, one vmapped run (loading and unloading)")
    labels = [r["mode"] for r in rows]
    bx.barh(labels, [r["curves_per_s"] for r in rows], color="C0")
    bx.invert_yaxis()  # the modes top to bottom in the order measured
    bx.set(xlabel="force curves per second (after compilation)", title="throughput")
    return fig


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if "--sharded-worker" in argv:
        return sharded_worker(Path(argv[argv.index("--sharded-worker") + 1]))
    args = _common.parse_args(__doc__, argv)
    nets = members(args.quick)
    B, n_dense = len(nets), 0 if args.quick else 8
    print(f"{B} members: {nets[0].dim}-D outcrop, {nets[0].n_nodes} nodes, {nets[0].n_segments} segments; "
          f"compress {DISPLACEMENT} µm and back", flush=True)
    seq = sequential(nets)
    print(f"sequential: {seq['wall_s']:.1f} s (first call {seq['first_call_s']:.1f} s, first pass {seq['first_pass_s']:.1f} s)", flush=True)
    ens = ensemble(nets, "sparse")
    print(f"vmapped: {ens['wall_s']:.1f} s (first call {ens['first_call_s']:.1f} s)", flush=True)
    dense = ensemble(nets[:n_dense], "dense") if n_dense else None
    shard = run_sharded(args.quick, args.out)
    print(f"sharded: {shard['wall_s']:.1f} s over {shard['devices']}", flush=True)

    ref = np.array([np.pad(r.force, (0, ens["result"].force.shape[1] - r.n_steps), constant_values=np.nan) for r in seq["results"]])
    scale = np.nanmax(np.abs(ref))
    same_steps = bool(np.array_equal(ens["result"].n_steps, seq["steps"]) and np.array_equal(shard["n_steps"], seq["steps"]))
    diff_seq = float(np.nanmax(np.abs(ens["result"].force - ref)) / scale) if same_steps else None
    diff_shard = float(np.nanmax(np.abs(shard["force"] - ens["result"].force)) / scale) if same_steps else None
    where = _worst(np.abs(shard["force"] - ens["result"].force) / scale, ens["result"]) if same_steps else None
    rows = [
        dict(mode="sequential (sparse)", members=B, wall_s=seq["wall_s"], first_s=seq["first_call_s"], curves_per_s=_rates(B, seq)),
        dict(mode="vmapped (sparse)", members=B, wall_s=ens["wall_s"], first_s=ens["first_call_s"], curves_per_s=_rates(B, ens)),
        dict(mode="sharded 2 dev (sparse)", members=B, wall_s=shard["wall_s"], first_s=shard["first_call_s"], curves_per_s=_rates(B, shard)),
    ]
    if dense:
        rows.insert(2, dict(mode="vmapped (dense)", members=n_dense, wall_s=dense["wall_s"], first_s=dense["first_call_s"],
                            curves_per_s=_rates(n_dense, dense)))
    for r, src in zip(rows, [seq, ens] + ([dense] if dense else []) + [shard]):
        r["compile_s"] = r["first_s"] - (r["wall_s"] if "sequential" not in r["mode"] else r["wall_s"] / B)
        r.update(cores_busy=src["lu"]["cpu_s"] / src["wall_s"], lu_calls=src["lu"]["calls"], lu_host_s=src["lu"]["seconds"],
                 compiled_s=src["lu"]["compiled_s"], host_s=src["wall_s"] - src["lu"]["compiled_s"])
    _common.print_table(["mode", "members", "first call s", "≈compile s", "run s", "in loops s", "host s", "LU host s",
                         "cores busy", "curves/s"],
                        [[r["mode"], r["members"], r["first_s"], r["compile_s"], r["wall_s"], r["compiled_s"], r["host_s"],
                          r["lu_host_s"], r["cores_busy"], r["curves_per_s"]] for r in rows],
                        title="Throughput after compilation", spec=".2f")
    why = analyse(B, seq, ens)
    ratio = rows[1]["curves_per_s"] / rows[0]["curves_per_s"]
    print(f"\nvmapped / sequential throughput: {ratio:.2f}×;  sharded(2) / vmapped: {rows[-1]['curves_per_s'] / rows[1]['curves_per_s']:.2f}×")
    print(f"max |F_vmapped − F_sequential| / max|F| = {diff_seq};  max |F_sharded − F_vmapped| / max|F| = {diff_shard} "
          f"(same steps: {same_steps})")
    print(f"sharded vs unsharded: median {where['median']:.2e}; largest at member {where['member']}, step {where['step']} "
          f"(phase {where['phase']}, u = {where['u_um']:.3g} µm)" if where else "")
    _common.print_table(["quantity", "value"], [[k, v] for k, v in why.items()], title="Where the time goes (sparse LU counted)", spec=".4g")
    member_EI = [float(np.asarray(net.EI).mean()) for net in nets]
    _common.save_figure(figure(ens["result"].displacement, ens["result"].force, rows, member_EI), args.out,
                        "ensemble_throughput")
    payload = dict(displacement_um=DISPLACEMENT, members=B, network=dict(dim=nets[0].dim, nodes=nets[0].n_nodes,
                   segments=nets[0].n_segments), max_steps=SETTINGS.max_steps, rows=rows,
                   throughput_ratio_vmapped_over_sequential=ratio, same_steps=same_steps,
                   max_rel_force_diff_vmapped_vs_sequential=diff_seq, max_rel_force_diff_sharded_vs_unsharded=diff_shard,
                   sharded_devices=shard["devices"], sharded_difference_location=where, analysis=why, load_average=os.getloadavg(),
                   steps=dict(min=int(min(seq["steps"])), max=int(max(seq["steps"])), mean=float(np.mean(seq["steps"]))))
    _common.write_json(args.out, "ensemble_throughput", args, payload)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
