"""Models for fitting: a network whose physical parameters are traced jax values.

A :class:`FitModel` declares its parameters (:class:`socbjax.Parameter`: name, unit,
bounds, default) and builds its :class:`Network` from a dict of values with jax operations
only, so :func:`socbjax.compress` — and therefore a fit loss — is differentiable in them.
The topology (nodes, segments, junctions, supports) is fixed when the model is made, at the
default values; parameters change stiffness, geometry and loads, never the structure.

Built-in models (``socbjax.fit(model="...")`` and the command line):

* ``"column"`` (:class:`ColumnModel`): a single filament compressed end to end (paper
  Fig. 5d); parameter ``EI``.
* ``"unit-mesh"`` (:class:`UnitMeshModel`): the unit dendritic mesh (Fig. 6a); ``EI``,
  ``EI_mother``, ``EI_daughter``, ``branch_angle``, ``perturbation``.  The branch angle
  rebuilds the geometry: the daughter leaves the mother's middle at the angle and grows
  straight to the surface, where it is hinged, so its length (L/2)/cos(angle) and its
  hinge point move with the angle (no pre-stress at any angle).
* ``"outcrop"`` (:class:`OutcropModel`): a dendritic outcrop (Fig. 7a) for one seed;
  ``EI``, ``EI_gen0``, ``EI_gen1``, … (per branching order: the first mother is order 0,
  her daughters 1, …) and ``perturbation``.  Its branch angle is not a fit parameter: the
  random growth (which strands reach the surface, how they are cut) changes discretely with
  the angle; fit the angle on the unit mesh, or build outcrops at several angles.

Stiffness groups: a segment takes the value of its group's parameter (``EI_mother``,
``EI_gen2``, …) when that parameter is free or fixed in the fit, else the global ``EI``.
``perturbation`` (pN) is the lateral force per strand.  Left out, the builder's loads (the
outcrop's 1e-4 pN per strand) or :func:`socbjax.compress`'s default 1e-4 EI/L² are used,
scaled with EI, so that forces scale exactly with EI; given (free or fixed), it replaces
them and is passed to :func:`socbjax.compress` (``model.network`` then carries no loads).
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

from ._builders import column
from ._curved import ACTIN_GJ
from ._dendritic import dendritic_outcrop, unit_dendritic_mesh
from ._fit_model import FitModel, contact_shift, data_terms
from ._lawn import LawnModel
from ._network import Network
from ._parameters import Parameter
from ._perturbation import strand_segments
from ._probe import probe_network

__all__ = [
    "FIT_MODELS",
    "ColumnModel",
    "FitModel",
    "LawnModel",
    "OutcropModel",
    "UnitMeshModel",
    "branch_orders",
    "builder_options",
    "contact_shift",
    "data_terms",
    "make_fit_model",
]

_ACTIN_EI = 0.071


def _ei(name: str, doc: str) -> Parameter:
    return Parameter(name, _ACTIN_EI, "pN·µm²", lower=0.0, doc=doc)


_PERTURBATION = Parameter("perturbation", 1e-5, "pN", lower=0.0, doc="lateral force on the middle of every strand")


class ColumnModel(FitModel):
    """A single filament of ``n_nodes`` (µm ``length``) with ``supports``, compressed by its
    last node toward the first (:func:`socbjax.column`)."""

    name = "column"
    size_option, reach_fraction = "length", 0.35  # clamped–pinned: a node crosses a support plane at u ≈ 0.39 L

    def __init__(self, n_nodes: int = 5, *, length: float = 1.0, supports=("clamped", "pinned"), dim: int = 3):
        self.base = probe_network(column(n_nodes, length=length, EI=_ACTIN_EI, supports=supports, dim=dim))
        self.parameters = {"EI": _ei("EI", "bending stiffness"), "perturbation": _PERTURBATION}
        self.groups = {}


class UnitMeshModel(FitModel):
    """The unit dendritic mesh (:func:`socbjax.unit_dendritic_mesh`) with a differentiable
    branch angle; ``branch_angle`` (deg) here is only the default / topology angle.

    ``mother_length`` (µm) sets the size: the mesh is the same shape at every size (forces
    scale as EI/mother_length², displacements with mother_length).  ``segment_length`` (µm,
    default a quarter of the mother: 0.25 µm at the default 1 µm) is the node spacing.  The
    path can be followed to about 0.3–0.44 × mother_length of compression (70°: 0.43) before
    a node crosses the surface (there is no contact model).  ``GJ`` (pN·µm², default actin's
    8e-3; None: torsion-free) as for :func:`socbjax.unit_dendritic_mesh`, held fixed in fits."""

    name = "unit-mesh"
    size_option, reach_fraction = "mother_length", 0.3  # crossing at 0.29 L (80°) .. 0.44 L (55°)

    def __init__(self, *, branch_angle: float = 70.0, mother_length: float = 1.0, segment_length: float | None = None,
                 dim: int = 3, GJ: float | None = ACTIN_GJ):
        if segment_length is None:
            segment_length = 0.25 * mother_length
        self.base = unit_dendritic_mesh(
            EI=_ACTIN_EI, branch_angle=branch_angle, mother_length=mother_length, segment_length=segment_length, dim=dim,
            GJ=GJ,
        )
        self.mother_length = float(mother_length)
        strand = np.asarray(self.base.strand)
        self.groups = {"EI_mother": strand == 0, "EI_daughter": strand == 1}
        seg = np.asarray(self.base.segments)
        self._daughter_nodes = seg[strand == 1, 1]  # in growth order
        self._daughter_base = int(seg[strand == 1, 0][0])
        self._middle = int(np.asarray(self.base.attach)[self._daughter_base])
        lengths = np.asarray(self.base.lengths)[strand == 1]
        self._fractions = np.cumsum(lengths) / lengths.sum()
        self._daughter_segments = np.flatnonzero(strand == 1)
        self.parameters = {
            "EI": _ei("EI", "bending stiffness of all filaments"),
            "EI_mother": _ei("EI_mother", "bending stiffness of the mother"),
            "EI_daughter": _ei("EI_daughter", "bending stiffness of the daughter"),
            "branch_angle": Parameter(
                "branch_angle", float(branch_angle), "deg", lower=0.0, upper=90.0,
                doc="daughter–mother angle at the junction (the daughter grows straight to the surface)",
            ),
            "perturbation": _PERTURBATION,
        }

    def geometry(self, values: dict) -> tuple:
        if "branch_angle" not in values:
            return super().geometry(values)
        phi = jnp.deg2rad(values["branch_angle"])
        d = self.base.dim
        t_d = jnp.cos(phi) * jnp.eye(d)[-1] + jnp.sin(phi) * jnp.eye(d)[0]
        total = 0.5 * self.mother_length / jnp.cos(phi)
        origin = jnp.asarray(self.base.positions)[self._middle]
        nodes = np.concatenate([[self._daughter_base], self._daughter_nodes])
        s = jnp.concatenate([jnp.zeros(1), total * jnp.asarray(self._fractions)])
        positions = jnp.asarray(self.base.positions).at[nodes].set(origin[None, :] + s[:, None] * t_d[None, :])
        tangents = jnp.asarray(self.base.tangents).at[nodes].set(jnp.broadcast_to(t_d, (nodes.size, d)))
        pieces = jnp.diff(s)
        lengths = jnp.asarray(self.base.lengths).at[self._daughter_segments].set(pieces)
        return positions, tangents, lengths


def branch_orders(network: Network) -> np.ndarray:
    """Branching order of every strand [n_strands]: 0 for strands that start at no junction,
    1 + the mother strand's order for a daughter."""
    strand, seg = np.asarray(network.strand), np.asarray(network.segments)
    attach = np.asarray(network.attach)
    mother_of = {}
    for s in range(strand.max() + 1):
        start = seg[strand == s, 0].min(initial=seg.shape[0] * 2)
        first = seg[strand == s][0, 0] if np.any(strand == s) else start
        if attach[first] != first:
            J = attach[first]
            mother_of[s] = int(strand[np.flatnonzero((seg[:, 0] == J) | (seg[:, 1] == J))[0]])
    order = np.zeros(strand.max() + 1, int)
    for s in range(order.size):
        k, depth = s, 0
        while k in mother_of:
            k, depth = mother_of[k], depth + 1
        order[s] = depth
    return order


