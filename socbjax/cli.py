"""Command line: ``socbjax demo | simulate | plot | fit`` (also ``python -m socbjax ...``).

Units everywhere: µm, pN, s; EI in pN·µm²; angles in degrees on the command line.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ._cli_fit import add_fit_parser, run_fit

__all__ = ["main"]

_DEFAULT_DISPLACEMENT = {"unit-mesh": 0.6, "outcrop": 3.0, "column": None}


def _add_demo(sub) -> None:
    demo = sub.add_parser(
        "demo",
        help="run the cantilever and buckling validations, print the table, write a figure",
        description="Cantilever (paper Fig. 4A) and buckling (Fig. 5c) validations against the exact "
        "elastica and Euler loads; writes demo.json and demo.png.",
    )
    demo.add_argument("--out", default="socbjax-demo", help="output folder (default: ./socbjax-demo)")
    demo.add_argument("--quick", action="store_true", help="fewer node counts (faster smoke run)")


def _add_simulate(sub) -> None:
    sim = sub.add_parser(
        "simulate",
        help="compress a network with the probe (and withdraw it), write the path to HDF5",
        description="Displacement-controlled compression of a unit dendritic mesh (paper Fig. 6), a "
        "dendritic actin outcrop (Fig. 7) or a single column (Fig. 5d); writes every step to an HDF5 "
        "file readable with socbjax.load, and optionally the figures.",
    )
    sim.add_argument("network", choices=["unit-mesh", "outcrop", "column"], help="what to compress")
    sim.add_argument("--out", required=True, help="output HDF5 file (written atomically), e.g. run.h5")
    sim.add_argument(
        "--displacement",
        type=float,
        default=None,
        help="total probe travel in µm (default: unit-mesh 0.6, outcrop 3.0, column 0.3 × length)",
    )
    sim.add_argument(
        "--no-unload",
        dest="unload",
        action="store_false",
        help="stop at the maximum displacement (default: withdraw the probe back)",
    )
    sim.add_argument(
        "--method",
        choices=["arclength", "displacement"],
        default="arclength",
        help="path following: pseudo-arclength (follows folds; default) or displacement control",
    )
    sim.add_argument(
        "--EI", type=float, default=None, help="bending stiffness in pN·µm² (default: actin 0.071; column 1.0)"
    )
    sim.add_argument("--branch-angle", type=float, default=70.0, help="daughter–mother angle in degrees (default 70)")
    sim.add_argument("--generations", type=int, default=8, help="outcrop: branching generations (default 8)")
    sim.add_argument("--gap", type=float, default=6.0, help="outcrop: probe–surface gap in µm (default 6)")
    sim.add_argument("--growth", type=float, default=1.0, help="outcrop: growth per generation in µm (default 1)")
    sim.add_argument("--segment-length", type=float, default=0.5, help="segment length in µm (default 0.5)")
    sim.add_argument("--seed", type=int, default=0, help="random seed of the outcrop's branch azimuths (default 0)")
    sim.add_argument(
        "--perturbation",
        type=float,
        default=None,
        help="lateral force on the middle of each strand in pN (default: the builder's, or 1e-4 EI/L²)",
    )
    sim.add_argument("--dim", type=int, choices=[2, 3], default=3, help="2 (planar) or 3 (spatial; default)")
    sim.add_argument("--nodes", type=int, default=9, help="column: number of nodes (default 9)")
    sim.add_argument("--length", type=float, default=1.0, help="column: length in µm (default 1)")
    sim.add_argument(
        "--supports",
        default="pinned,pinned",
        help="column: supports of first,last node among clamped/pinned/free (default pinned,pinned)",
    )
    sim.add_argument(
        "--max-step", type=float, default=None, help="largest continuation step in µm (default 0.05, ≤ displacement/4)"
    )
    sim.add_argument(
        "--linear-solver",
        choices=["auto", "dense", "sparse"],
        default="auto",
        help="Newton linear algebra (auto: sparse LU above 1500 unknowns)",
    )
    sim.add_argument(
        "--checkpoint-every", type=int, default=50, help="write OUT.ckpt.h5 every N accepted steps (default 50)"
    )
    sim.add_argument("--resume", action="store_true", help="continue an interrupted run from OUT.ckpt.h5")
    sim.add_argument("--figures", default=None, help="also write the figures (PNG) into this folder")
    sim.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_plot(sub) -> None:
    plot = sub.add_parser(
        "plot",
        help="write the figures of a simulate run",
        description="Force–compression curve (loading and unloading), network snapshots, "
        "strand-end force curves and the Fig. 7d-like scatter, as PNG files.",
    )
    plot.add_argument("run", help="HDF5 file written by 'socbjax simulate'")
    plot.add_argument("--out", default=None, help="output folder (default: next to RUN, RUN without .h5 + '-figures')")
    plot.add_argument("--steps", default=None, help="comma-separated step indices for the snapshots and scatter")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="socbjax",
        description="SOCB simulator of slender elastic filaments (units: µm, pN, s; EI in pN·µm²). Compiled "
        "programs are cached in ~/.cache/socbjax/jax (set SOCBJAX_CACHE_DIR to another folder, or to off).",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    _add_demo(sub)
    _add_simulate(sub)
    _add_plot(sub)
    add_fit_parser(sub)
    return parser


def _build(args):
    """(network, parameters, default displacement) for ``socbjax simulate``."""
    import socbjax as sj

    if args.network == "column":
        supports = tuple(s.strip() for s in args.supports.split(","))
        EI = 1.0 if args.EI is None else args.EI
        net = sj.column(args.nodes, length=args.length, EI=EI, supports=supports, dim=args.dim)
        params = dict(
            network="column", nodes=args.nodes, length_um=args.length, EI=EI, supports=list(supports), dim=args.dim
        )
        return net, params, 0.3 * args.length
    EI = 0.071 if args.EI is None else args.EI
    pert = {} if args.perturbation is None else {"perturbation": args.perturbation}
    if args.network == "unit-mesh":
        net = sj.unit_dendritic_mesh(EI=EI, branch_angle=args.branch_angle, dim=args.dim, **pert)
        params = dict(network="unit-mesh", EI=EI, branch_angle=args.branch_angle, dim=args.dim, **pert)
    else:
        net = sj.dendritic_outcrop(
            generations=args.generations,
            gap=args.gap,
            growth=args.growth,
            segment_length=args.segment_length,
            branch_angle=args.branch_angle,
            EI=EI,
            seed=args.seed,
            dim=args.dim,
            **pert,
        )
        params = dict(
            network="outcrop",
            generations=args.generations,
            gap_um=args.gap,
            growth_um=args.growth,
            segment_length_um=args.segment_length,
            branch_angle=args.branch_angle,
            EI=EI,
            seed=args.seed,
            dim=args.dim,
            **pert,
        )
    return net, params, _DEFAULT_DISPLACEMENT[args.network]


def _simulate(args) -> int:
    import socbjax as sj

    out = Path(args.out)
    if not out.parent.exists():
        raise SystemExit(f"socbjax simulate: the folder of --out does not exist: {out.parent}")
    net, params, default_u = _build(args)
    displacement = default_u if args.displacement is None else args.displacement
    steps = {} if args.max_step is None else dict(max_step=args.max_step, initial_step=min(0.02, args.max_step))
    settings = sj.PathSettings(linear_solver=args.linear_solver, **steps)
    checkpoint = out.with_name(out.name + ".ckpt.h5")
    print(
        f"socbjax simulate {args.network}: {net.n_nodes} nodes, {net.n_segments} segments, "
        f"{net.n_junctions} junctions; probe travel {displacement} µm{' and back' if args.unload else ''}",
        file=sys.stderr,
    )
    result = sj.compress(
        net,
        displacement,
        unload=args.unload,
        method=args.method,
        perturbation=args.perturbation,
        settings=settings,
        progress=not args.quiet,
        checkpoint=sj.Checkpoint(checkpoint, every=args.checkpoint_every, resume=args.resume),
        throw=False,
        parameters=params,
    )
    sj.save(result, out)
    if result.completed and checkpoint.exists():
        checkpoint.unlink()
    if args.figures:
        sj.save_figures(result, args.figures)
    print(f"{out}: {result.summary()}")
    return 0 if result.completed else 1


def _plot(args) -> int:
    import socbjax as sj

    result = sj.load(args.run)
    out = Path(args.out) if args.out else Path(args.run).with_suffix("").with_name(Path(args.run).stem + "-figures")
    steps = None if args.steps is None else [int(s) for s in args.steps.split(",")]
    for path in sj.save_figures(result, out, steps=steps):
        print(path)
    return 0


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from ._cache import enable_compilation_cache

    enable_compilation_cache()  # a second run of the same network does not recompile ($SOCBJAX_CACHE_DIR, "off")
    if args.command == "demo":
        from ._demo import run_demo

        run_demo(args.out, quick=args.quick)
        return 0
    if args.command == "simulate":
        return _simulate(args)
    if args.command == "plot":
        return _plot(args)
    if args.command == "fit":
        try:
            return run_fit(args)
        except (ValueError, FileNotFoundError, ImportError) as err:
            raise SystemExit(f"socbjax fit: {err}") from None
    return 2  # pragma: no cover - argparse enforces the choices


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
