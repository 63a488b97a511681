"""Command line: ``socbjax demo | simulate | plot | fit | examples`` (also ``python -m socbjax ...``).

Units everywhere: µm, pN, s; EI in pN·µm²; angles in degrees on the command line.

Only the standard library is imported at module level and before the arguments are parsed
and checked: ``--help`` and argument errors answer at once, JAX (seconds to import) and the
solver load only for a command that runs.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
from pathlib import Path

from ._cli_fit import add_fit_parser  # stdlib only at module level (socbjax fit's parser)
from ._progress import plural  # stdlib only

__all__ = ["main", "build_parser"]

# Defaults stop before the first node crosses the surface (without --contact): the unit mesh's mother at
# u ≈ 0.44 µm, the default 8-generation outcrop (seed 0) at u ≈ 0.34 µm (both with actin's twist).
_DEFAULT_DISPLACEMENT = {"unit-mesh": 0.35, "outcrop": 0.2, "column": None}
# The column's supports (socbjax.SUPPORTS, here without importing the solver); its default is
# fit's: a clamped–pinned column (Euler load 20.19 EI/L²) crosses the surface at u ≈ 0.39 L,
# after the default travel of 0.3 L.
_SUPPORT_KINDS = ("clamped", "pinned", "free")
_DEFAULT_SUPPORTS = "clamped,pinned"


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
        help="total probe travel in µm (default: unit-mesh 0.35, outcrop 0.2, column 0.3 × length: before any node crosses the surface)",
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
    sim.add_argument(
        "--GJ",
        default=None,
        help="torsional stiffness in pN·µm² (3D networks; default: actin 8e-3 for unit-mesh and outcrop, Tsuda et al. "
        "1996; torsion-free for a column), or 'none' for the paper's torsion-free model (about half the run time; "
        "branch junctions then drop the moment about the mother's axis)",
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
    sim.add_argument(
        "--dim",
        type=int,
        choices=[2, 3],
        default=3,
        help="3 (spatial; the default for every network, as for every builder and fit model) or 2 (planar, opt-in: "
        "faster to compile and run)",
    )
    sim.add_argument("--nodes", type=int, default=9, help="column: number of nodes (default 9)")
    sim.add_argument("--length", type=float, default=1.0, help="column: length in µm (default 1)")
    sim.add_argument(
        "--supports",
        default=_DEFAULT_SUPPORTS,
        help=f"column: supports of the first,last node, each one of {', '.join(_SUPPORT_KINDS)} "
        f"(default {_DEFAULT_SUPPORTS})",
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
    sim.add_argument(
        "--contact",
        action=argparse.BooleanOptionalAction,
        default=False,
        help="contact with the probe face and the substrate (rigid frictionless planes), and between filaments "
        "in planar networks (--dim 2; 3D: the surfaces only, since 3D filament-filament contact costs about 10 s "
        "per path step on a 6-generation outcrop: use socbjax.compress(..., contact=socbjax.Contact()) with "
        "dendritic_outcrop(clearance=0.007) for it) (default: --no-contact)",
    )
    sim.add_argument("--diameter", type=float, default=0.007, help="filament diameter for --contact in µm (default 0.007)")
    sim.add_argument("--resume", action="store_true", help="continue an interrupted run from OUT.ckpt.h5")
    sim.add_argument("--figures", default=None, help="also write the figures (PNG) into this folder")
    sim.add_argument("--quiet", action="store_true", help="no progress bar")


def _add_examples(sub) -> None:
    ex = sub.add_parser(
        "examples",
        help="list the example AFM force curves shipped with socbjax, or print one's path",
        description="Real AFM force curves shipped as package data (from afmformats' test data, MIT/CC0): "
        "without NAME, one line per file (name, what it is, path); with NAME, only its path, for use as "
        'socbjax fit "$(socbjax examples NAME)" ...',
    )
    ex.add_argument("name", nargs="?", default=None, help="a file name from the list (prints its path)")


def _examples(args) -> int:
    from ._examples import example_descriptions, example_file, example_files

    if args.name is not None:
        print(example_file(args.name))  # ValueError (one line, exit 2) names the available files
        return 0
    for name, path in example_files().items():
        print(f"{name}\n    {example_descriptions()[name]}\n    {path}")
    print("read them with socbjax.load_curve or socbjax fit (JPK, Asylum and .tab files need: pip install \".[afm]\")")
    return 0


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
    parser.add_argument("--debug", action="store_true", help="show Python tracebacks for errors (default: one line)")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_demo(sub)
    _add_simulate(sub)
    _add_plot(sub)
    add_fit_parser(sub)
    _add_examples(sub)
    for command in sub.choices.values():  # --debug also after the command (SUPPRESS keeps the global one)
        command.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
    return parser


def _supports(text: str) -> tuple[str, str]:
    """``--supports first,last`` as a pair of support names (ValueError naming the fix)."""
    names = tuple(s.strip() for s in text.split(","))
    if len(names) != 2 or not all(n in _SUPPORT_KINDS for n in names):
        raise ValueError(f"--supports expects two comma-separated supports first,last, each one of "
                         f"{', '.join(_SUPPORT_KINDS)} (e.g. --supports {_DEFAULT_SUPPORTS}); got {text!r}")
    return names


def _check_simulate(args) -> None:
    """The values argparse cannot check, before anything is imported or computed."""
    if args.max_step is not None and not (math.isfinite(args.max_step) and args.max_step > 0):
        raise ValueError(f"--max-step must be a positive finite step in µm, got {args.max_step}")
    if args.checkpoint_every < 1:
        raise ValueError(f"--checkpoint-every must be a positive number of steps, got {args.checkpoint_every}")
    if args.network == "column":
        _supports(args.supports)
    _torsion(args.GJ)


def _torsion(text) -> dict:
    """Builder keywords for ``--GJ``: {} (the builder's default), {"GJ": None} or {"GJ": value}."""
    if text is None:
        return {}
    if text.strip().lower() == "none":
        return {"GJ": None}
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"--GJ must be a positive torsional stiffness in pN·µm² or 'none' (torsion-free), got {text!r}")
    return {"GJ": value}


