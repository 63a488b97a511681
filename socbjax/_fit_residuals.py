"""The residuals of a fit as a pytree (:class:`FitResiduals`), and their Jacobian and loss as
programs compiled once for every curve of a model (:func:`residuals_and_jacobian`).

The data (compressions, forces, σ, bin ranges), the bounds of the free parameters, the probe
travel the path is followed to and the path settings are arrays of the pytree, so a new
curve, a repeated fit or the next curve of :func:`socbjax.fit_batch` reuses the compiled
program; the model, the free names, the fixed values and the number of points are static.
The points sent to the model are padded to a multiple of :data:`TOUCH_CLASS` (the last one
repeated), so curves whose contact starts at different points share a program too.
Units: µm, pN.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._fit_data import bin_evaluation_points, bin_mean_force
from ._fit_model import FitModel, contact_shift, data_terms
from ._parameters import bounded_value
from ._path_settings import PathSettings

__all__ = ["FitResiduals", "residuals_and_jacobian", "loss", "loss_and_gradient", "padded_touch", "TOUCH_CLASS"]

# The number of points sent to the model is rounded up to a multiple of this: at most 7
# repeated equilibria, against a compilation (seconds to minutes) for every new count.
TOUCH_CLASS = 8


class FitResiduals(eqx.Module):
    """``residuals(z [p], throw=False)`` -> r [m] = (F̂(cᵢ; θ(z)) − Fᵢ)/σᵢ, the weighted
    residuals of a fit (model F̂ in :mod:`socbjax._fit_problem`), traced and differentiable;
    NaN where the model's path cannot be followed or its nodes cross the surface (no contact
    model): the optimiser rejects the step.  ``throw=True`` raises instead (untraced use).

    free : the free names, in the order of z; lower, upper : per free name, its bound (a
    0-d array, µm, pN, … in its unit) or None (open side); fixed : name -> fixed value.
    compression, force, sigma, low, high : [m] the data (µm, pN, pN) and each point's bin
    range (µm; :class:`socbjax.FitData`); touch : [k] int, the points that can be in contact
    at some allowed contact shift (the others have model force 0), padded to a multiple of
    :data:`TOUCH_CLASS`.  reach : 0-d, the probe travel the path is followed to (µm).
    retract : [k] bools (the touching points on the retract branch) or None.  method,
    settings : the path's control and its filled :class:`socbjax.PathSettings`.
    """

    model: FitModel = eqx.field(static=True)
    free: tuple = eqx.field(static=True)
    lower: tuple
    upper: tuple
    fixed: dict
    compression: jax.Array
    force: jax.Array
    sigma: jax.Array
    low: jax.Array
    high: jax.Array
    touch: jax.Array
    reach: jax.Array
    retract: tuple | None = eqx.field(static=True)
    method: str = eqx.field(static=True)
    settings: PathSettings

    def to_values(self, z) -> dict:
        """z [p] -> {name: value} (free and fixed parameters, in their units)."""
        values = {n: bounded_value(z[i], self.lower[i], self.upper[i]) for i, n in enumerate(self.free)}
        return {**self.fixed, **values}

    def __call__(self, z, throw: bool = False):
        values = self.to_values(z)
        shift = contact_shift(values)
        u = bin_evaluation_points(self, shift)[self.touch]
        sampled, ok = self.model.probe_force(values, u, reach=self.reach, retract=self.retract, method=self.method,
                                             settings=self.settings, throw=throw)
        # a binned point is the mean over its bin: the bin astride contact is partly at zero
        # force; a repeated (padding) index sets the same value twice
        m = self.compression.shape[0]
        force = bin_mean_force(self, shift, jnp.zeros(m, sampled.dtype).at[self.touch].set(sampled))
        return jnp.where(ok, (data_terms(values, force, self.compression) - self.force) / self.sigma, jnp.nan)


def padded_touch(touch: np.ndarray) -> np.ndarray:
    """``touch`` (sorted point indices) with its last index repeated up to a multiple of
    :data:`TOUCH_CLASS` entries."""
    size = -(-touch.size // TOUCH_CLASS) * TOUCH_CLASS
    return np.concatenate([touch, np.full(size - touch.size, touch[-1])])


@eqx.filter_jit
def residuals_and_jacobian(residuals: FitResiduals, z):
    """(J [m, p], r [m]): the residuals at z [p] and their Jacobian dr/dz (forward mode: p is
    small), one compiled program per model, free names, fixed values and data size."""
    def both(z):
        r = residuals(z)
        return r, r

    return jax.jacfwd(both, has_aux=True)(z)


def _loss(residuals: FitResiduals, z):
    return 0.5 * jnp.sum(residuals(z) ** 2)


@eqx.filter_jit
def loss(residuals: FitResiduals, z):
    """½|r(z)|² (the optax optimisers' line search), compiled as :func:`residuals_and_jacobian`."""
    return _loss(residuals, z)


@eqx.filter_jit
def loss_and_gradient(residuals: FitResiduals, z):
    """(½|r(z)|², its gradient [p]) for the optax optimisers, compiled as
    :func:`residuals_and_jacobian`."""
    return jax.value_and_grad(lambda z: _loss(residuals, z))(z)
