"""The base of every fit model, :class:`FitModel`: parameters, the network at values, and the
force a model predicts for a curve (:meth:`FitModel.predict`), with the curve's own terms
(contact point, baseline and tilt, force scale; :func:`data_terms`).  Units: µm, pN, pN·µm².
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._compress import compress
from ._geometry import minimal_rotation
from ._network import Network
from ._parameters import NUISANCE_PARAMETERS, Parameter
from ._probe import probe_gap
from ._solution import RESULTS

__all__ = ["FitModel", "contact_shift", "data_terms"]


class FitModel:
    """Base class: ``parameters`` (name -> Parameter), ``groups`` (name -> segment mask [S]),
    ``base`` (the network at the defaults) and :meth:`network` (values -> Network, traced)."""

    name = "model"
    base: Network
    parameters: dict[str, Parameter]
    groups: dict[str, np.ndarray]

    # The builder option that scales the model (all lengths with it) and the fraction of it the
    # path can typically follow before a node crosses the surface (there is no contact model):
    # used to suggest a model large enough for a curve.  None: no such option.
    size_option: str | None = None
    reach_fraction: float = 1.0

    @property
    def gap(self) -> float:
        """Largest probe travel the model can reach (µm): the probe–surface distance."""
        return probe_gap(self.base)

    def size_for(self, reach: float) -> float | None:
        """A value of :attr:`size_option` (µm, rounded up) whose model can typically be
        compressed by ``reach`` µm before its nodes cross the surface; None if the model has
        no size option."""
        if self.size_option is None:
            return None
        need = float(reach) / self.reach_fraction
        step = 10.0 ** np.floor(np.log10(need)) / 5  # round up to 2 significant digits, even: 1.2, 1.4, .., 12, 14
        return float(np.ceil(need / step) * step)

    def describe(self) -> str:
        lines = [f"{self.name}: {self.base.n_nodes} nodes, {self.base.n_segments} segments, {self.base.n_junctions} junctions"]
        for p in self.parameters.values():
            lines.append(f"  {p.name:<14s} default {p.value:<10.4g} {p.unit:<8s} bounds ({p.lower}, {p.upper})  {p.doc}")
        return "\n".join(lines)

    def stiffness(self, values: dict) -> jnp.ndarray:
        """EI per segment [S] (pN·µm²) from the global and group values."""
        EI = jnp.full((self.base.n_segments,), 1.0) * values.get("EI", self.parameters["EI"].value)
        for name, mask in self.groups.items():
            if name in values:
                EI = jnp.where(jnp.asarray(mask), values[name], EI)
        return EI

    def geometry(self, values: dict) -> tuple:
        """(positions [N, d], tangents [N, d], lengths [S]); default: the base geometry."""
        return self.base.positions, self.base.tangents, self.base.lengths

    def network(self, values: dict) -> Network:
        """The network at ``values`` (name -> float or traced scalar; missing: defaults)."""
        unknown = set(values) - set(self.parameters)
        if unknown:
            raise ValueError(f"{self.name} has no parameter(s) {sorted(unknown)}; it has {sorted(self.parameters)}")
        positions, tangents, lengths = self.geometry(values)
        EI = self.stiffness(values)
        if "perturbation" in values:  # given explicitly: compress(perturbation=...) applies it
            loads = jnp.zeros_like(self.base.loads)
        else:  # the builder's loads, scaled with EI so that forces scale exactly with EI
            loads = self.base.loads * (jnp.mean(EI) / jnp.mean(jnp.asarray(self.base.EI)))
        changes = dict(positions=positions, tangents=tangents, lengths=lengths, EI=EI, loads=loads)
        if self.base.twisting:  # reference directors carried to the (possibly traced) new tangents
            unit = lambda v: v / jnp.linalg.norm(v, axis=-1, keepdims=True)  # noqa: E731
            changes["directors"] = minimal_rotation(unit(jnp.asarray(self.base.tangents)), unit(tangents),
                                                    jnp.asarray(self.base.directors))
        return self.base.replace(**changes)


    def probe_force(self, values: dict, u, *, reach: float, retract=None, method: str = "displacement",
                    settings=None, throw: bool = False) -> tuple:
        """(force [m], ok): the model's probe force (pN, compressive positive) at probe
        displacements ``u`` [m] (µm; 0 at and before contact), on the loading branch, or, where
        ``retract`` [m] (bool, concrete) is True, on the unloading one (one path, withdrawn
        after ``reach``); ``reach`` (µm, concrete) is how far the path is followed (``u`` is
        clipped to it).  ``ok`` (traced bool) is False when the path fails
        or nodes cross the surface or the probe plane (no contact model: not physical).
        Traced and differentiable in ``values`` and ``u``; subclasses that are not one
        network (e.g. :class:`socbjax.LawnModel`) override this."""
        u = jnp.asarray(u, jnp.float64)
        network = self.network({n: v for n, v in values.items() if n in self.parameters})
        floor = 1e-6 * reach
        result = compress(network, reach, at=jnp.clip(u, floor, reach), unload=retract is not None, method=method,
                          settings=settings, perturbation=values.get("perturbation"), throw=throw)
        force = result.force[:u.shape[0]]
        if retract is not None:
            force = jnp.where(np.asarray(retract, bool), result.force[u.shape[0]:][::-1], force)
        ok = jnp.all(result.converged) & (result.result != RESULTS.surface_crossed)
        return jnp.where(u > 0, force, 0.0), ok

    def predict(self, values: dict, compression, *, reach: float | None = None, branch: str = "loading",
                method: str = "displacement", settings=None) -> jnp.ndarray:
        """The force (pN) the model predicts at the data compressions ``compression`` [m] (µm):

            F̂ = force_scale · F(c − contact_point + contact_offset) + baseline + baseline_tilt · c,

        F the probe force of :meth:`probe_force` (0 before contact), the data terms from
        ``values`` (defaults 1, 0).  ``values``: name -> value (floats or traced scalars;
        missing model parameters take their defaults), differentiable (``jax.grad``,
        ``jax.jacfwd``).  ``branch`` "loading" (approach) or "unloading" (retract).  ``reach``
        (µm): how far the path is followed; default the largest probe travel the points need
        (with concrete contact terms) or 1.5 × the largest compression (traced), at most
        0.95 × the gap.  NaN where the model cannot be followed (path failure, surface crossing)."""
        if branch not in ("loading", "unloading"):
            raise ValueError(f"branch must be 'loading' or 'unloading', got {branch!r}")
        unknown = set(values) - set(self.parameters) - set(NUISANCE_PARAMETERS)
        if unknown:
            raise ValueError(f"{self.name} has no parameter(s) {sorted(unknown)}; it has "
                             f"{sorted(set(self.parameters) | set(NUISANCE_PARAMETERS))}")
        c = jnp.asarray(compression, jnp.float64)
        if c.ndim != 1 or c.shape[0] < 1:
            raise ValueError(f"compression must be a 1-D array of compressions (µm), got shape {c.shape}")
        u = c + contact_shift(values)
        if reach is None:
            if isinstance(u, jax.core.Tracer):  # traced contact terms: leave room for them
                reach = 1.5 * float(np.max(np.asarray(compression)))
            else:
                reach = float(np.max(np.asarray(u)))
            reach = min(reach, 0.95 * self.gap)
        retract = np.ones(c.shape[0], bool) if branch == "unloading" else None
        force, ok = self.probe_force(values, u, reach=max(float(reach), 1e-6), retract=retract, method=method,
                                     settings=settings)
        return jnp.where(ok, data_terms(values, force, c), jnp.nan)


def contact_shift(values: dict):
    """µm added to the data's compression to give the probe travel: contact_offset − contact_point."""
    return values.get("contact_offset", 0.0) - values.get("contact_point", 0.0)


def data_terms(values: dict, force, compression):
    """force_scale · force + baseline + baseline_tilt · compression (pN): the curve's own terms."""
    return (values.get("force_scale", 1.0) * force + values.get("baseline", 0.0)
            + values.get("baseline_tilt", 0.0) * compression)