def _build(args):
    """(network, parameters, default displacement) for ``socbjax simulate``."""
    import socbjax as sj

    if args.network == "column":
        supports = _supports(args.supports)
        EI = 1.0 if args.EI is None else args.EI
        net = sj.column(args.nodes, length=args.length, EI=EI, supports=supports, dim=args.dim, **_torsion(args.GJ))
        params = dict(
            network="column", nodes=args.nodes, length_um=args.length, EI=EI, supports=list(supports), dim=args.dim,
        )
        return net, _with_torsion(params, net), 0.3 * args.length
    EI = 0.071 if args.EI is None else args.EI
    pert = {} if args.perturbation is None else {"perturbation": args.perturbation}
    torsion = _torsion(args.GJ)
    if args.network == "unit-mesh":
        net = sj.unit_dendritic_mesh(EI=EI, branch_angle=args.branch_angle, dim=args.dim, **pert, **torsion)
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
            **torsion,
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
    return net, _with_torsion(params, net), _DEFAULT_DISPLACEMENT[args.network]


def _with_torsion(params: dict, net) -> dict:
    """The run's parameters with the torsional stiffness used (pN·µm²; None: torsion-free)."""
    import numpy as np

    return {**params, "GJ": float(np.asarray(net.GJ).flat[0]) if net.twisting else None}


def _check_outputs(args, out: Path, checkpoint: Path) -> None:
    """Every output of ``socbjax simulate`` checked before any work (no run is lost at the
    final save), and another run's checkpoint never discarded silently."""
    from ._io import check_output_path

    check_output_path(out, "--out")
    check_output_path(checkpoint, "the checkpoint next to --out")
    if args.figures:
        _check_folder(args.figures, "--figures")


def _check_checkpoint(args, checkpoint: Path) -> None:
    """Under the output's lock (so a checkpoint of a run still going is reported as such)."""
    if checkpoint.exists() and not args.resume:
        raise ValueError(f"{checkpoint} holds the checkpoint of an interrupted run on this --out: continue it with "
                         "--resume, or delete that file to start afresh")
    if args.resume and not checkpoint.exists():
        print(f"socbjax simulate: no checkpoint at {checkpoint}; starting from the beginning", file=sys.stderr)


def _check_folder(folder, what: str) -> None:
    """A figure folder: an existing folder, or absent with an existing parent folder."""
    from ._io import check_output_path

    folder = Path(folder).expanduser()
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{what} {folder} exists and is not a folder; give a folder for the PNG files")
    check_output_path((folder if folder.is_dir() else folder.parent) / ".socbjax-write-test", what)


