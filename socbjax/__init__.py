"""socbjax: a JAX-differentiable String-Of-Continuous-Beams simulator of slender filaments.

The method is that of Simhadri & Chandran, Sci. Rep. 2019 (SOCB), with the corrections and
the frame-free 3D form documented in ``docs/equations.md``.

Units everywhere: length µm, force pN, time s, bending stiffness EI pN·µm², moments pN·µm.

Importing socbjax enables JAX's float64 mode (``jax_enable_x64``): the physics is float64
throughout and large-deflection Newton solves are not reliable in float32.  Every public
entry point is a function of traced values (``jax.jit``, ``jax.grad``, ``jax.jacfwd``,
``jax.vmap``; see the README's "JAX transformations" table).

The import itself is light (it does not import JAX): the public names are loaded, with JAX,
on first use (PEP 562 ``__getattr__``; they live in ``socbjax._api``), so the command line
answers ``--help`` and argument errors at once.

The import also adds ``--xla_cpu_use_fusion_emitters=false`` to ``XLA_FLAGS`` (a quarter to
a half less compile time of a first call on CPU, the same run time): see ``socbjax._xla_flags``;
``SOCBJAX_XLA_DEFAULTS=off`` opts out.
"""

import os as _os
import sys as _sys

if "jax" in _sys.modules:  # JAX already imported: switch its configuration now
    _sys.modules["jax"].config.update("jax_enable_x64", True)
else:  # JAX reads JAX_ENABLE_X64 when it is imported (jax/_src/config.py); _api enables it again
    _os.environ["JAX_ENABLE_X64"] = "1"

from ._version import __version__  # noqa: E402
from ._xla_flags import add_default_xla_flags as _add_default_xla_flags  # noqa: E402

_add_default_xla_flags()  # faster XLA compilation on CPU; SOCBJAX_XLA_DEFAULTS=off opts out

__all__ = [
    "__version__",
    # networks
    "Network", "Topology", "make_network", "cantilever", "column", "SUPPORTS", "unit_dendritic_mesh",
    "dendritic_outcrop", "pad_outcrop", "Padding", "universal_strands", "probe_network", "strand_perturbation",
    "arc", "helix", "crimped_fibre", "with_natural_curvature", "thermal_network", "persistence_length", "ACTIN_GJ",
    # solving
    "solve", "Solution", "FilamentCurve", "filament_curve", "buckling_load", "compress", "CompressionResult",
    "LimitPoint", "PHASES",
    "compress_ensemble", "EnsembleResult", "PathSettings", "NaturalParameter", "PseudoArclength", "Checkpoint",
    "follow_path", "start_path", "PathProblem", "PathState", "StepRecorder", "NoRecorder",
    "RESULTS", "ConvergenceError", "default_atol",
    # contact
    "Contact", "Plane", "Sphere",
    # solver parts
    "DampedNewton", "ImplicitAdjoint", "DenseLU", "ColouredSparseLU", "PairedSparseLU", "Bordered", "linear_solver_for", "make_model", "MODELS",
    "SOCBModel", "SOCBState", "JointedModel", "JointedState", "Control",
    "coupling_matrix", "quintic_coefficients", "gauss_legendre",
    # fitting and data
    "fit", "fit_problem", "FitProblem", "FitResiduals", "FitData", "ApproachBaseline", "FitRangeError", "FitResult", "FitSettings", "FitModel", "ColumnModel", "UnitMeshModel",
    "OutcropModel", "LawnModel", "check_dimension", "collect_curve_files", "read_curve", "FIT_MODELS", "make_fit_model", "Parameter", "NUISANCE_PARAMETERS", "ForceCurve", "load_curve",
    "save_curve", "example_files", "example_file", "example_descriptions",
    # batch fits
    "fit_batch", "BatchResult", "curve_from_result",
    # goodness of fit and model comparison
    "goodness_of_fit", "Goodness", "estimate_noise", "runs_test", "RunsTest", "lag1_autocorrelation",
    "information_criteria", "compare_models", "ModelComparison",
    # files, figures, tooling
    "save", "load", "save_checkpoint", "load_checkpoint", "check_output_path", "output_lock", "atomic_path", "save_figures", "plot_force_curve", "plot_snapshots",
    "plot_end_forces", "plot_strand_forces", "plot_fit", "plot_lawn", "save_fit_figure", "enable_compilation_cache",
    "add_default_xla_flags",
]

_SUBMODULES = ("testing", "cli")  # ``socbjax.testing`` works without importing it first


def __getattr__(name: str):
    """The public names, imported with JAX on first use (``socbjax._api``)."""
    import importlib

    if name in __all__:
        api = importlib.import_module("._api", __name__)
        globals().update({n: getattr(api, n) for n in __all__ if n != "__version__"})
        return globals()[name]
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__) | set(_SUBMODULES))
