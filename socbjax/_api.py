"""The public API of socbjax, imported on first use of ``socbjax.<name>`` (see ``__init__``).

Importing this module imports JAX and every part of the package; ``import socbjax`` alone does
not, so the command line answers ``--help`` and argument errors without waiting for JAX.
"""

import jax as _jax

# Also here (``__init__`` sets JAX_ENABLE_X64 before JAX loads): a JAX imported earlier, or one
# whose configuration was changed since, still runs socbjax in float64.
_jax.config.update("jax_enable_x64", True)

from ._adjoint import ImplicitAdjoint  # noqa: E402
from ._afm import ForceCurve, load_curve, save_curve  # noqa: E402
from ._batch import BatchResult, curve_from_result, fit_batch  # noqa: E402
from ._curve_inputs import check_dimension, collect_curve_files, read_curve  # noqa: E402
from ._buckling import buckling_load  # noqa: E402
from ._builders import SUPPORTS, arc, cantilever, column, crimped_fibre, helix  # noqa: E402
from ._cache import enable_compilation_cache  # noqa: E402
from ._xla_flags import add_default_xla_flags  # noqa: E402
from ._compare import ModelComparison, compare_models  # noqa: E402
from ._compress import compress  # noqa: E402
from ._contact import Contact, Plane, Sphere  # noqa: E402
from ._curve import FilamentCurve, filament_curve  # noqa: E402
from ._curved import ACTIN_GJ, with_natural_curvature  # noqa: E402
from ._dendritic import dendritic_outcrop, unit_dendritic_mesh  # noqa: E402
from ._ensemble import EnsembleResult, compress_ensemble  # noqa: E402
from ._equilibrium import Solution  # noqa: E402
from ._examples import example_descriptions, example_file, example_files  # noqa: E402
from ._figures import plot_end_forces, plot_force_curve, plot_snapshots, plot_strand_forces, save_figures  # noqa: E402
from ._fit import FitResult, FitSettings, fit  # noqa: E402
from ._fit_figure import plot_fit, save_fit_figure  # noqa: E402
from ._lawn_figure import plot_lawn  # noqa: E402
from ._fit_data import ApproachBaseline, FitData
from ._fit_problem import FitProblem, FitRangeError, fit_problem  # noqa: E402
from ._fit_residuals import FitResiduals  # noqa: E402
from ._goodness import (  # noqa: E402
    Goodness, RunsTest, estimate_noise, goodness_of_fit, information_criteria, lag1_autocorrelation, runs_test,
)
from ._io import atomic_path, check_output_path, load, load_checkpoint, output_lock, save, save_checkpoint  # noqa: E402
from ._jointed import JointedModel, JointedState  # noqa: E402
from ._linear import Bordered, ColouredSparseLU, DenseLU  # noqa: E402
from ._paired import PairedSparseLU  # noqa: E402
from ._models import FIT_MODELS, ColumnModel, FitModel, OutcropModel, UnitMeshModel, make_fit_model  # noqa: E402
from ._lawn import LawnModel  # noqa: E402
from ._network import Network, Padding, Topology, make_network  # noqa: E402
from ._padding import pad_outcrop, universal_strands  # noqa: E402
from ._parameters import NUISANCE_PARAMETERS, Parameter  # noqa: E402
from ._path import (  # noqa: E402
    NaturalParameter, NoRecorder, PathProblem, PathState, PseudoArclength, StepRecorder, follow_path, start_path,
)
from ._path_settings import PathSettings  # noqa: E402
from ._perturbation import strand_perturbation  # noqa: E402
from ._probe import probe_network  # noqa: E402
from ._protocol import Checkpoint  # noqa: E402
from ._quadrature import coupling_matrix, gauss_legendre, quintic_coefficients  # noqa: E402
from ._residual import Control, SOCBModel, SOCBState  # noqa: E402
from ._result import PHASES, CompressionResult, LimitPoint  # noqa: E402
from ._thermal import persistence_length, thermal_network  # noqa: E402
from ._root import DampedNewton  # noqa: E402
from ._solution import RESULTS, ConvergenceError  # noqa: E402
from ._solve import MODELS, default_atol, make_model, solve  # noqa: E402
from ._sparsity import linear_solver_for  # noqa: E402
