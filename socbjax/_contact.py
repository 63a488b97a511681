"""Contact with rigid frictionless obstacles: :class:`Plane`, :class:`Sphere` and the
settings :class:`Contact` (``solve(..., contact=...)``, ``compress(..., contact=...)``).

Units: µm, pN.  A filament of diameter d touches an obstacle when the signed distance φ of
its axis from the obstacle's surface reaches d/2; the *gap* is g = φ − d/2 (µm, negative =
penetration).  Each (segment, obstacle) pair carries one contact slot: the closest point of
the segment's smooth SOCB curve to the obstacle (not a node: with 0.25–0.5 µm segments most
contacts fall between nodes), where the contact force acts as an interior point force,
carried exactly by the segment equations (:mod:`socbjax._contact_segment`,
``docs/equations.md`` "Contact").  On networks of more than 96 segments, with planes only
and no self-contact, only the segments nearest to a plane evaluate that kernel; far from
every plane a slot is idle and its segment's equations are the contact-free ones
(``Contact.slot_capacity``, :mod:`socbjax._contact_near`).

Contact law: a C² penalty on the gap (frictionless, along the obstacle's normal at the
contact point),

    f(g) = (k δ / 3) (1 − g/δ)³  for g < δ,   f(g) = 0  for g ≥ δ,

with activation distance δ (µm) and stiffness k = −f'(0) (pN/µm).  f, f' and f'' vanish at
g = δ, so the residual is C² and Newton, continuation and implicit derivatives see a smooth
problem.  Penetration bound: f is decreasing, so a contact that carries the force F sits at
g = δ (1 − (3F/(kδ))^{1/3}); it penetrates by less than p·d exactly when
F < (kδ/3)(1 + p d/δ)³.  The defaults (δ = d/10, k from :attr:`Contact.force_limit`) keep
the penetration below 1 % of d up to that force; ``CompressionResult.min_gap`` reports the
actual gap of every step.  The residual states the law as H(F·n) = H(f(g)) with one
increasing map H (:func:`socbjax._contact_segment.force_law_rows`): the same solutions, but
linear in the gap where the law is stiffer than the filament, so Newton comes out of a deep
guess in a few steps instead of walking down the cube of the depth.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._checks import check_array, check_bool, check_int, check_real, describe

__all__ = ["Plane", "Sphere", "Contact", "DEFAULT_DIAMETER", "penalty_force"]

DEFAULT_DIAMETER = 0.007  # µm: an actin filament (7 nm)


def _point(name: str, value, dim: int | None = None) -> np.ndarray:
    v = check_array(name, value, "µm")
    if not isinstance(v, np.ndarray):
        raise TypeError(f"{name} must be concrete numbers (µm); obstacles fix the contact set-up, got a traced value")
    v = v.ravel()
    if v.shape not in ((2,), (3,)) or (dim is not None and v.shape != (dim,)):
        want = f"{dim}" if dim is not None else "2 or 3"
        raise ValueError(f"{name} must have {want} components (x, y[, z]), got {describe(value)}")
    return v


class Plane(eqx.Module):
    """A rigid frictionless plane through ``point`` (µm, [d]) with unit ``normal`` ([d],
    normalised here) pointing to the allowed side: filament axes stay at distance ≥ d/2 on
    that side.  In 2D a plane is a line."""

    point: np.ndarray
    normal: np.ndarray

    def __init__(self, point, normal):
        p = _point("Plane point", point)
        n = _point("Plane normal", normal, p.size)
        length = float(np.linalg.norm(n))
        if length < 1e-12:
            raise ValueError(f"Plane normal must be a non-zero vector (it points to the allowed side), got {n.tolist()}")
        self.point, self.normal = p, n / length

    @property
    def dim(self) -> int:
        return int(self.point.size)


class Sphere(eqx.Module):
    """A rigid frictionless sphere (a disc in 2D) of ``radius`` µm around ``center`` (µm,
    [d]); ``radius=0`` is a point obstacle.  Filament axes stay at distance ≥ radius + d/2
    from the center."""

    center: np.ndarray
    radius: float

    def __init__(self, center, radius=0.0):
        self.center = _point("Sphere center", center)
        self.radius = check_real("Sphere radius", radius, "µm", low=0.0, low_open=False, traced_ok=False)

    @property
    def dim(self) -> int:
        return int(self.center.size)


def _obstacles(name: str, value, kind) -> tuple:
    if value is None:
        return ()
    if isinstance(value, kind):
        return (value,)
    if not isinstance(value, (tuple, list)) or not all(isinstance(v, kind) for v in value):
        raise TypeError(f"{name} must be a tuple of socbjax.{kind.__name__} (e.g. {name}=(socbjax.{kind.__name__}"
                        f"(...),)), got {describe(value)}")
    return tuple(value)


class Contact(eqx.Module):
    """Contact settings (frictionless; see the module docstring for the law).

    diameter : filament diameter d (µm; default 0.007, actin).
    planes : extra rigid planes (:class:`Plane`), e.g. the walls of a channel.
    obstacles : rigid spheres / point obstacles (:class:`Sphere`).
    self_contact : contact between non-adjacent pieces of filament (any two segments that do
        not share a node: other filaments and the same one), found by a fixed-capacity
        spatial-hash broad phase (:mod:`socbjax._contact_pairs`).  The pairs change the
        Jacobian's pattern from step to step: the sparse solver follows them
        (:class:`socbjax.PairedSparseLU`, colours per pair list; a list that needs more
        colours than it prepared is ``RESULTS.colour_capacity``, which
        :func:`socbjax.compress` mends by doubling them, with a warning).
    capacity : pair slots (default max(8, S) for S segments); more candidates stop the path
        with ``RESULTS.contact_capacity``.
    per_segment : most pairs per segment (default 4; a hash cell holds up to twice as many
        segments).  Each adds an interior force to every segment's kernel: keep it small.
    reach : µm beyond touching at which a pair enters the list (default max(l/4, 20 δ), l the
        mean segment length); a path step may move no segment farther than reach/2.
    surfaces : add the probe face (moving with the probe) and the substrate (the plane of the
        farthest opposing support) for networks with a probe.
    activation : δ (µm) at which the contact force starts; default d/10.
    stiffness : k = −f'(0) (pN/µm); default: the value that keeps the penetration below 1 % of
        d up to ``force_limit``.
    force_limit : the contact force (pN) up to which the default stiffness keeps the
        penetration below 1 % of d; default 0.1 EI/d² (mean EI): a force that bends the
        filament on the scale of its own diameter, beyond the rod model (actin: 84 pN).  It
        depends on the material, not on the discretisation: refining the nodes keeps the law.
    slot_capacity : the most segments that carry the contact kernel at once (the segments
        nearest to an obstacle, listed before each path step; the others carry the
        contact-free kernel and idle slots, :mod:`socbjax._contact_near`).  Default: all
        segments up to 96, else max(96, S/3).  More segments within ``reach`` of the contact
        band than K: :func:`socbjax.compress` doubles K, warns and goes on from its last step
        (one more compilation); ``solve`` and traced compressions stop with
        ``RESULTS.contact_capacity``.  Planes only, without
        self-contact (a sphere's or a pair's slot is never idle); give S or more for every
        segment.
    lumped : for comparison only: put each contact force on the segment's two nodes
        ((1 − σ)F and σF) instead of carrying it at its point (what node-based codes do; see
        ``docs/equations.md`` "Contact" for how much worse it is).
    """

    diameter: float = DEFAULT_DIAMETER
    planes: tuple = ()
    obstacles: tuple = ()
    self_contact: bool = True
    surfaces: bool = True
    activation: float | None = None
    stiffness: float | None = None
    force_limit: float | None = None
    lumped: bool = False
    capacity: int | None = None
    per_segment: int = 4
    reach: float | None = None
    slot_capacity: int | None = None

    def __init__(self, diameter=DEFAULT_DIAMETER, planes=(), self_contact=True, surfaces=True, *, obstacles=(),
                 activation=None, stiffness=None, force_limit=None, lumped=False, capacity=None, per_segment=4,
                 reach=None, slot_capacity=None):
        self.diameter = check_real("Contact diameter", diameter, "µm", low=0.0, traced_ok=False)
        self.planes = _obstacles("planes", planes, Plane)
        self.obstacles = _obstacles("obstacles", obstacles, Sphere)
        self.self_contact = check_bool("self_contact", self_contact)
        self.surfaces = check_bool("surfaces", surfaces)
        opt = lambda name, v, unit: None if v is None else check_real(name, v, unit, low=0.0, traced_ok=False)  # noqa: E731
        self.activation = opt("activation", activation, "µm")
        self.stiffness = opt("stiffness", stiffness, "pN/µm")
        self.force_limit = opt("force_limit", force_limit, "pN")
        self.lumped = check_bool("lumped", lumped)
        if self.lumped and self.self_contact:
            raise ValueError("lumped=True (a comparison of obstacle contact) needs self_contact=False; got "
                             "self_contact=True")
        self.capacity = None if capacity is None else check_int("capacity", capacity, minimum=1, maximum=10**6)
        self.per_segment = check_int("per_segment", per_segment, minimum=1, maximum=1024)
        self.reach = opt("reach", reach, "µm")
        self.slot_capacity = None if slot_capacity is None else check_int("slot_capacity", slot_capacity, minimum=1,
                                                                          maximum=10**7)
        if self.slot_capacity is not None and (self.self_contact or self.obstacles):
            raise ValueError(f"slot_capacity={self.slot_capacity} lists the segments near planes; it needs "
                             f"self_contact=False and no spheres (got self_contact={self.self_contact}, "
                             f"{len(self.obstacles)} spheres): leave slot_capacity=None")

    def as_dict(self) -> dict:
        """JSON-able description (stored in a compression result's ``parameters["contact"]``,
        drawn by the figures)."""
        return {"diameter_um": self.diameter, "surfaces": self.surfaces, "self_contact": self.self_contact,
                "planes": [{"point_um": p.point.tolist(), "normal": p.normal.tolist()} for p in self.planes],
                "spheres": [{"center_um": o.center.tolist(), "radius_um": o.radius} for o in self.obstacles],
                "activation_um": self.activation, "stiffness_pN_per_um": self.stiffness,
                "force_limit_pN": self.force_limit, "lumped": self.lumped,
                "slot_capacity": self.slot_capacity}

    def near_capacity(self, n_segments: int) -> int:
        """K segments with the contact kernel for a network of ``n_segments`` (0: every
        segment; see ``slot_capacity``)."""
        if self.self_contact or self.obstacles:
            return 0
        K = max(96, -(-n_segments // 3)) if self.slot_capacity is None else self.slot_capacity
        return 0 if K >= n_segments else K

    def law(self, EI_mean) -> tuple:
        """(δ µm, k pN/µm) of this contact for a network of mean EI (pN·µm²): the defaults of
        the class docstring where not given."""
        delta = self.diameter / 10 if self.activation is None else self.activation
        if self.stiffness is not None:
            return delta, self.stiffness
        force = 0.1 * EI_mean / self.diameter**2 if self.force_limit is None else self.force_limit
        return delta, 3.0 * force / (delta * (1.0 + 0.01 * self.diameter / delta) ** 3)


def penalty_force(gap, activation, stiffness):
    """f(g) = (k δ/3)(1 − g/δ)³ for g < δ, else 0 (pN): the C² contact law (gap µm)."""
    x = jnp.maximum(1.0 - gap / activation, 0.0)
    return stiffness * activation / 3.0 * x**3
