"""socbjax: a JAX-differentiable String-Of-Continuous-Beams simulator of slender filaments.

The method is that of Simhadri & Chandran, Sci. Rep. 2019 (SOCB), with the corrections and
the frame-free 3D form documented in ``docs/equations.md``.

Units everywhere: length µm, force pN, time s, bending stiffness EI pN·µm², moments pN·µm.

Importing socbjax enables JAX's float64 mode (``jax_enable_x64``): the physics is float64
throughout and large-deflection Newton solves are not reliable in float32.
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._afm import ForceCurve, load_curve, save_curve  # noqa: E402
from ._builders import SUPPORTS, cantilever, column  # noqa: E402
from ._compress import compress, probe_network, strand_perturbation  # noqa: E402
from ._dendritic import dendritic_outcrop, unit_dendritic_mesh  # noqa: E402
from ._ensemble import EnsembleResult, compress_ensemble  # noqa: E402
from ._continuation import ContinuationResult, ContinuationSettings, load_continuation  # noqa: E402
from ._fit import FitResult, fit, fit_problem  # noqa: E402
from ._fit_figure import plot_fit, save_fit_figure  # noqa: E402
from ._implicit import implicit_root  # noqa: E402
from ._models import FIT_MODELS, ColumnModel, FitModel, OutcropModel, UnitMeshModel, make_fit_model  # noqa: E402
from ._parameters import NUISANCE_PARAMETERS, Parameter  # noqa: E402
from ._figures import plot_end_forces, plot_force_curve, plot_snapshots, plot_strand_forces, save_figures  # noqa: E402
from ._io import load, load_checkpoint, save, save_checkpoint  # noqa: E402
from ._jointed import JointedModel, JointedState  # noqa: E402
from ._network import Network, make_network  # noqa: E402
from ._newton import NewtonResult, NewtonSolver, Status  # noqa: E402
from ._path import PathSettings  # noqa: E402
from ._quadrature import coupling_matrix, gauss_legendre, quintic_coefficients  # noqa: E402
from ._residual import SOCBModel, SOCBState, socb_residual  # noqa: E402
from ._result import PHASES, CompressionResult, LimitPoint  # noqa: E402
from ._solve import (  # noqa: E402
    MODELS, ConvergenceError, Solution, buckling_load, default_atol, forces_array, make_model, prepare_jacobian_solver, solve,
)
from ._linear import DenseJacobianSolver, SparseJacobianSolver  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "__version__",
    "Network",
    "make_network",
    "cantilever",
    "column",
    "compress",
    "compress_ensemble",
    "EnsembleResult",
    "implicit_root",
    "fit",
    "fit_problem",
    "FitResult",
    "plot_fit",
    "save_fit_figure",
    "FitModel",
    "ColumnModel",
    "UnitMeshModel",
    "OutcropModel",
    "FIT_MODELS",
    "make_fit_model",
    "Parameter",
    "NUISANCE_PARAMETERS",
    "ForceCurve",
    "load_curve",
    "save_curve",
    "unit_dendritic_mesh",
    "dendritic_outcrop",
    "probe_network",
    "strand_perturbation",
    "PathSettings",
    "CompressionResult",
    "LimitPoint",
    "PHASES",
    "save",
    "save_figures",
    "plot_force_curve",
    "plot_snapshots",
    "plot_end_forces",
    "plot_strand_forces",
    "load",
    "save_checkpoint",
    "load_checkpoint",
    "SUPPORTS",
    "solve",
    "default_atol",
    "prepare_jacobian_solver",
    "DenseJacobianSolver",
    "SparseJacobianSolver",
    "buckling_load",
    "Solution",
    "Status",
    "ConvergenceError",
    "NewtonSolver",
    "NewtonResult",
    "ContinuationSettings",
    "ContinuationResult",
    "load_continuation",
    "SOCBModel",
    "SOCBState",
    "JointedModel",
    "JointedState",
    "MODELS",
    "make_model",
    "forces_array",
    "socb_residual",
    "coupling_matrix",
    "quintic_coefficients",
    "gauss_legendre",
]
