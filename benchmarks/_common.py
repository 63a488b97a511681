"""Shared helpers of the socbjax benchmarks: command line, output folder, JSON with a
machine description, a plain-text table printer, convergence-order fits, and the exact
planar-elastica cantilever used as ground truth.

The ground truth comes from ``socbjax.testing`` (diffrax shooting) when it imports and
works; otherwise from :func:`shoot_cantilever_numpy`, an independent numpy shooting solver
(fixed-step RK4 from the free tip back to the clamp, Newton on the tip angle).  Both are
computed when possible and their difference is recorded as a cross-check.

Importing this module sets ``OPENBLAS_NUM_THREADS=1`` unless it is already set: numpy and
jaxlib's CPU LU/eigen kernels use OpenBLAS, and on small machines its threads fight XLA's
own thread pool, making dense solves of ~200 unknowns 10-50x slower and erratic.  Import
``_common`` before numpy (the benchmark scripts do).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy/jax load OpenBLAS

import numpy as np  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"


def parse_args(description: str, argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=description.strip().splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small settings for a smoke test")
    p.add_argument("--out", type=Path, default=RESULTS, help=f"output folder (default {RESULTS})")
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    return args


def machine_info() -> dict:
    import jax

    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "jax": jax.__version__,
        "jax_backend": jax.default_backend(),
        "jax_devices": [str(d) for d in jax.devices()],
        "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
        "XLA_FLAGS": os.environ.get("XLA_FLAGS"),
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, np.integer):
        return int(x)
    return x


def write_json(out: Path, name: str, args, payload: dict) -> Path:
    data = {"benchmark": name, "quick": bool(args.quick), "machine": machine_info(), **payload}
    path = Path(out) / f"{name}.json"
    path.write_text(json.dumps(_jsonable(data), indent=2))
    print(f"wrote {path}")
    return path


def save_figure(fig, out: Path, name: str) -> Path:
    path = Path(out) / f"{name}.png"
    fig.savefig(path, dpi=130, bbox_inches="tight")
    print(f"wrote {path}")
    return path


def new_figure(figsize=(6.4, 4.4), ncols: int = 1):
    """(figure, axes): a figure on matplotlib's Agg canvas with ``ncols`` axes side by side
    and constrained layout; no pyplot, so nothing changes matplotlib's global backend (the
    figure functions can be called from a notebook or from docs/gallery.py)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(fig)
    return fig, fig.subplots(1, ncols)


def plain_log_labels(ax) -> None:
    """Tick labels of a log–log axes as plain numbers (6, 20, 0.5), minor ones only where an
    axis spans less than about two decades, instead of 6×10⁰ and 2×10¹."""
    from matplotlib.ticker import LogFormatter

    class Plain(LogFormatter):  # LogFormatter picks which ticks to label; the label itself in %g
        def __call__(self, x, pos=None):
            return f"{x:g}" if super().__call__(x, pos) else ""

    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(Plain(labelOnlyBase=False, minor_thresholds=(2, 0.5)))
        axis.set_minor_formatter(Plain(labelOnlyBase=False, minor_thresholds=(2, 0.5)))
    ax.tick_params(which="minor", pad=5.0)  # minor ticks are 1.5 pt shorter: labels in line with the major ones


def log_node_axis(ax, ticks) -> None:
    """A logarithmic axis of node counts labelled with the counts themselves (2, 5, 10, ...),
    not powers of ten, and no minor labels."""
    from matplotlib.ticker import NullFormatter

    ticks = sorted({int(t) for t in ticks})
    ax.set_xticks(ticks, [str(t) for t in ticks])
    ax.xaxis.set_minor_formatter(NullFormatter())


def fmt(v, spec: str = ".3e") -> str:
    if v is None:
        return "-"
    if isinstance(v, (float, np.floating)):
        return "nan" if not np.isfinite(v) else format(v, spec)
    return str(v)


def print_table(headers, rows, title: str | None = None, spec: str = ".3e") -> None:
    cells = [[fmt(c, spec) for c in row] for row in rows]
    widths = [max(len(str(h)), *(len(r[i]) for r in cells)) if cells else len(str(h)) for i, h in enumerate(headers)]
    if title:
        print(f"\n{title}")
    print("  ".join(str(h).rjust(w) for h, w in zip(headers, widths)))
    print("  ".join("-" * w for w in widths))
    for r in cells:
        print("  ".join(c.rjust(w) for c, w in zip(r, widths)))


def fit_order(n_nodes, errors, floor: float = 1e-12):
    """Log-log slope p of error ~ h^p, h = L/(n-1), over the points with error > floor."""
    h = 1.0 / (np.asarray(n_nodes, float) - 1.0)
    e = np.asarray(errors, float)
    keep = np.isfinite(e) & (e > floor)
    if keep.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(h[keep]), np.log(e[keep]), 1)[0])


