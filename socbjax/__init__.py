"""socbjax: a JAX-differentiable String-Of-Continuous-Beams simulator of slender filaments.

The method is that of Simhadri & Chandran, Sci. Rep. 2019 (SOCB), with the corrections and
the frame-free 3D form documented in ``docs/equations.md``.

Units everywhere: length µm, force pN, time s, bending stiffness EI pN·µm², moments pN·µm.

Importing socbjax enables JAX's float64 mode (``jax_enable_x64``): the physics is float64
throughout and large-deflection Newton solves are not reliable in float32.  Every public
entry point is a function of traced values (``jax.jit``, ``jax.grad``, ``jax.jacfwd``,
``jax.vmap``; see the README's "JAX transformations" table).
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._adjoint import ImplicitAdjoint  # noqa: E402
from ._afm import ForceCurve, load_curve, save_curve  # noqa: E402
from ._buckling import buckling_load  # noqa: E402
from ._builders import SUPPORTS, cantilever, column  # noqa: E402
from ._cache import enable_compilation_cache  # noqa: E402
from ._compress import compress  # noqa: E402
from ._curve import FilamentCurve  # noqa: E402
from ._dendritic import dendritic_outcrop, unit_dendritic_mesh  # noqa: E402
from ._ensemble import EnsembleResult, compress_ensemble  # noqa: E402
from ._equilibrium import Solution  # noqa: E402
from ._figures import plot_end_forces, plot_force_curve, plot_snapshots, plot_strand_forces, save_figures  # noqa: E402
from ._fit import FitResult, FitSettings, fit  # noqa: E402
from ._fit_figure import plot_fit, save_fit_figure  # noqa: E402
from ._fit_problem import FitProblem, fit_problem  # noqa: E402
from ._io import atomic_path, check_output_path, load, load_checkpoint, output_lock, save, save_checkpoint  # noqa: E402
from ._jointed import JointedModel, JointedState  # noqa: E402
from ._linear import Bordered, ColouredSparseLU, DenseLU  # noqa: E402
from ._models import FIT_MODELS, ColumnModel, FitModel, OutcropModel, UnitMeshModel, make_fit_model  # noqa: E402
from ._network import Network, Topology, make_network  # noqa: E402
from ._parameters import NUISANCE_PARAMETERS, Parameter  # noqa: E402
from ._path import (  # noqa: E402
    NaturalParameter, NoRecorder, PathProblem, PathSettings, PathState, PseudoArclength, StepRecorder, follow_path, start_path,
)
from ._perturbation import strand_perturbation  # noqa: E402
from ._probe import probe_network  # noqa: E402
from ._protocol import Checkpoint  # noqa: E402
from ._quadrature import coupling_matrix, gauss_legendre, quintic_coefficients  # noqa: E402
from ._residual import Control, SOCBModel, SOCBState  # noqa: E402
from ._result import PHASES, CompressionResult, LimitPoint  # noqa: E402
from ._root import DampedNewton  # noqa: E402
from ._solution import RESULTS, ConvergenceError  # noqa: E402
from ._solve import MODELS, default_atol, make_model, solve  # noqa: E402
from ._sparsity import linear_solver_for  # noqa: E402

from ._version import __version__  # noqa: E402

__all__ = [
    "__version__",
    # networks
    "Network", "Topology", "make_network", "cantilever", "column", "SUPPORTS", "unit_dendritic_mesh",
    "dendritic_outcrop", "probe_network", "strand_perturbation",
    # solving
    "solve", "Solution", "FilamentCurve", "buckling_load", "compress", "CompressionResult", "LimitPoint", "PHASES",
    "compress_ensemble", "EnsembleResult", "PathSettings", "NaturalParameter", "PseudoArclength", "Checkpoint",
    "follow_path", "start_path", "PathProblem", "PathState", "StepRecorder", "NoRecorder",
    "RESULTS", "ConvergenceError", "default_atol",
    # solver parts
    "DampedNewton", "ImplicitAdjoint", "DenseLU", "ColouredSparseLU", "Bordered", "linear_solver_for", "make_model", "MODELS",
    "SOCBModel", "SOCBState", "JointedModel", "JointedState", "Control",
    "coupling_matrix", "quintic_coefficients", "gauss_legendre",
    # fitting and data
    "fit", "fit_problem", "FitProblem", "FitResult", "FitSettings", "FitModel", "ColumnModel", "UnitMeshModel",
    "OutcropModel", "FIT_MODELS", "make_fit_model", "Parameter", "NUISANCE_PARAMETERS", "ForceCurve", "load_curve",
    "save_curve",
    # files, figures, tooling
    "save", "load", "save_checkpoint", "load_checkpoint", "check_output_path", "output_lock", "atomic_path", "save_figures", "plot_force_curve", "plot_snapshots",
    "plot_end_forces", "plot_strand_forces", "plot_fit", "save_fit_figure", "enable_compilation_cache",
]
