"""Shared input checks of the public builders, settings and entry points.

Every check runs on the host, before anything is traced or compiled, and raises
``TypeError`` for a value of the wrong type (a string, a boolean or a float where an integer
is needed, a traced value where the topology needs a concrete one) and ``ValueError`` for a
value of the right type that is out of range (NaN, infinite, negative, too large).  Every
message names the argument, shows the value it got and says what would fix it.

Continuous values (positions, tangents, lengths, EI, loads, couples, perturbation) may be JAX
tracers inside ``jax.jit``/``jax.grad``/``jax.vmap``: the checks that need their values are
then skipped (the value is returned as a float64 JAX array).  Topology (counts, indices,
choices) must always be concrete.

Limits (documented in the builders and settings):

* :data:`MAX_SEGMENTS` = 200,000 segments per built network: the builders estimate the size
  from their arguments before building and refuse larger networks, naming the argument.
* :data:`MAX_INT32` = 2³¹ − 1: counts and indices live in int32 arrays and counters.
* :data:`MIN_BRANCH_ANGLE` = 0.1°: junction angles must lie in [0.1°, 179.9°].  A daughter
  (nearly) parallel or antiparallel to its mother overlaps it; measured on the 2D unit mesh,
  compressions stop with "step below its minimum" from about 0.001°, so 0.1° keeps a 100×
  margin.
* :data:`GEOMETRY_RTOL` = 1e-6: relative tolerance of the straight, stress-free reference
  state (unit tangents, tangents parallel to chords, lengths equal to chords).
"""

from __future__ import annotations

import math
import numbers
import operator

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "GEOMETRY_RTOL",
    "MAX_INT32",
    "MAX_SEGMENTS",
    "MIN_BRANCH_ANGLE",
    "check_array",
    "check_bool",
    "check_choice",
    "check_concrete",
    "check_dim",
    "check_index_array",
    "check_int",
    "check_positive_array",
    "check_real",
    "check_size",
    "check_vector",
    "describe",
    "is_traced",
]

MAX_SEGMENTS = 200_000
MAX_INT32 = 2**31 - 1
MIN_BRANCH_ANGLE = 0.1  # degrees
GEOMETRY_RTOL = 1e-6


def is_traced(*trees) -> bool:
    """True if any leaf of ``trees`` is a JAX tracer (inside jit, grad, vmap, ...)."""
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(trees))


def describe(value) -> str:
    """A short ``repr`` of ``value`` with its type, for error messages."""
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{text} ({type(value).__name__})"


def check_concrete(name: str, value, why: str = "it fixes the network's topology"):
    """``value`` itself; a traced JAX value is refused (TypeError) with the reason ``why``."""
    if is_traced(value):
        raise TypeError(f"{name} must be concrete (numpy or Python values), not a traced JAX value: {why}; build it "
                        "outside jax.jit/grad/vmap")
    return value


def _is_bool(value) -> bool:
    return isinstance(value, (bool, np.bool_)) or (hasattr(value, "dtype") and np.dtype(value.dtype) == np.bool_)


def check_int(name: str, value, *, minimum: int | None = None, maximum: int | None = MAX_INT32, hint: str = "") -> int:
    """``value`` as a Python int: an integer (Python, numpy or a 0-d integer array), not a
    boolean nor a float (even an integral one: ``2.0`` is refused with a hint to pass ``2``),
    within [minimum, maximum]; ``hint`` is appended to range errors."""
    check_concrete(name, value, "it is a count or index (topology)")
    if _is_bool(value):
        raise TypeError(f"{name} must be an integer, not a boolean; got {value!r}")
    try:
        v = operator.index(value)
    except TypeError:
        try:
            whole = float(value).is_integer()
        except (TypeError, ValueError):
            whole = None
        fix = f"; pass {name}={int(float(value))}" if whole else (
            "; fractional values are not rounded" if whole is False and math.isfinite(float(value)) else "")
        raise TypeError(f"{name} must be an integer, got {describe(value)}{fix}") from None
    if minimum is not None and v < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {v}{hint}")
    if maximum is not None and v > maximum:
        raise ValueError(f"{name} must be an integer <= {maximum:,}, got {v:,}{hint}")
    return int(v)


