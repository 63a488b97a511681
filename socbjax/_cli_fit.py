"""``socbjax fit``: fit a model to a measured or simulated force curve from the command line.

Importing this module loads only the standard library (``socbjax --help`` stays fast):
jax and socbjax's solvers are imported inside :func:`run_fit`.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

__all__ = ["add_fit_parser", "run_fit", "CLI_FIXES"]

SUPPORTS = ("clamped", "pinned", "free")
DEFAULT_SUPPORTS = "clamped,pinned"
_INTEGER_OPTIONS = ("dim", "generations", "seed", "n_nodes")

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
        help="fit model parameters (EI, branch angle, ...) to a force–compression curve",
        description="Least-squares fit of a model's force–compression curve to data, with gradients through the "
        "solver (implicit function theorem). Writes the fitted values with standard errors and correlations "
        "as JSON, and a PNG with data, fitted curve and residuals. Units: µm, pN, pN·µm², degrees. "
        "Exit status 0: converged, 1: the fit ran but did not converge or explains nothing (R² ≤ 0), "
        "2: the inputs cannot be fitted (the message names the option that fixes it).",
    )
    fit.add_argument("curve", help="force curve: CSV/TSV with unit-carrying header (compression_um,force_pN, "
                     "compression_m,force_N, tip_position_m,force_N, ...) or, with socbjax[afm], .jpk-force/.ibw/.tab")
    fit.add_argument("--model", choices=["unit-mesh", "outcrop", "column"], default="unit-mesh",
                     help="model whose force curve is fitted (default unit-mesh)")
    fit.add_argument("--free", default="EI", help="comma-separated free parameters (default EI); model parameters "
                     "(EI, EI_mother, EI_daughter, EI_gen0.., branch_angle, perturbation) and data parameters "
                     "(contact_offset µm, baseline pN, force_scale)")
    fit.add_argument("--fixed", default="", help="comma-separated name=value pairs held fixed, e.g. force_scale=2")
    fit.add_argument("--initial", default="", help="comma-separated name=value starting values of free parameters "
                     "(default: the parameter defaults, with EI scaled to the data's force level)")
    fit.add_argument("--out", required=True, help="output JSON (written atomically); the figure goes to OUT with .png")
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
                     "compressed by about 0.3-0.4 of it), segment_length (µm, default mother_length/4), dim, "
                     "branch_angle (deg, topology); outcrop generations, gap (µm), seed, dim; column n_nodes, length (µm)")
    fit.add_argument("--quiet", action="store_true", help="no progress lines")


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


def _plural(n: int, word: str) -> str:
    return f"{n} {word if n == 1 else word + 's'}"


def run_fit(args) -> int:
    import socbjax as sj

    from ._fit_figure import save_fit_figure
    from ._fit_problem import FitRangeError
    from ._io import check_output_path

    out = Path(args.out).expanduser()
    check_output_path(out, "--out")  # before any work: a fit is not lost at the final save
    check_output_path(out.with_suffix(".png"), "the figure next to --out")
    _check_numbers(args)
    fixed, initial = _pairs(args.fixed, "--fixed"), _pairs(args.initial, "--initial")
    options = _model_options(args)
    free = tuple(n.strip() for n in args.free.split(",") if n.strip())
    curve = sj.load_curve(args.curve, spring_constant=args.spring_constant,
                          segment="approach" if args.branch == "loading" else "retract")
    if args.max_compression is not None:
        curve = curve.select(max_compression=args.max_compression)
    print(f"socbjax fit: {_plural(len(curve), 'point')} from {args.curve}, compression up to "
          f"{curve.compression.max():.4g} µm, force up to {curve.force.max():.4g} pN; model {args.model}, "
          f"free {', '.join(free) or '(none)'}", file=sys.stderr)
    settings = sj.FitSettings(branch=args.branch, optimizer=args.optimizer, max_iterations=args.max_iterations,
                              max_points=args.max_points, method=args.method, learning_rate=args.learning_rate)
    try:
        result = sj.fit(curve, args.model, free=free, fixed=fixed, initial=initial, settings=settings,
                        model_options=options, progress=not args.quiet)
    except FitRangeError as err:  # worded with this command's options
        raise ValueError(err.describe(CLI_FIXES)) from None
    figure = out.with_suffix(".png")
    save_fit_figure(result, figure, title=Path(args.curve).name)
    result.save(out)
    print(result.summary())
    print(f"wrote {out} and {figure}")
    if not result.converged:
        print(f"socbjax fit: not converged: {result.message}", file=sys.stderr)
    return 0 if result.converged else 1
