"""The settings of the path engine (:mod:`socbjax._path`): :class:`PathSettings` (step sizes,
growth, cut-back, budgets, acceptance tests and Newton's tolerances), and the defaults of the
load ramp (:data:`LOAD_RAMP`) and the probe paths (:data:`PROBE_PATH`)."""

from __future__ import annotations

import dataclasses
import itertools

import equinox as eqx
import jax
import numpy as np

from ._checks import MAX_INT32, check_bool, check_choice, check_int, check_real

__all__ = ["PathSettings", "LOAD_RAMP", "PROBE_PATH", "METHODS", "MAX_QUADRATURE_ORDER", "MAX_STEPS_LIMIT"]

METHODS = ("displacement", "load", "natural", "arclength")
MAX_QUADRATURE_ORDER = 16  # integration_matrix (a Vandermonde inverse) error: 7e-14 at 8, 8e-9 at 16, 1e-5 at 20
MAX_STEPS_LIMIT = 1_000_000  # max_steps sizes the compress step buffers: [max_steps, unknowns] per phase
_STEP = {"unit": "path parameter units", "low": 0.0}
_REAL_FIELDS = {
    "initial_step": _STEP, "min_step": _STEP, "max_step": _STEP,
    "grow": {"unit": "factor", "low": 1.0, "low_open": False},
    "max_corrector_ratio": {"unit": "fraction", "low": 0.0},
    "max_turn": {"unit": "rad", "low": 0.0, "high": float(np.pi), "high_open": False},
    "corrector_floor": {"unit": "relative", "low": 0.0},
    "corner_step": {"unit": "path parameter units", "low": 0.0, "low_open": False},
    "atol": {"unit": "dimensionless residual", "low": 0.0},
}
_COUNT_FIELDS = ("max_steps", "max_attempts", "fast_iterations", "max_iterations", "max_backtracks")