class OutcropModel(FitModel):
    """A dendritic outcrop (:func:`socbjax.dendritic_outcrop`, arguments passed on: ``GJ``
    defaults to actin's and is held fixed in fits) with EI per branching order."""

    name = "outcrop"

    def __init__(self, **builder):
        builder = {"generations": 4, "gap": 3.0, "dim": 3, **builder}
        builder.pop("EI", None)
        self.base = dendritic_outcrop(EI=_ACTIN_EI, **builder)
        order = branch_orders(self.base)[np.asarray(self.base.strand)]
        self.groups = {f"EI_gen{k}": order == k for k in range(order.max() + 1)}
        self.parameters = {"EI": _ei("EI", "bending stiffness of all filaments")}
        self.parameters.update({k: _ei(k, f"bending stiffness of branching order {k[6:]}") for k in self.groups})
        self.parameters["perturbation"] = _PERTURBATION
        self.n_strands = len(strand_segments(self.base))


FIT_MODELS = {"column": ColumnModel, "unit-mesh": UnitMeshModel, "outcrop": OutcropModel, "lawn": LawnModel}


def make_fit_model(model, **options) -> FitModel:
    """A :class:`FitModel` from a name in ``FIT_MODELS`` (with builder ``options``) or itself.
    A name with the same (hashable) options returns the same object: built-in models are not
    changed after construction, and sharing them lets fits reuse their compiled programs."""
    if isinstance(model, FitModel):
        if options:
            raise ValueError("model options apply to built-in model names only")
        return model
    if model not in FIT_MODELS:
        raise ValueError(f"unknown model {model!r}; use one of {sorted(FIT_MODELS)} or a socbjax.FitModel")
    known = builder_options(model)
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise ValueError(f"unknown option(s) {', '.join(map(repr, unknown))} for the {model} model; it takes "
                         f"{', '.join(known)}")
    key = (model, tuple(sorted(options.items())))
    try:
        hash(key)
    except TypeError:  # e.g. a list option: built afresh
        return _built_model(model, key[1])
    return _shared_model(key)


def _built_model(name: str, options: tuple) -> FitModel:
    try:
        return FIT_MODELS[name](**dict(options))
    except TypeError as err:
        raise ValueError(f"invalid option for the {name} model: {err}") from None


# A built-in model by name and options is built once and shared (models are not changed after
# construction): a fit's compiled program is keyed on the model object, so repeated
# ``fit(curve, "unit-mesh")`` calls compile once, and a lawn's outcrops grow once.
@functools.lru_cache(maxsize=16)
def _shared_model(key: tuple) -> FitModel:
    return _built_model(*key)


def builder_options(model: str) -> list[str]:
    """The keyword options a built-in model takes (the outcrop: those of dendritic_outcrop but EI)."""
    import inspect

    target = dendritic_outcrop if model == "outcrop" else FIT_MODELS[model].__init__
    names = [n for n, p in inspect.signature(target).parameters.items()
             if n != "self" and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    return [n for n in names if n != "EI"]
