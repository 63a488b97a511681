"""``socbjax fit``: fit a model to a measured or simulated force curve from the command line."""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["add_fit_parser", "run_fit"]


def add_fit_parser(sub) -> None:
    fit = sub.add_parser(
        "fit",
        help="fit model parameters (EI, branch angle, ...) to a force–compression curve",
        description="Least-squares fit of a model's force–compression curve to data, with gradients through the "
        "solver (implicit function theorem). Writes the fitted values with standard errors and correlations "
        "as JSON, and a PNG with data, fitted curve and residuals. Units: µm, pN, pN·µm², degrees.",
    )
    fit.add_argument("curve", help="force curve: CSV/TSV with unit-carrying header (compression_um,force_pN, "
                     "compression_m,force_N, tip_position_m,force_N, ...) or, with socbjax[afm], .jpk-force/.ibw/.tab")
    fit.add_argument("--model", choices=["unit-mesh", "outcrop", "column"], default="unit-mesh",
                     help="model whose force curve is fitted (default unit-mesh)")
    fit.add_argument("--free", default="EI", help="comma-separated free parameters (default EI); model parameters "
                     "(EI, EI_mother, EI_daughter, EI_gen0.., branch_angle, perturbation) and data parameters "
                     "(contact_offset µm, baseline pN, force_scale)")
    fit.add_argument("--fixed", default="", help="comma-separated name=value pairs held fixed, e.g. force_scale=2")
    fit.add_argument("--initial", default="", help="comma-separated name=value starting values of free parameters")
    fit.add_argument("--out", required=True, help="output JSON (written atomically); the figure goes to OUT with .png")
    fit.add_argument("--branch", choices=["loading", "unloading"], default="loading",
                     help="fit the approach/loading (default) or the retract/unloading branch")
    fit.add_argument("--optimizer", choices=["lm", "adam", "lbfgs"], default="lm",
                     help="Levenberg–Marquardt (default) or optax Adam / L-BFGS")
    fit.add_argument("--max-iterations", type=int, default=30, help="optimiser iterations (default 30)")
    fit.add_argument("--max-points", type=int, default=80, help="average the curve into at most this many points (default 80)")
    fit.add_argument("--max-compression", type=float, default=None, help="drop data beyond this compression in µm")
    fit.add_argument("--spring-constant", type=float, default=None, help="cantilever spring constant in N/m "
                     "(default: from the file's metadata)")
    fit.add_argument("--model-option", action="append", default=[], metavar="NAME=VALUE",
                     help="model builder option, repeatable: unit-mesh mother_length (µm), segment_length (µm), "
                     "dim, branch_angle (deg, topology); outcrop generations, gap (µm), seed, dim; column n_nodes, "
                     "length (µm), supports (first/last among clamped, pinned, free; default clamped/pinned)")
    fit.add_argument("--quiet", action="store_true", help="no progress bar")


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


def _model_options(items: list[str]) -> dict:
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--model-option expects NAME=VALUE, got {item!r}")
        name = name.strip()
        if name == "supports":
            out[name] = tuple(v.strip() for v in value.split("/"))
            continue
        try:
            number = float(value)
        except ValueError:
            raise ValueError(f"--model-option {name} needs a number, got {value!r}") from None
        out[name] = int(number) if number.is_integer() and name in ("dim", "generations", "seed", "n_nodes") else number
    return out


def run_fit(args) -> int:
    import socbjax as sj

    from ._fit_figure import save_fit_figure
    from ._io import check_output_path

    out = Path(args.out).expanduser()
    check_output_path(out, "--out")  # before any work: a fit is not lost at the final save
    check_output_path(out.with_suffix(".png"), "the figure next to --out")
    fixed, initial = _pairs(args.fixed, "--fixed"), _pairs(args.initial, "--initial")
    options = _model_options(args.model_option)
    curve = sj.load_curve(args.curve, spring_constant=args.spring_constant,
                          segment="approach" if args.branch == "loading" else "retract")
    if args.max_compression is not None:
        curve = curve.select(max_compression=args.max_compression)
    print(f"socbjax fit: {len(curve)} points from {args.curve}, compression up to {curve.compression.max():.4g} µm, "
          f"force up to {curve.force.max():.4g} pN; model {args.model}, free {args.free}", file=sys.stderr)
    result = sj.fit(
        curve, args.model, free=tuple(n.strip() for n in args.free.split(",") if n.strip()),
        fixed=fixed, initial=initial,
        settings=sj.FitSettings(branch=args.branch, optimizer=args.optimizer, max_iterations=args.max_iterations,
                                max_points=args.max_points),
        model_options=options, progress=not args.quiet,
    )
    figure = out.with_suffix(".png")
    save_fit_figure(result, figure, title=Path(args.curve).name)
    result.save(out)
    print(result.summary())
    print(f"wrote {out} and {figure}")
    return 0 if result.converged else 1
