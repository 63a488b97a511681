"""Shared fixtures and the test session's JAX set-up. float64 is enabled here (socbjax also
enables it on import).

Compilation dominates the suite's time, so the session (and the subprocesses it starts,
which inherit the environment) compiles with XLA's backend optimisation level 0 (about a third less compile time) and
without LLVM's expensive passes (a further ~7 %), the same arithmetic (set ``SOCBJAX_TEST_XLA_FLAGS`` to override,
e.g. to an empty string) — and uses JAX's persistent compilation cache in
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
LONGEST_FIRST = ("test_notebooks.py", "test_transformations.py", "test_lawn.py", "test_sampled.py", "test_compress.py",
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
