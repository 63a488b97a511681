"""Shared fixtures and the test session's JAX set-up. float64 is enabled here (socbjax also
enables it on import).

Compilation dominates the suite's time, so the session (and the subprocesses it starts,
which inherit the environment) compiles with XLA's backend optimisation level 0 (about a third less compile time) and
without LLVM's expensive passes (a further ~7 %), the same arithmetic (set ``SOCBJAX_TEST_XLA_FLAGS`` to override,
e.g. to an empty string); importing socbjax adds its own default, the legacy CPU fusion emitters
(``socbjax._xla_flags``: a further third off the compile time of the 3D tests) — and uses JAX's persistent compilation cache in
``.jax_cache/`` at the repository root (``SOCBJAX_CACHE_DIR`` overrides; ``off`` disables),
so a second run does not recompile.
"""

import os
from pathlib import Path

# OpenBLAS's own threads oversubscribe 2-core machines and slow dense solves 10-50x
# (measured in benchmarks/); must be set before numpy/jaxlib load it.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
_XLA = os.environ.get("SOCBJAX_TEST_XLA_FLAGS",
                      "--xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true")
os.environ["XLA_FLAGS"] = " ".join(filter(None, [os.environ.get("XLA_FLAGS", ""), _XLA]))
os.environ.setdefault("SOCBJAX_CACHE_DIR", str(Path(__file__).resolve().parents[1] / ".jax_cache"))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import socbjax  # noqa: E402

socbjax.enable_compilation_cache()

import numpy as np  # noqa: E402
import pytest  # noqa: E402


# The longest files first: with one file per worker (--dist loadfile) a long file scheduled last
# runs alone at the end while the other worker idles (measured: about a minute of the suite).
LONGEST_FIRST = ("test_contact.py", "test_notebooks.py", "test_transformations.py", "test_lawn.py", "test_sampled.py", "test_compress.py",
                 "test_fit_model.py", "test_batch.py", "test_compare.py")


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: file order kept otherwise


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random proper rotation matrix (3×3)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_code():
    """Free each module's compiled executables afterwards: one process runs the whole suite,
    and hundreds of network shapes (3D ones especially) otherwise accumulate in XLA's caches."""
    yield
    import gc

    jax.clear_caches()
    gc.collect()


@pytest.fixture
def traces():
    """Names of the functions JAX traces while the test runs (``jax.monitoring``'s public
    trace event): a cache hit does not trace, so repeated solves must add nothing."""
    names = []

    def listener(event, duration, **kwargs):
        if event == "/jax/core/compile/jaxpr_trace_duration":
            names.append(kwargs.get("fun_name"))

    jax.monitoring.register_event_duration_secs_listener(listener)
    yield names
    jax.monitoring.unregister_event_duration_listener(listener)


def two_filaments():
    """(network, tip node): a cantilever (4 segments, L 1 µm, EI 1 pN·µm²) 0.12 µm above a stiff
    filament (7 segments, EI 1e6), both clamped at the left; the stiff one guided vertically at
    its right end.  Filament–filament contact tests (test_contact, test_paired) press the tip
    onto it."""
    nA, nB = 5, 8
    xa, xb = np.linspace(0, 1, nA), np.linspace(-0.1, 1.3, nB)
    pos = np.concatenate([np.stack([xa, 0 * xa], 1), np.stack([xb, 0 * xb - 0.12], 1)])
    seg = np.array([[i, i + 1] for i in range(nA - 1)] + [[nA + i, nA + i + 1] for i in range(nB - 1)])
    lengths = np.linalg.norm(pos[seg[:, 1]] - pos[seg[:, 0]], axis=1)
    EI_ = np.array([1.0] * (nA - 1) + [1e6] * (nB - 1))
    fixed = ([np.eye(2)] + [np.zeros((0, 2))] * (nA - 1) + [np.eye(2)] + [np.zeros((0, 2))] * (nB - 2)
             + [np.array([[0.0, 1.0]])])
    clamped = np.zeros(nA + nB, bool)
    clamped[[0, nA]] = True
    return socbjax.make_network(pos, np.tile([1.0, 0.0], (nA + nB, 1)), seg, lengths, EI_, fixed_directions=fixed,
                           clamped=clamped), nA - 1