def _simulate(args) -> int:
    import socbjax as sj

    from ._io import output_lock

    out = Path(args.out).expanduser()
    checkpoint = out.with_name(out.name + ".ckpt.h5")
    _check_outputs(args, out, checkpoint)
    net, params, default_u = _build(args)
    displacement = default_u if args.displacement is None else args.displacement
    steps = {} if args.max_step is None else dict(max_step=args.max_step, initial_step=min(0.02, args.max_step))
    settings = sj.PathSettings(linear_solver=args.linear_solver, **steps)
    with output_lock(out):  # a second run on the same --out refuses instead of deleting our checkpoints
        _check_checkpoint(args, checkpoint)
        print(
            f"socbjax simulate {args.network}: {plural(net.n_nodes, 'node')}, {plural(net.n_segments, 'segment')}, "
            f"{plural(net.n_junctions, 'junction')}; probe travel {displacement:g} µm"
            f"{' and back' if args.unload else ''}",
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
            checkpoint=sj.Checkpoint(checkpoint, every=args.checkpoint_every, resume=args.resume and checkpoint.exists()),
            throw=False,
            parameters=params,
            contact=sj.Contact(diameter=args.diameter, self_contact=net.dim == 2) if args.contact else None,
        )
        sj.save(result, out)
        if checkpoint.exists():  # the path ended (whatever its result): a resume would only repeat it
            checkpoint.unlink()
    if args.figures:
        sj.save_figures(result, args.figures)
    print(f"{out}: {result.summary()}")
    return 0 if result.completed else 1


def _steps(text: str | None):
    if text is None:
        return None
    try:
        return [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise ValueError(f"--steps expects comma-separated step indices, e.g. 0,10,20; got {text!r}") from None


def _plot(args) -> int:
    import socbjax as sj

    steps = _steps(args.steps)
    run = Path(args.run).expanduser()
    out = Path(args.out).expanduser() if args.out else run.with_name(run.stem + "-figures")
    _check_folder(out, "--out")
    result = sj.load(run)
    for path in sj.save_figures(result, out, steps=steps):
        print(path)
    return 0


# Errors that mean "the user asked for something that cannot be done": one line, exit 2.
_USER_ERRORS = (ValueError, TypeError, OSError, ImportError)


def build_parser() -> argparse.ArgumentParser:
    """The ``socbjax`` argument parser (all subcommands; no JAX imported): e.g. to check a command
    line without running it, ``build_parser().parse_args(["simulate", "column", "--out", "c.h5"])``."""
    return _parser()


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status (0 success, 1 the run did not complete or
    the fit did not converge, 2 a user error, printed as one line ``socbjax: error: ...``;
    ``--debug`` shows the traceback instead)."""
    args = _parser().parse_args(argv)  # before any import of JAX: --help and argument errors answer at once
    if hasattr(signal, "SIGXFSZ"):  # over a file-size limit, writes fail with EFBIG (an OSError) instead of killing us
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    try:
        return _dispatch(args)
    except _USER_ERRORS as err:
        if args.debug:
            raise
        print(f"socbjax: error: {_one_line(err)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if args.debug:
            raise
        print("socbjax: interrupted", file=sys.stderr)
        return 130
    except Exception as err:
        if args.debug or not _is_convergence_error(err):
            raise
        print(f"socbjax: error: {_one_line(err)}", file=sys.stderr)  # no answer at these inputs: one line too
        return 1


def _is_convergence_error(err: BaseException) -> bool:
    """Whether ``err`` is a :class:`socbjax.ConvergenceError` (only raised once the solver is
    imported: looked up there, so that this module imports no JAX)."""
    solution = sys.modules.get("socbjax._solution")
    return solution is not None and isinstance(err, solution.ConvergenceError)


def _one_line(err: BaseException) -> str:
    if isinstance(err, OSError) and err.strerror:  # without the "[Errno N]" prefix
        text = f"{err.filename}: {err.strerror}" if err.filename is not None else err.strerror
        return " ".join(text.split())
    return " ".join(str(err).split()) or type(err).__name__


def _dispatch(args) -> int:
    if args.command == "examples":
        return _examples(args)  # no JAX, no cache
    if args.command == "simulate":
        _check_simulate(args)
    if args.command == "plot":
        _steps(args.steps)
    if args.command == "fit":
        from ._cli_fit import check_fit_args

        check_fit_args(args)
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
        from ._cli_fit import run_fit

        return run_fit(args)
    return 2  # pragma: no cover - argparse enforces the choices


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
