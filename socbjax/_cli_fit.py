"""``socbjax fit``: fit a model to measured or simulated force curves from the command line.

One curve file with ``--out OUT.json``: the fit's JSON and ``OUT.png`` (as always).  Several
files and/or folders, or ``--out`` naming a folder: a batch (:func:`socbjax.fit_batch`),
``DIR/results.csv``, ``DIR/results.json``, ``DIR/<stem>.png`` per curve and
``DIR/summary.png``.  ``--compare column,unit-mesh``: :func:`socbjax.compare_models` per curve
(tables printed; ``--out DIR`` adds ``DIR/comparison.json``).

Importing this module loads only the standard library (``socbjax --help`` stays fast):
jax and socbjax's solvers are imported inside :func:`run_fit`.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from ._progress import plural  # stdlib only

__all__ = ["add_fit_parser", "check_fit_args", "run_fit", "CLI_FIXES"]

SUPPORTS = ("clamped", "pinned", "free")
DEFAULT_SUPPORTS = "clamped,pinned"
_INTEGER_OPTIONS = ("dim", "generations", "seed", "n_nodes", "n_outcrops")

# How the command line spells the fixes of socbjax's FitRangeError (see _fit_problem.PYTHON_FIXES).
CLI_FIXES = {
    "crop": "crop the curve with --max-compression {value}",
    "size": "use a larger model with --model-option {name}={value}",
    "method": "follow the fold with --method arclength",
    "start": "start elsewhere with --initial NAME=VALUE",
}


def add_fit_parser(sub) -> None:
    fit = sub.add_parser(
        "fit",
        help="fit model parameters (EI, branch angle, ...) to force–compression curves (one file, or a batch)",
        description="Least-squares fit of a model's force–compression curve to data, with gradients through the "
        "solver (implicit function theorem). One CURVE with --out OUT.json: the fitted values with standard errors "
        "and correlations as JSON, and OUT.png with data, fitted curve and residuals. Several CURVEs or folders, or "
        "--out naming a folder: a batch, every curve fitted with the same options (in file-name order, whatever the "
        "order of the arguments), writing DIR/results.csv and DIR/results.json (one row per curve: sha256, values "
        "± SE, contact point, fit range, noise, chi2_reduced, misfit, warnings), DIR/<stem>.png per curve and "
        "DIR/summary.png. Every model defaults to 3D (--dim 3, as every builder and socbjax simulate); planar "
        "models are opt-in with --dim 2. Units: µm, pN, pN·µm², degrees. Exit status 0: converged (a batch: at "
        "least one curve fitted; failed curves get a row with their error), 1: the fit ran but did not converge or "
        "explains nothing (R² ≤ 0) (a batch: every curve failed), 2: the inputs cannot be fitted (the message names "
        "the option that fixes it).",
    )
    fit.add_argument("curves", nargs="+", metavar="CURVE",
                     help="force curve file(s) or folder(s): CSV/TSV with unit-carrying header (compression_um,force_pN, "
                     "compression_m,force_N, tip_position_m,force_N, ...), with socbjax[afm] .jpk-force/.ibw/.tab, or an "
                     "HDF5 result of socbjax simulate (its network's dimension must match the model's); a folder "
                     "contributes its curve files by extension (no sub-folders, symbolic links or hidden files)")
    fit.add_argument("--model", choices=["unit-mesh", "outcrop", "column", "lawn"], default="unit-mesh",
                     help="model whose force curve is fitted (default unit-mesh; lawn: a film of outcrops under the "
                     "probe)")
    fit.add_argument("--dim", type=int, choices=[2, 3], default=None,
                     help="dimension of the model: 3 (spatial; the default, as every builder and socbjax simulate) "
                     "or 2 (planar, opt-in; compiles and runs faster)")
    fit.add_argument("--free", default=None, help="comma-separated free parameters (default EI; with --compare each "
                     "model's defaults); model parameters "
                     "(EI, EI_mother, EI_daughter, EI_gen0.., branch_angle, perturbation) and data parameters "
                     "(contact_offset µm, baseline pN, force_scale)")
    fit.add_argument("--fixed", default="", help="comma-separated name=value pairs held fixed, e.g. force_scale=2")
    fit.add_argument("--initial", default="", help="comma-separated name=value starting values of free parameters "
                     "(default: the parameter defaults, with EI scaled to the data's force level)")
    fit.add_argument("--out", default=None,
                     help="one CURVE: output JSON ending in .json (written atomically; the figure goes to OUT with "
                     ".png); a batch: a folder (created if missing) for results.csv, results.json and the PNGs. "
                     "Required, except with --compare (which then only prints its tables)")
    fit.add_argument("--compare", default=None, metavar="MODELS",
                     help="compare models on each curve instead of fitting one, e.g. --compare column,unit-mesh "
                     "(socbjax.compare_models: a table with AIC/BIC per curve); with --out DIR also DIR/comparison.json")
    fit.add_argument("--branch", choices=["loading", "unloading"], default="loading",
                     help="fit the approach/loading (default) or the retract/unloading branch")
    fit.add_argument("--method", choices=["displacement", "arclength"], default="displacement",
                     help="path following of the model: displacement control (default; the AFM's own control, stops "
                     "at a fold) or pseudo-arclength (follows snap-throughs; each compression then takes the path's "
                     "first crossing)")
    fit.add_argument("--optimizer", choices=["lm", "adam", "lbfgs"], default="lm",
                     help="Levenberg–Marquardt (default) or optax Adam / L-BFGS")
    fit.add_argument("--max-iterations", type=int, default=30, help="optimiser iterations (default 30)")
    fit.add_argument("--learning-rate", type=float, default=0.05,
                     help="Adam's step in the unconstrained parameters (default 0.05; --optimizer adam only)")
    fit.add_argument("--max-points", type=int, default=80, help="average the curve into at most this many points (default 80)")
    fit.add_argument("--max-compression", type=float, default=None, help="drop data beyond this compression in µm")
    fit.add_argument("--spring-constant", type=float, default=None, help="cantilever spring constant in N/m "
                     "(default: from the file's metadata)")
    fit.add_argument("--supports", default=None, metavar="FIRST,LAST",
                     help=f"column: supports of the first,last node among clamped/pinned/free (default {DEFAULT_SUPPORTS}, "
                     "as socbjax simulate column)")
    fit.add_argument("--model-option", action="append", default=[], metavar="NAME=VALUE",
                     help="model builder option, repeatable: unit-mesh mother_length (µm, default 1; the mesh can be "
                     "compressed by about 0.3-0.4 of it), segment_length (µm, default mother_length/4), "
                     "branch_angle (deg, topology); outcrop generations, gap (µm), seed; column n_nodes, length (µm); "
                     "the dimension with --dim")
    fit.add_argument("--quiet", action="store_true", help="no progress lines of the optimiser")


def batch_mode(args) -> bool:
    """Whether ``socbjax fit`` runs as a batch: several CURVEs, a folder among them, or an
    ``--out`` that does not end in .json (a folder)."""
    return (len(args.curves) > 1 or any(Path(c).expanduser().is_dir() for c in args.curves)
            or (args.out is not None and not args.out.lower().endswith(".json")))


def check_fit_args(args) -> None:
    """The checks of ``socbjax fit`` that need no JAX (run before it is imported)."""
    if args.out is None and args.compare is None:
        raise ValueError("--out is required: --out OUT.json for one curve, --out DIR (a folder) for a batch")
    if args.compare is not None:
        models = [m.strip() for m in args.compare.split(",") if m.strip()]
        if len(models) < 2:
            raise ValueError(f"--compare expects at least two comma-separated models, e.g. --compare column,unit-mesh; "
                             f"got {args.compare!r}")
        if args.out is not None and args.out.lower().endswith(".json"):
            raise ValueError(f"--compare writes DIR/comparison.json: give --out a folder, not {args.out!r}")
    elif batch_mode(args) and args.out.lower().endswith(".json"):
        raise ValueError(f"--out {args.out} names a JSON file, but {plural(len(args.curves), 'CURVE argument')} "
                         "(or a folder) make a batch: give --out a folder (created if missing) for results.csv, "
                         "results.json and the figures")
    _check_numbers(args)


def _pairs(text: str, what: str) -> dict:
    out = {}
    for item in filter(None, (t.strip() for t in text.split(","))):
        name, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"{what} expects name=value pairs, got {item!r}")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise ValueError(f"{what} value of {name.strip()!r} is not a number: {value!r}") from None
    return out


def parse_supports(text: str, option: str = "--supports") -> tuple[str, str]:
    """``"clamped,pinned"`` -> ("clamped", "pinned"); ValueError naming the value and the form."""
    parts = tuple(p.strip() for p in text.split(","))
    if len(parts) != 2 or not all(p in SUPPORTS for p in parts):
        raise ValueError(f"{option} expects the first,last supports among {', '.join(SUPPORTS)}, comma-separated "
                         f"(e.g. {option} {DEFAULT_SUPPORTS}), got {text!r}")
    return parts


def _model_options(args) -> dict:
    out = {}
    for item in args.model_option:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"--model-option expects NAME=VALUE, got {item!r}")
        if name == "supports":
            raise ValueError(f"--model-option {item!r}: give the column's supports with --supports FIRST,LAST "
                             f"(e.g. --supports {DEFAULT_SUPPORTS})")
        try:
            number = float(value)
        except ValueError:
            raise ValueError(f"--model-option {name} needs a number, got {value!r}") from None
        out[name] = int(number) if number.is_integer() and name in _INTEGER_OPTIONS else number
    if args.dim is not None:
        if "dim" in out and out["dim"] != args.dim:
            raise ValueError(f"--dim {args.dim} and --model-option dim={out['dim']} disagree; give the dimension once, "
                             "with --dim")
        out["dim"] = args.dim
    if args.supports is not None and args.model != "column":
        raise ValueError(f"--supports {args.supports} applies to --model column only (got --model {args.model})")
    if args.model == "column":
        out["supports"] = parse_supports(DEFAULT_SUPPORTS if args.supports is None else args.supports)
    return out


def _check_numbers(args) -> None:
    if args.max_iterations < 1:
        raise ValueError(f"--max-iterations must be a positive number of iterations, got {args.max_iterations}")
    if args.max_points < 3:
        raise ValueError(f"--max-points must be at least 3, got {args.max_points}")
    for option, value, unit in (("--max-compression", args.max_compression, " in µm"),
                                ("--spring-constant", args.spring_constant, " in N/m"),
                                ("--learning-rate", args.learning_rate, "")):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ValueError(f"{option} must be a positive finite number{unit}, got {value}")


def _settings(args):
    import socbjax as sj

    return sj.FitSettings(branch=args.branch, optimizer=args.optimizer, max_iterations=args.max_iterations,
                          max_points=args.max_points, method=args.method, learning_rate=args.learning_rate)


def _free(args) -> tuple:
    return tuple(n.strip() for n in (args.free or "EI").split(",") if n.strip())


def _dim_fix(args) -> str:
    return "--dim %d"


def run_fit(args) -> int:
    check_fit_args(args)
    if args.compare is not None:
        return _run_compare(args)
    if batch_mode(args):
        return _run_batch(args)
    return _run_single(args)


def _run_batch(args) -> int:
    from ._batch import fit_batch

    fixed, initial = _pairs(args.fixed, "--fixed"), _pairs(args.initial, "--initial")
    options = _model_options(args)
    free = _free(args)
    dim = options.get("dim", 3)
    print(f"socbjax fit: model {args.model} ({dim}D), free {', '.join(free) or '(none)'}; results in {args.out}",
          file=sys.stderr)
    batch = fit_batch(args.curves, args.model, out=args.out, spring_constant=args.spring_constant,
                      max_compression=args.max_compression, report=lambda line: print(line, flush=True), free=free,
                      fixed=fixed, initial=initial, settings=_settings(args), model_options=options,
                      progress=not args.quiet, _cli_fixes=CLI_FIXES, _dim_option=_dim_fix(args))
    out = Path(args.out).expanduser()
    print(f"{plural(len(batch), 'curve')}: {batch.n_converged} converged, "
          f"{len(batch) - batch.n_converged - batch.n_failed} not converged, {batch.n_failed} failed; wrote "
          f"{out / 'results.csv'}, {out / 'results.json'}, {out / 'summary.png'} and the figure of each fitted curve")
    if batch.exit_status:
        print("socbjax fit: every curve failed (see the message column of results.csv)", file=sys.stderr)
    return batch.exit_status


def _run_compare(args) -> int:
    from ._batch import compare_batch

    models = tuple(m.strip() for m in args.compare.split(",") if m.strip())
    options = _model_options(args) if args.model in models else {}
    per_model = {m: {**({"dim": args.dim} if args.dim is not None else {}), **(options if m == args.model else {})}
                 for m in models}
    extra = {} if args.free is None else {"free": _free(args)}
    record = compare_batch(args.curves, models, out=args.out, spring_constant=args.spring_constant,
                           max_compression=args.max_compression, segment="approach" if args.branch == "loading"
                           else "retract", report=lambda text: print(text, flush=True), settings=_settings(args),
                           model_options=per_model, progress=not args.quiet, **extra)
    if args.out is not None:
        print(f"wrote {Path(args.out).expanduser() / 'comparison.json'}")
    return 0 if any("comparison" in c for c in record["curves"]) else 1


def _run_single(args) -> int:
    import socbjax as sj

    from ._curve_inputs import check_dimension, model_dim, read_curve
    from ._fit_figure import save_fit_figure
    from ._fit_problem import FitRangeError
    from ._io import check_output_path

    out = Path(args.out).expanduser()
    check_output_path(out, "--out")  # before any work: a fit is not lost at the final save
    check_output_path(out.with_suffix(".png"), "the figure next to --out")
    fixed, initial = _pairs(args.fixed, "--fixed"), _pairs(args.initial, "--initial")
    options = _model_options(args)
    free = _free(args)
    (path,) = args.curves
    curve = read_curve(path, spring_constant=args.spring_constant, max_compression=args.max_compression,
                       segment="approach" if args.branch == "loading" else "retract")
    model = sj.make_fit_model(args.model, **options)
    check_dimension(curve, model, option=_dim_fix(args))
    print(f"socbjax fit: {plural(len(curve), 'point')} from {path}, compression up to "
          f"{curve.compression.max():.4g} µm, force up to {curve.force.max():.4g} pN; model {args.model} "
          f"({model_dim(model) or '?'}D), free {', '.join(free) or '(none)'}", file=sys.stderr)
    try:
        result = sj.fit(curve, model, free=free, fixed=fixed, initial=initial, settings=_settings(args),
                        progress=not args.quiet)
    except FitRangeError as err:  # worded with this command's options
        raise ValueError(err.describe(CLI_FIXES)) from None
    figure = out.with_suffix(".png")
    save_fit_figure(result, figure, title=Path(path).name)
    result.save(out)
    print(result.summary())
    print(f"wrote {out} and {figure}")
    if not result.converged:
        print(f"socbjax fit: not converged: {result.message}", file=sys.stderr)
    return 0 if result.converged else 1
