"""A static equilibrium and what users read off it: :class:`Solution`.

A :class:`Solution` is an ``eqx.Module`` pytree (``jax.jit`` can return it, ``jax.vmap``
batches it, ``jax.grad`` differentiates through its arrays).  Besides the nodal fields it
evaluates the smooth SOCB curve between nodes (:meth:`Solution.curve`) and the quantities
of beam theory: end rotations, the maximum deflection, and the support reactions (forces
and clamp couples).  Units: µm, pN, pN·µm, rad.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._checks import check_int, check_vector, is_traced
from ._curve import FilamentCurve, filament_curve
from ._network import Network
from ._solution import RESULTS, result_message
from ._twist import material_frames

__all__ = ["Solution", "node_angles_and_curvatures", "node_stiffness"]

MAX_CURVE_POINTS = 10_000  # points per segment of Solution.curve: far beyond what plots or integrals need


def node_stiffness(network: Network):
    """EI at every node [N] (pN·µm²): the mean over the segments that meet there."""
    seg = np.concatenate([network.segments[:, 0], network.segments[:, 1]])
    total = jnp.zeros(network.n_nodes).at[seg].add(jnp.concatenate([network.EI, network.EI]))
    return total / np.maximum(np.bincount(seg, minlength=network.n_nodes), 1)


def node_angles_and_curvatures(network: Network, tangents, moments):
    """(angles, curvatures) at the nodes of an equilibrium: 2D the tangent angle [N] (rad,
    in (−π, π]) and m/EI [N] (1/µm); 3D (azimuth, elevation) [N, 2] (rad) and the bending
    part of the moment over EI, (m − (m·t) t)/EI [N, 3] (1/µm): a twisting part goes to GJ."""
    EI = node_stiffness(network)
    if network.dim == 2:
        return jnp.arctan2(tangents[:, 1], tangents[:, 0]), moments / EI
    angles = jnp.stack([jnp.arctan2(tangents[:, 1], tangents[:, 0]), jnp.arcsin(jnp.clip(tangents[:, 2], -1, 1))], -1)
    bending = moments - jnp.sum(moments * tangents, axis=1, keepdims=True) * tangents
    return angles, bending / EI[:, None]


class Solution(eqx.Module):
    """A static equilibrium (or, with ``throw=False``, the last accepted state of a failed
    solve: check ``result`` / ``converged``).

    positions : [N, d] node positions (µm).
    tangents : [N, d] unit tangents at nodes.
    angles : 2D [N] angle θ (rad, winding kept); 3D [N, 2] in-plane θ = atan2(t_y, t_x) and
        out-plane φ = asin(t_z) (rad) — for reporting only; the 3D solver uses no angles.
    moments : 2D [N] bending moment (pN·µm); 3D [N, 3] moment vector.
    curvatures : 2D [N] signed curvature dθ/ds (1/µm) relative to the rest shape (m/EI; the
        natural curvature of the segments is added to it); 3D [N, 3] curvature vector t × t'.
    segment_forces : [S, d] internal force per segment (pN).
    reactions : [N, d] support reaction forces (pN), zero at free nodes.
    result : a :class:`socbjax.RESULTS` item; ``converged`` is ``result == successful``.
    load_factor : fraction of the requested loads reached (1.0 when converged).
    iterations, steps, cutbacks, residual_norm : how the load ramp went.
    state : the solver's state (SOCB or jointed); network : the loaded network (its
        ``loads`` and ``couples`` include the applied ones); model : "socb" or "jointed".
    """

    positions: Float[Array, "N d"]
    tangents: Float[Array, "N d"]
    angles: Array
    moments: Array
    curvatures: Array
    segment_forces: Float[Array, "S d"]
    reactions: Float[Array, "N d"]
    result: RESULTS
    iterations: Array
    steps: Array
    cutbacks: Array
    residual_norm: Array
    load_factor: Array
    state: object
    network: Network
    model: str = eqx.field(static=True)

    @property
    def converged(self) -> Array:
        """Boolean array (traced under jit): the full load was reached."""
        return self.result == RESULTS.successful

    def material_frames(self) -> Array:
        """[N, 3, 3] material frames at the nodes, rows (t, d1, d2), of a twisting network
        (3D, built with ``GJ=``); d1 is the reference director ``orthonormal_complement(
        tangent)[0]`` carried along with the rod.  ``ValueError`` for other networks (a
        torsion-free rod has no material frame)."""
        if not self.network.twisting or self.model != "socb":
            raise ValueError("material_frames needs a twisting network (3D, built with GJ=) solved with model='socb'; "
                             "a torsion-free rod has no material frame")
        return material_frames(self.tangents, self.state.twists, self.network)

    @property
    def status_message(self) -> str:
        return result_message(self.result)

    def curve(self, points_per_segment: int = 16) -> FilamentCurve:
        """The smooth filament curve: ``s``, ``positions``, ``tangents``, ``curvature`` and
        ``moment`` at ``points_per_segment`` points of every segment (both ends included;
        :class:`socbjax.FilamentCurve`).  For the jointed model: its rigid bars.
        ``points_per_segment``: an integer from 2 to 10,000."""
        points_per_segment = check_int("points_per_segment", points_per_segment, minimum=2, maximum=MAX_CURVE_POINTS)
        bars = None
        if self.model == "jointed":
            d = self.state.directions
            bars = jnp.stack([jnp.cos(d), jnp.sin(d)], -1) if self.network.dim == 2 else d / jnp.linalg.norm(d, axis=-1, keepdims=True)
        twists = self.state.twists if self.model == "socb" and self.network.twisting else None
        return filament_curve(self.network, self.positions, self.tangents, self.moments, self.segment_forces,
                              points_per_segment=points_per_segment, model=self.model, bar_directions=bars, twists=twists)

    def end_rotation(self, node: int = -1) -> Array:
        """Rotation of the tangent at ``node`` from its reference direction (rad): signed
        (counter-clockwise positive, winding kept) in 2D, the unsigned angle in 3D.  ``node``:
        an integer index, negative ones counted from the end (or a traced one, unchecked)."""
        n = self.network.n_nodes
        if not is_traced(node):  # a traced index stays a dynamic index
            node = check_int("node", node, minimum=-n, maximum=n - 1, hint=f" (the network has {n} nodes)")
        t0 = self.network.tangents[node]
        if self.network.dim == 2:
            return self.angles[node] - jnp.arctan2(t0[1], t0[0])
        t = self.tangents[node]
        return jnp.arctan2(jnp.linalg.norm(jnp.cross(t0, t)), jnp.dot(t0, t))

    def max_deflection(self, points_per_segment: int = 16, axis=None) -> Array:
        """Largest distance (µm) of the smooth curve from the reference axis: the line through
        the first node's reference position along ``axis`` (default: from the first to the
        last node's reference position), e.g. the lateral deflection of a column.  A concrete
        ``axis`` must be a finite non-zero vector of the network's dimension."""
        points_per_segment = check_int("points_per_segment", points_per_segment, minimum=2, maximum=MAX_CURVE_POINTS)
        origin = self.network.positions[0]
        if axis is None:
            axis = self.network.positions[-1] - origin
        elif not is_traced(axis):
            axis = check_vector("axis", axis, self.network.dim, nonzero=True)
        axis = jnp.asarray(axis, jnp.float64)
        axis = axis / jnp.linalg.norm(axis)
        offsets = self.curve(points_per_segment).positions - origin
        lateral = offsets - jnp.sum(offsets * axis, axis=-1, keepdims=True) * axis
        return jnp.max(jnp.linalg.norm(lateral, axis=-1))

    @property
    def reaction_moments(self) -> Array:
        """Couples the clamps apply to the filament (2D [N], 3D [N, 3], pN·µm; zero at
        unclamped nodes): −m at a clamp where a segment starts, +m where one ends."""
        net = self.network
        sign = np.where(net.leaving_segment < net.n_segments, -1.0, 1.0) * net.clamped
        return (sign if net.dim == 2 else sign[:, None]) * self.moments

    def __repr__(self) -> str:
        try:
            tip = np.asarray(self.positions[-1]).round(6).tolist()
            return (f"Solution(model={self.model!r}, converged={bool(self.converged)}, "
                    f"result={self.status_message!r}, load_factor={float(self.load_factor):.4g}, steps={int(self.steps)}, "
                    f"iterations={int(self.iterations)}, residual={float(self.residual_norm):.2e}, last_node={tip})")
        except Exception:  # noqa: BLE001  (traced: no values to show)
            return f"Solution(model={self.model!r}, traced)"
