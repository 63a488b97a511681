"""Fit parameters: names, units, bounds and the transforms that enforce the bounds.

A :class:`Parameter` is a physical value with optional bounds.  The optimiser works on an
unconstrained number z; the value is

* lower and upper bound: ``lower + (upper − lower) · sigmoid(z)`` (e.g. a branch angle in
  (0°, 90°)),
* lower bound only: ``lower + exp(z)`` (e.g. EI > 0, a force scale > 0),
* no bounds: ``z`` itself (e.g. a contact-point offset or a force baseline),

so every value an optimiser can reach is admissible and no step is ever clipped.  Standard
errors are mapped from z to the value with the transform's derivative (delta method).
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import check_real

__all__ = ["Parameter", "NUISANCE_PARAMETERS", "bounded_value"]


def bounded_value(z, lower, upper):
    """The value of unconstrained z (jax or float) inside the open bounds ``lower``,
    ``upper`` (numbers or arrays, e.g. traced in a compiled fit; None: unbounded side), by
    the transforms of the module docstring."""
    if lower is not None and upper is not None:
        return lower + (upper - lower) * jax.nn.sigmoid(z)
    if lower is not None:
        return lower + jnp.exp(z)
    if upper is not None:
        return upper - jnp.exp(-z)
    return z


@dataclasses.dataclass(frozen=True)
class Parameter:
    """One model or data parameter.

    name : identifier used by ``fit(free=..., fixed=...)`` and the command line.
    value : default / initial value (in ``unit``), a finite real number.
    unit : e.g. "pN·µm²", "deg", "µm", "pN", "1".
    lower, upper : open bounds, finite real numbers with lower < upper (None: unbounded on
        that side).
    doc : one line: what it is.

    Checked at construction: ``TypeError`` for a non-string name/unit/doc or a non-number
    (including booleans), ``ValueError`` for NaN/infinite numbers or crossed bounds.
    """

    name: str
    value: float
    unit: str
    lower: float | None = None
    upper: float | None = None
    doc: str = ""

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise TypeError(f"Parameter name must be a non-empty string, got {self.name!r}")
        for field in ("unit", "doc"):
            if not isinstance(getattr(self, field), str):
                raise TypeError(f"parameter {self.name}: {field} must be a string, got {getattr(self, field)!r}")
        check_real(f"parameter {self.name}: value", self.value, self.unit, traced_ok=False)
        for field in ("lower", "upper"):
            if getattr(self, field) is not None:
                check_real(f"parameter {self.name}: {field}", getattr(self, field), self.unit, traced_ok=False)
        lo, hi = self.lower, self.upper
        if lo is not None and hi is not None and not lo < hi:
            raise ValueError(f"parameter {self.name}: lower bound {lo} must be below upper bound {hi}")

    def check(self, value: float, what: str = "value") -> float:
        """``value`` as a float strictly inside the bounds, else ValueError naming them."""
        v = float(value)
        if not math.isfinite(v):
            raise ValueError(f"{self.name} {what} must be finite, got {value!r}")
        if (self.lower is not None and v <= self.lower) or (self.upper is not None and v >= self.upper):
            raise ValueError(
                f"{self.name} {what} {v:g} {self.unit} is outside its bounds ({self.lower}, {self.upper}); "
                "choose a value strictly inside or change the bounds"
            )
        return v

    def with_bounds(self, lower, upper) -> Parameter:
        return dataclasses.replace(self, lower=lower, upper=upper)

    def to_value(self, z):
        """Unconstrained z (jax or float) -> value."""
        return bounded_value(z, self.lower, self.upper)

    def to_z(self, value: float) -> float:
        """Value -> unconstrained z (host side)."""
        v, lo, hi = self.check(value), self.lower, self.upper
        if lo is not None and hi is not None:
            q = (v - lo) / (hi - lo)
            return float(np.log(q) - np.log1p(-q))
        if lo is not None:
            return float(np.log(v - lo))
        if hi is not None:
            return float(-np.log(hi - v))
        return v


NUISANCE_PARAMETERS = {
    p.name: p
    for p in (
        Parameter("contact_point", 0.0, "µm",
                  doc="where on the data's compression axis the model's contact begins: the model sees c − contact_point"),
        Parameter("contact_offset", 0.0, "µm",
                  doc="added to the data's compression (= −contact_point; use one of the two)"),
        Parameter("baseline", 0.0, "pN", doc="force offset added to the model force"),
        Parameter("baseline_tilt", 0.0, "pN/µm", doc="baseline slope: adds baseline_tilt × compression to the model force"),
        Parameter(
            "force_scale", 1.0, "1", lower=0.0,
            doc="multiplies the model force (e.g. the number of outcrops under the probe)",
        ),
    )
}