def check_bool(name: str, value) -> bool:
    """``value`` as a bool: True/False (or numpy booleans) only, not 0/1 or strings."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {describe(value)}")
    return bool(value)


def check_real(name: str, value, unit: str, *, low: float | None = None, high: float | None = None,
               low_open: bool = True, high_open: bool = True, traced_ok: bool = True):
    """A scalar real number (Python, numpy or a 0-d array, not a boolean) as a float, finite
    and within the interval given by ``low``/``high`` (open ends unless ``low_open``/
    ``high_open`` is False).  A traced value is returned as a float64 JAX scalar when
    ``traced_ok`` (it cannot be checked), else refused."""
    if is_traced(value):
        if not traced_ok:
            check_concrete(name, value, "it fixes the network's topology")
        return jnp.asarray(value, jnp.float64)
    if _is_bool(value):
        raise TypeError(f"{name} must be a number ({unit}), not a boolean; got {value!r}")
    if isinstance(value, numbers.Real) or hasattr(value, "dtype") and np.shape(value) == () and np.dtype(value.dtype).kind in "iuf":
        v = float(value)
    else:
        raise TypeError(f"{name} must be a real number ({unit}), got {describe(value)}")
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite ({unit}), got {v}")
    if low is not None and (v <= low if low_open else v < low):
        bound = ("positive" if low_open else "non-negative") if low == 0 else f"{'>' if low_open else '>='} {low:g}"
        raise ValueError(f"{name} must be {bound} ({unit}), got {v:g}")
    if high is not None and (v >= high if high_open else v > high):
        raise ValueError(f"{name} must be {'<' if high_open else '<='} {high:g} ({unit}), got {v:g}")
    return v


def check_array(name: str, value, unit: str):
    """``value`` as a finite float64 numpy array (numbers only: strings, booleans and other
    objects are refused); a traced value is returned as a float64 JAX array, unchecked."""
    if is_traced(value):
        return jnp.asarray(value, jnp.float64)
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as err:  # ragged nesting
        raise ValueError(f"{name} must be a regular array of numbers ({unit}), got {describe(value)}: {err}") from None
    if arr.dtype.kind == "O":  # e.g. None, a dict, or Python ints beyond int64
        if not all(isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_)) for x in arr.ravel().tolist()):
            raise TypeError(f"{name} must hold real numbers ({unit}), got {describe(value)}")
        arr = arr.astype(np.float64)
    if arr.dtype.kind not in "iuf":
        what = "booleans" if arr.dtype.kind == "b" else f"dtype {arr.dtype}"
        raise TypeError(f"{name} must hold real numbers ({unit}), got {what}: {describe(value)}")
    arr = arr.astype(np.float64)
    bad = ~np.isfinite(arr)
    if bad.any():
        where = np.unravel_index(int(np.argmax(bad)), arr.shape) if arr.ndim else ()
        raise ValueError(f"{name} must be finite ({unit}), without NaN or infinite values; {_entry(where)} "
                         f"{arr[where]}")
    return arr


def check_positive_array(name: str, value, unit: str, *, allow_zero: bool = False):
    """:func:`check_array` whose concrete entries must also be positive (or >= 0)."""
    arr = check_array(name, value, unit)
    if is_traced(arr):
        return arr
    bad = arr < 0 if allow_zero else arr <= 0
    if bad.any():
        where = np.unravel_index(int(np.argmax(bad)), arr.shape) if arr.ndim else ()
        kind = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{name} must be {kind} ({unit}); {_entry(where)} {arr[where]:g}")
    return arr


def _entry(where: tuple) -> str:
    """"got" for a scalar, "entry [i, ...] is" for an array element."""
    return f"entry {[int(i) for i in where]} is" if where else "got"


def check_vector(name: str, value, dim: int, unit: str = "", *, nonzero: bool = False) -> np.ndarray:
    """A concrete finite vector of ``dim`` components (and not the zero vector if
    ``nonzero``)."""
    check_concrete(name, value, "it fixes the network's topology")
    v = check_array(name, value, unit).ravel()
    if v.shape != (dim,):
        raise ValueError(f"{name} must have {dim} components (dim={dim}), got shape {np.shape(value)}: {describe(value)}")
    if nonzero and np.linalg.norm(v) < 1e-12:
        raise ValueError(f"{name} must be a non-zero vector (it gives a direction), got {v.tolist()}")
    return v


def check_index_array(name: str, value, n: int, *, allow_negative: bool = False, what: str = "node index") -> np.ndarray:
    """Concrete indices (any shape) as int64, each in 0..n−1 (−n..n−1 with
    ``allow_negative``).  Integer dtypes only: booleans (a mask is not a list of indices)
    and floats (fractional ones would be truncated) are refused with a TypeError."""
    check_concrete(name, value, f"{what} values are topology")
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} must be a regular array of integers ({what}), got {describe(value)}: {err}") from None
    if arr.size == 0:
        return arr.astype(np.int64)
    if isinstance(value, (list, tuple)) and arr.dtype.kind in "iuf":
        # numpy turns booleans mixed with integers into 0/1 and integers beyond int64 into floats
        items = np.asarray(value, dtype=object)
        if any(isinstance(x, (bool, np.bool_)) for x in items.ravel().tolist()):
            raise TypeError(f"{name} must hold integers ({what}), not booleans (got {describe(value)})")
        if arr.dtype.kind == "f" and all(isinstance(x, numbers.Integral) for x in items.ravel().tolist()):
            arr = items
    if arr.dtype.kind == "b":
        raise TypeError(f"{name} must hold integers ({what}), not booleans (got {describe(value)}); for a mask "
                        "pass np.flatnonzero(mask)")
    if arr.dtype.kind == "f":
        frac = arr[np.isfinite(arr) & (arr != np.round(arr))]
        got = f"the fractional value {float(frac.ravel()[0])!r}" if frac.size else f"floats ({arr.dtype})"
        raise TypeError(f"{name} must hold integers ({what}), got {got}; floats are not rounded: pass integers, "
                        "e.g. np.asarray(..., dtype=int)")
    valid = f"{-n}..{n - 1}" if allow_negative else f"0..{n - 1}"
    if arr.dtype.kind == "O":  # Python ints beyond int64, or a mixture of types
        flat = arr.ravel().tolist()
        if not all(isinstance(x, numbers.Integral) and not isinstance(x, bool) for x in flat):
            raise TypeError(f"{name} must hold integers ({what}), got {describe(value)}")
        bad = next(x for x in flat if not (-n if allow_negative else 0) <= x < n)
        raise ValueError(f"{name} has the {what} {bad}, outside the valid range {valid}")
    if arr.dtype.kind not in "iu":
        raise TypeError(f"{name} must hold integers ({what}), got dtype {arr.dtype}: {describe(value)}")
    out = (arr < (-n if allow_negative else 0)) | (arr >= n)
    if out.any():
        raise ValueError(f"{name} has the {what} {arr.ravel()[np.argmax(out.ravel())]}, outside the valid range {valid}")
    return arr.astype(np.int64)


def check_size(name: str, value, count, *, fix: str, what: str = "segments", limit: int = MAX_SEGMENTS) -> None:
    """Refuse a network whose estimated ``count`` of segments exceeds ``limit`` (before
    building it), naming the argument ``name=value`` that makes it so."""
    if count > limit:
        shown = f"{count:,.0f}" if math.isfinite(count) else "infinitely many"
        raise ValueError(f"{name}={value!r} would build {shown} {what}, more than the limit of {limit:,} "
                         f"(socbjax._checks.MAX_SEGMENTS); {fix}")


def check_choice(name: str, value, choices, *, allow_none: bool = False):
    """``value`` if it is one of the strings ``choices`` (or None when ``allow_none``)."""
    if value is None and allow_none:
        return None
    if not isinstance(value, str):
        raise TypeError(f"{name} must be one of {tuple(choices)} (a string), got {describe(value)}")
    if value not in choices:
        raise ValueError(f"{name} must be one of {tuple(choices)}, got {value!r}")
    return value


def check_dim(dim) -> int:
    """The spatial dimension: the integer 2 or 3 (``2.0`` is refused like every float count)."""
    dim = check_int("dim", dim)
    if dim not in (2, 3):
        raise ValueError(f"dim must be 2 or 3 (planar or spatial), got {dim}")
    return dim