class PathSettings(eqx.Module):
    """Numerics of path following (used by :func:`socbjax.solve` and :func:`socbjax.compress`).

    Every field left ``None`` takes the entry point's default (first value: ``solve``'s load
    ramp, step in units of the load factor; second: ``compress``, steps in µm of probe travel
    or of arclength):

    method : "displacement"/"load"/"natural" (natural parameter) or "arclength" (pseudo-arclength).
    initial_step, min_step, max_step : 0.25, 1e-6, 1.0 | 0.02, 1e-7, 0.05 µm.
    max_steps : accepted steps (compress: the capacity of the step buffers): 500 | 1000.
    max_attempts : attempted steps (accepted + rejected): 5000 | 5000.
    grow, fast_iterations : a step converging within ``fast_iterations`` Newton iterations
        multiplies the next by ``grow``: 2.0, 5 | 1.5, 4.  After cut-backs, fast steps
        accepted in a row grow by 4 instead, back to the largest step cut back (a corner of
        the path, passed with tiny steps, is followed by steps of the size before it).
    max_corrector_ratio : reject when the corrector moved farther than this fraction of the
        predicted increment (the path bends too sharply for the step): 0.5 | 0.5.
    max_turn : reject when the tangent turned by more than this (rad) in one step: π | 0.6.
    corrector_floor : absolute floor of that test, relative to 1 + ‖x‖: 1e-9 | 1e-12.
    corner_step : a converged step no longer than this passes a corner of the path, where the
        tangent turns by up to 1.25 rad however small the step (a contact that a floppy strand
        reaches or leaves at nearly zero force: the penalty's band is crossed over a stretch of
        the path far shorter than ``min_step``); the corrector may then move up to 3× the
        predicted increment (tan 1.25 rad ≈ 3).  0 turns it off: 0 | 1e-5 with
        ``method="arclength"`` (at most 1e-3 × the largest step), 0 otherwise (at fixed
        load or displacement a corner step may land on another branch).
    detect_critical_points : reject natural-parameter steps across which sign(det J)
        changes (the path crossed a critical point or jumped branch), and arclength steps
        longer than max(``corner_step``, 2 ``min_step``) across which it changes without a
        fold (a long step across a near-bifurcation lands on the unstable branch): True.
    atol : Newton tolerance on ‖F‖∞ (dimensionless): ``socbjax.default_atol`` | 1e-10.
    max_iterations, max_backtracks : Newton caps: 40, 16 | 25, 12.
    linear_solver : "dense", "sparse" or "auto" (sparse above 1,500 unknowns): "auto".
    quadrature_order : Gauss–Legendre points per SOCB segment (Eq. 7), an integer in 2..16
        (above 16 the segment integration matrix loses accuracy: 1e-8 at 16, 1e-5 at 20): 8.

    Checked at construction (concrete values; traced fields, see :meth:`traced`, pass
    unchecked), so bad settings fail before anything is compiled, naming the field:
    steps, ``max_corrector_ratio``, ``corrector_floor`` and ``atol`` finite and positive
    (``corner_step`` ≥ 0),
    ``min_step <= initial_step <= max_step`` among those given; ``grow`` finite and ≥ 1;
    ``max_turn`` in (0, π]; the counts integers (not booleans, not floats) ≥ 1, at most
    2³¹ − 1 (int32 counters), ``max_steps`` at most 1,000,000 (it sizes the step buffers of
    :func:`socbjax.compress`); ``method``, ``linear_solver`` one of their strings;
    ``detect_critical_points`` a bool.  ``TypeError`` for a wrong type, ``ValueError`` for
    a wrong value.
    """

    method: str | None = eqx.field(static=True, default=None)
    initial_step: float | None = None
    min_step: float | None = None
    max_step: float | None = None
    max_steps: int | None = eqx.field(static=True, default=None)
    max_attempts: int | None = None
    grow: float | None = None
    fast_iterations: int | None = None
    max_corrector_ratio: float | None = None
    max_turn: float | None = None
    corrector_floor: float | None = None
    corner_step: float | None = None
    detect_critical_points: bool = eqx.field(static=True, default=True)
    atol: float | None = None
    max_iterations: int | None = None
    max_backtracks: int | None = None
    linear_solver: str = eqx.field(static=True, default="auto")
    quadrature_order: int = eqx.field(static=True, default=8)

    def __check_init__(self):
        check_choice("PathSettings.method", self.method, METHODS, allow_none=True)
        check_choice("PathSettings.linear_solver", self.linear_solver, ("dense", "sparse", "auto"))
        check_int("PathSettings.quadrature_order", self.quadrature_order, minimum=2, maximum=MAX_QUADRATURE_ORDER)
        check_bool("PathSettings.detect_critical_points", self.detect_critical_points)
        for name, kwargs in _REAL_FIELDS.items():
            value = getattr(self, name)
            if value is not None and not isinstance(value, jax.core.Tracer):
                check_real(f"PathSettings.{name}", value, **kwargs)
        for name in _COUNT_FIELDS:
            value = getattr(self, name)
            if value is not None and not isinstance(value, jax.core.Tracer):
                check_int(f"PathSettings.{name}", value, minimum=1,
                          maximum=MAX_STEPS_LIMIT if name == "max_steps" else MAX_INT32)
        steps = [(n, getattr(self, n)) for n in ("min_step", "initial_step", "max_step")]
        steps = [(n, float(v)) for n, v in steps if v is not None and not isinstance(v, jax.core.Tracer)]
        for (a, u), (b, v) in itertools.pairwise(steps):
            if u > v:
                raise ValueError(f"PathSettings needs min_step <= initial_step <= max_step; got {a}={u:g} > {b}={v:g}")

    def replace(self, **changes) -> PathSettings:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)

    def filled(self, **defaults) -> PathSettings:
        """A copy with every ``None`` field set from ``defaults``, checked."""
        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        values.update({k: v for k, v in defaults.items() if values.get(k) is None})
        out = PathSettings(**values)
        out.check()
        return out

    def check(self) -> None:
        """Validate a filled settings object: every field set (the values themselves are
        checked at construction)."""
        missing = [f.name for f in dataclasses.fields(self) if getattr(self, f.name) is None and f.name != "method"]
        if missing:
            raise ValueError(f"PathSettings fields {missing} are not set; fill them with PathSettings.filled(...)")

    def traced(self) -> PathSettings:
        """The numeric fields as arrays: ``eqx.filter_jit`` traces arrays but holds Python
        numbers static, so new step sizes or tolerances would otherwise recompile."""
        def leaf(v):  # numpy for concrete numbers: traced by filter_jit, no device dispatch here
            return v if isinstance(v, (bool, jax.Array)) or v is None else np.asarray(v)

        return jax.tree_util.tree_map(leaf, self)


LOAD_RAMP = dict(method="natural", initial_step=0.25, min_step=1e-6, max_step=1.0, max_steps=500, max_attempts=5000,
                 grow=2.0, fast_iterations=5, max_corrector_ratio=0.5, max_turn=float(np.pi), corrector_floor=1e-9,
                 corner_step=0.0, max_iterations=40, max_backtracks=16)
PROBE_PATH = dict(method="displacement", initial_step=0.02, min_step=1e-7, max_step=0.05, max_steps=1000,
                  max_attempts=5000, grow=1.5, fast_iterations=4, max_corrector_ratio=0.5, max_turn=0.6,
                  corrector_floor=1e-12, corner_step=1e-5, atol=1e-10, max_iterations=25, max_backtracks=12)