def local_orders(n_nodes, errors):
    """Slopes log(e_i/e_{i-1}) / log(h_i/h_{i-1}) between consecutive points (first is nan)."""
    h = 1.0 / (np.asarray(n_nodes, float) - 1.0)
    e = np.asarray(errors, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.log(e[1:] / e[:-1]) / np.log(h[1:] / h[:-1])
    return [float("nan"), *out.tolist()]


def time_solve(net, forces, model: str = "socb", repeats: int = 9):
    """Wall times of ``socbjax.solve(net, forces, model=model)`` (s, until the positions are
    ready): (first call including compilation, [the ``repeats`` later calls], last solution)."""
    import jax

    import socbjax as sj

    def call():
        t0 = time.perf_counter()
        sol = sj.solve(net, forces, model=model, throw=True)
        jax.block_until_ready(sol.positions)
        return time.perf_counter() - t0, sol

    first, sol = call()
    times = [call()[0] for _ in range(repeats)]
    return first, times, sol


def median_ms(f, repeats: int) -> float:
    """Median wall time in ms of f() over ``repeats`` calls after a first (compiling) call;
    JAX results are waited for (``jax.block_until_ready``)."""
    import jax

    jax.block_until_ready(f())
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(f())
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


class Timer:
    def __enter__(self):
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.seconds = time.perf_counter() - self.t0


# ---------------------------------------------------------------- exact cantilever
def _rk4_tip_to_base(p, alpha, steps: int):
    """Integrate θ'' = -p cos θ from the free tip (τ = 0: θ = α, θ' = 0) to the clamp.

    τ = 1 - s/L runs from the tip to the base.  Returns θ(base), dθ(base)/dα and the tip
    position relative to the base (X, Y), all arrays of the broadcast shape of p, α.
    """
    p, alpha = np.broadcast_arrays(np.asarray(p, float), np.asarray(alpha, float))
    y = np.stack([alpha, np.zeros_like(p), np.zeros_like(p), np.zeros_like(p), np.ones_like(p), np.zeros_like(p)])

    def f(y):  # θ, ω = dθ/dτ, X, Y, a = ∂θ/∂α, b = ∂ω/∂α
        c, s = np.cos(y[0]), np.sin(y[0])
        return np.stack([y[1], -p * c, c, s, y[5], p * s * y[4]])

    h = 1.0 / steps
    for _ in range(steps):
        k1 = f(y)
        k2 = f(y + 0.5 * h * k1)
        k3 = f(y + 0.5 * h * k2)
        k4 = f(y + h * k3)
        y = y + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
    return y[0], y[4], y[2], y[3]


def shoot_cantilever_numpy(loads, steps: int = 20000, tol: float = 1e-14):
    """Exact unit cantilever (L = EI = 1, clamp along +x) under tip force (0, P), numpy only.

    Shooting on the tip angle α ∈ (0, π/2): a coarse scan picks the first sign change of
    θ(base; α) (the fundamental branch), then Newton with the variational equations at
    ``steps`` RK4 steps.  Returns (ΔX/L, ΔY/L) arrays: shortening 1 - x_tip and y_tip.
    """
    P = np.atleast_1d(np.asarray(loads, float))
    grid = np.linspace(1e-6, np.pi / 2, 129)
    th, *_ = _rk4_tip_to_base(P[None, :], grid[:, None], 400)
    first = np.argmax(th > 0, axis=0)  # θ(base) < 0 at α → 0 and = π/2 > 0 at α = π/2
    i0 = np.maximum(first - 1, 0)
    t0, t1 = th[i0, np.arange(P.size)], th[first, np.arange(P.size)]
    alpha = grid[i0] - t0 * (grid[first] - grid[i0]) / (t1 - t0)
    for _ in range(30):
        th, dth, X, Y = _rk4_tip_to_base(P, alpha, steps)
        alpha = alpha - th / dth
        if np.max(np.abs(th)) < tol:
            break
    _, _, X, Y = _rk4_tip_to_base(P, alpha, steps)
    return 1.0 - X, Y


def exact_cantilever(loads) -> dict:
    """Ground truth (ΔX/L, ΔY/L) for the unit cantilever at each P L²/EI in ``loads``."""
    loads = np.atleast_1d(np.asarray(loads, float))
    dX_np, dY_np = shoot_cantilever_numpy(loads)
    out = {"source": "numpy RK4 shooting (benchmarks/_common.py)", "dX": dX_np, "dY": dY_np,
           "crosscheck_max_abs_diff": None, "reference_error": None}
    try:
        import socbjax  # noqa: F401  (enables float64)
        from socbjax.testing import elastica_tip_deflection

        ref = np.array([elastica_tip_deflection(float(p)) for p in loads])
        diff = float(np.max(np.abs(ref - np.stack([dX_np, dY_np], axis=1))))
        out.update(source="socbjax.testing.elastica_tip_deflection", dX=ref[:, 0], dY=ref[:, 1],
                   crosscheck_max_abs_diff=diff)
        if diff > 1e-9:
            print(f"WARNING: socbjax.testing and numpy shooting differ by {diff:.2e}")
    except Exception as exc:  # reference not ready: keep the numpy solution
        out["reference_error"] = f"{type(exc).__name__}: {exc}"
        print(f"note: socbjax.testing unavailable ({out['reference_error'][:120]}); using numpy shooting")
    return out
