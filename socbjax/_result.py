"""Result of a displacement-controlled compression: :class:`CompressionResult`.

An ``eqx.Module`` pytree (``jax.jit`` can return it; ``compress(..., at=...)`` is traced end
to end): one row per recorded equilibrium along the path, in path order — the settled start
(phase 0), the loading steps (phase 1), the unloading steps (phase 2) — or, sampled with
``at=``, one row per requested displacement.  Units: µm, pN, pN·µm.
"""

from __future__ import annotations

import dataclasses
import json
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ._equilibrium import Solution, node_angles_and_curvatures
from ._network import Network
from ._residual import SOCBState, net_nodal_force, support_reactions
from ._solution import RESULTS, result_message

__all__ = ["CompressionResult", "LimitPoint", "PHASES"]

PHASES = ("settle", "loading", "unloading")


@dataclasses.dataclass(frozen=True)
class LimitPoint:
    """An event between two recorded steps of the path.

    kind : "force_maximum" / "force_minimum" (local extremum of the probe force along the
        path: the limit load a force-controlled test would snap at), "fold" (the probe
        displacement turns back: a snap-back, only on arclength paths) or "bifurcation"
        (sign(det J) changes without a fold: a critical point of the tangent stiffness), or
        "surface_crossing" (the first step with a node beyond the surface or behind the probe
        plane; the result is then ``RESULTS.surface_crossed``: computed without contact).
    step : index of the recorded step at (or just after) the event.
    displacement, force : probe displacement (µm) and force (pN) at that step.
    phase : "loading" or "unloading".
    """

    kind: str
    step: int
    displacement: float
    force: float
    phase: str


class CompressionResult(eqx.Module):
    """A compression (and optional withdrawal) path; see :func:`socbjax.compress`.

    displacement : [K] probe displacement from the as-built position along the probe
        direction (µm, compression positive).
    force : [K] probe reaction along the compression axis (pN, compressive positive).
    converged : [K] bool, the row is a converged equilibrium (path steps always are: failed
        attempts are cut back and never recorded; sampled rows may not be reached).
    stable : [K] bool, sign(det J) equals that of the settled start state: an even number of
        unstable modes (a parity indicator of stability, see docs/equations.md).
    phase : [K] int, 0 settle, 1 loading, 2 unloading (names in ``PHASES``).
    positions, tangents : [K, N, d] node positions (µm) and unit tangents.
    moments : [K, N] (2D, pN·µm) or [K, N, 3] (3D) nodal bending moments.
    segment_forces : [K, S, d] internal force per segment (pN).
    twists : [K, N] material-frame angles ψ (rad) of a twisting network (built with ``GJ=``),
        [K, 0] otherwise; with the tangents they give the material frames of every step.
    end_nodes : [E] supported non-probe nodes (strand ends on the surface).
    end_forces : [K, E] axial force on each strand end (pN, compressive positive).
    iterations : [K] Newton iterations of each step.
    contact_count : [K] int, contacts carrying force (0 without contact).
    min_gap : [K] smallest surface-to-surface gap of the contact slots (µm; negative =
        penetration; NaN without contact).  Exact (the closest points of the smooth curves)
        for slots near contact (within max(10 δ, l/20)); farther, a slot rests at its
        segment's middle and its gap is an upper bound.
    contact_force : [K] sum of the contact force magnitudes (pN; 0 without contact).
    contact_points, contact_forces : [K, c, d] the c = S·C contact slots' points (µm) and
        forces on the filament (pN; zero where not in contact); c = 0 without contact.
    reactions : [K, N, d] the force each support exerts on its node (pN; zero at free nodes;
        the probe nodes' along the compression axis make up ``force`` with the probe face's
        contacts), as :attr:`socbjax.Solution.reactions` per step: with the loads and the
        contact forces they balance every filament.  NaN in files written before format 6.
    result : :class:`socbjax.RESULTS` item of the whole protocol (successful: every phase
        completed and, when sampled, every sample converged).
    network : the compressed network, its ``loads`` the applied ones (perturbation included).
    limit_points : events found along the path (:class:`LimitPoint`; empty when sampled).
    parameters : JSON-able dict of the run's settings (and builder parameters if given).
    """

    displacement: Array
    force: Array
    converged: Array
    stable: Array
    phase: Array
    positions: Array
    tangents: Array
    moments: Array
    segment_forces: Array
    twists: Array
    end_nodes: Array
    end_forces: Array
    iterations: Array
    result: RESULTS
    network: Network
    contact_count: Array | None = None
    min_gap: Array | None = None
    contact_force: Array | None = None
    contact_points: Array | None = None
    contact_forces: Array | None = None
    reactions: Array | None = None
    limit_points: tuple = eqx.field(static=True, default=())
    parameters_json: str = eqx.field(static=True, default="{}")

    def __post_init__(self):
        # A result built without contact outputs (by hand, or by an older reader) reports no
        # contact: count 0, gap NaN (no obstacle), force 0, no slots.
        if self.contact_count is None:
            K, d = np.shape(self.displacement)[0], self.network.dim
            self.contact_count, self.min_gap = np.zeros(K, np.int32), np.full(K, np.nan)
            self.contact_force, self.contact_points, self.contact_forces = np.zeros(K), np.zeros((K, 0, d)), np.zeros((K, 0, d))
        if self.reactions is None:  # not recorded (a file before format 6, a result built by hand)
            K, N, d = np.shape(self.displacement)[0], self.network.n_nodes, self.network.dim
            self.reactions = np.full((K, N, d), np.nan)

    @property
    def parameters(self) -> dict[str, Any]:
        return json.loads(self.parameters_json)

    @property
    def obstacle_forces(self) -> np.ndarray:
        """[K, C, d] the total force (pN) the filaments exert on each obstacle at each step, in
        the order of ``parameters["contact"]["obstacles"]`` ("probe face", "substrate",
        "plane i", "sphere i"): minus the sum of its slots' ``contact_forces``.  [K, 0, d]
        without contact.  With the support ``reactions`` and the loads, the filaments balance:
        Σ reactions + Σ loads = Σ obstacle forces (without filament–filament contact)."""
        K, d, S = np.shape(self.displacement)[0], self.network.dim, self.network.n_segments
        contact = self.parameters.get("contact")
        if contact is None:
            return np.zeros((K, 0, d))
        if "obstacles" not in contact:
            raise ValueError("this result was computed before socbjax recorded its obstacles' names "
                             "(parameters['contact']['obstacles']); re-run the compression")
        C = len(contact["obstacles"])
        return -np.asarray(self.contact_forces)[:, : S * C].reshape(K, S, C, d).sum(axis=1)

    @property
    def completed(self) -> bool:
        return bool(self.result == RESULTS.successful)

    @property
    def status_message(self) -> str:
        return result_message(self.result)

    @property
    def first_crossing(self) -> LimitPoint | None:
        """The "surface_crossing" event (first step with a node beyond the surface or behind
        the probe plane), or None."""
        return next((p for p in self.limit_points if p.kind == "surface_crossing"), None)

    @property
    def records_frame_angles(self) -> bool:
        """False only for a twisting network's result read from a file of format 3 or older,
        which did not record the frame angles ψ (``twists`` is then [K, 0])."""
        return not self.network.twisting or self.twists.shape[-1] == self.network.n_nodes

    @property
    def n_steps(self) -> int:
        return int(self.displacement.shape[0])

    @property
    def loading(self) -> np.ndarray:
        """[K] bool: settle point and loading steps."""
        return np.asarray(self.phase) <= 1

    @property
    def unloading(self) -> np.ndarray:
        """[K] bool: unloading steps, preceded by the last loading step."""
        mask = np.asarray(self.phase) == 2
        if mask.any():
            mask = mask.copy()
            mask[np.argmax(mask) - 1] = True
        return mask

    def solution(self, i: int) -> Solution:
        """Row ``i`` as a :class:`socbjax.Solution` (curve, end rotations, deflection, reactions)."""
        net = self.network
        if np.shape(self.contact_points)[1]:
            raise ValueError("CompressionResult.solution: this path was computed with contact, and its equilibria need "
                             "the contact slots (interior forces), which the result does not store; use the recorded "
                             "positions, moments, contact_points and contact_forces, or solve the state you need with "
                             "socbjax.solve(..., contact=...)")
        if not self.records_frame_angles:
            raise ValueError("CompressionResult.solution: this result of a twisting network has no material-frame "
                             "angles (read from a file of format 3 or older, which did not record them); solve the "
                             "state you need with socbjax.solve, or use the recorded positions, tangents and moments")
        i = int(i) if not isinstance(i, (jnp.ndarray, np.ndarray)) else i
        positions, tangents, moments, forces = (self.positions[i], self.tangents[i], self.moments[i], self.segment_forces[i])
        angles, curvatures = node_angles_and_curvatures(net, tangents, moments)
        directors = angles if net.dim == 2 else tangents
        reactions = support_reactions(net_nodal_force(forces, net, net.loads), net)
        row = RESULTS.where(jnp.asarray(self.converged)[i], RESULTS.successful, RESULTS.not_reached)
        twists = self.twists[i] if net.twisting else jnp.zeros(0)
        state = SOCBState(positions=positions, directors=directors, moments=moments, forces=forces, twists=twists,
                          contacts=jnp.zeros((net.n_segments, 0, 5)), pairs=jnp.zeros((0, 10)))
        zero = jnp.zeros((), jnp.int32)
        return Solution(positions=positions, tangents=tangents, angles=angles, moments=moments, curvatures=curvatures,
                        segment_forces=forces, reactions=reactions, result=row, iterations=jnp.asarray(self.iterations)[i],
                        steps=zero, cutbacks=zero, residual_norm=jnp.zeros(()), load_factor=jnp.ones(()), state=state,
                        network=net, model="socb")

    def summary(self) -> str:
        """One line: completion, steps, peak force and where."""
        force, disp = np.asarray(self.force), np.asarray(self.displacement)
        k = int(np.argmax(force)) if self.n_steps else 0
        peak = f"peak {force[k]:.4g} pN at {disp[k]:.4g} µm" if self.n_steps else "no steps"
        unstable = int(np.sum(~np.asarray(self.stable)))
        steps = f"{self.n_steps} step{'s' * (self.n_steps != 1)}"
        iterations = int(np.sum(np.asarray(self.iterations)))
        events = len(self.limit_points)
        status = "completed" if self.completed else "FAILED: " + self.status_message
        if (crossing := self.first_crossing) is not None:
            status += f" [first crossing at step {crossing.step}, u = {crossing.displacement:.4g} µm]"
        return (f"{status}; {steps} ({iterations} Newton "
                f"iteration{'s' * (iterations != 1)}), {peak}, max displacement {disp.max() if self.n_steps else 0:.4g} µm, "
                f"{events} event{'s' * (events != 1)}, {unstable} step{'s' * (unstable != 1)} flagged unstable")

    def __repr__(self) -> str:
        try:
            return f"CompressionResult({self.summary()})"
        except Exception:  # noqa: BLE001  (traced: no values to show)
            return "CompressionResult(traced)"
