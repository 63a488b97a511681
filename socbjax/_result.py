"""Result of a displacement-controlled compression: :class:`CompressionResult`.

Host-side (numpy) arrays, one row per recorded equilibrium along the path, in path order:
the settled start (phase 0), the loading steps (phase 1), the unloading steps (phase 2).
Units: µm, pN, pN·µm.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ._network import Network
from ._newton import Status

__all__ = ["CompressionResult", "LimitPoint", "PHASES"]

PHASES = ("settle", "loading", "unloading")


@dataclasses.dataclass(frozen=True)
class LimitPoint:
    """An event between two recorded steps of the path.

    kind : "force_maximum" / "force_minimum" (local extremum of the probe force along the
        path: the limit load a force-controlled test would snap at), "fold" (the probe
        displacement turns back: a snap-back, only on arclength paths) or "bifurcation"
        (sign(det J) changes without a fold: a critical point of the tangent stiffness).
    step : index of the recorded step at (or just after) the event.
    displacement, force : probe displacement (µm) and force (pN) at that step.
    phase : "loading" or "unloading".
    """

    kind: str
    step: int
    displacement: float
    force: float
    phase: str


@dataclasses.dataclass(eq=False)
class CompressionResult:
    """A compression (and optional withdrawal) path; see :func:`socbjax.compress`.

    displacement : [K] probe displacement from the as-built position along the probe
        direction (µm, compression positive).
    force : [K] probe reaction along the compression axis (pN, compressive positive).
    converged : [K] bool, every recorded step is a converged equilibrium (failed attempts
        are cut back and never recorded; ``status`` says whether the protocol completed).
    stable : [K] bool, sign(det J) equals that of the settled start state: an even number of
        unstable modes (see docs/equations.md: a parity indicator of stability).
    phase : [K] int, 0 settle, 1 loading, 2 unloading (names in ``PHASES``).
    positions, tangents : [K, N, d] node positions (µm) and unit tangents.
    moments : [K, N] (2D, pN·µm) or [K, N, 3] (3D) nodal bending moments.
    segment_forces : [K, S, d] internal force per segment (pN).
    end_nodes : [E] supported non-probe nodes (strand ends on the surface).
    end_forces : [K, E] axial force on each strand end (pN, compressive positive).
    iterations : [K] Newton iterations of each step.
    limit_points : events found along the path (:class:`LimitPoint`).
    status : :class:`Status` code of the whole protocol (CONVERGED: every phase completed).
    network : the compressed :class:`Network`.
    parameters : JSON-able dict of the run's settings (and builder parameters if given).
    """

    displacement: np.ndarray
    force: np.ndarray
    converged: np.ndarray
    stable: np.ndarray
    phase: np.ndarray
    positions: np.ndarray
    tangents: np.ndarray
    moments: np.ndarray
    segment_forces: np.ndarray
    end_nodes: np.ndarray
    end_forces: np.ndarray
    iterations: np.ndarray
    limit_points: list[LimitPoint]
    status: int
    network: Network
    parameters: dict[str, Any]

    @property
    def completed(self) -> bool:
        return int(self.status) == Status.CONVERGED

    @property
    def status_message(self) -> str:
        return Status(int(self.status)).message

    @property
    def n_steps(self) -> int:
        return int(self.displacement.shape[0])

    @property
    def loading(self) -> np.ndarray:
        """[K] bool: settle point and loading steps."""
        return self.phase <= 1

    @property
    def unloading(self) -> np.ndarray:
        """[K] bool: unloading steps, preceded by the last loading step."""
        mask = self.phase == 2
        if mask.any():
            mask = mask.copy()
            mask[np.argmax(mask) - 1] = True
        return mask

    def summary(self) -> str:
        """One line: completion, steps, peak force and where."""
        k = int(np.argmax(self.force)) if self.n_steps else 0
        peak = f"peak {self.force[k]:.4g} pN at {self.displacement[k]:.4g} µm" if self.n_steps else "no steps"
        unstable = int(np.sum(~self.stable))
        return (
            f"{'completed' if self.completed else 'FAILED: ' + self.status_message}; {self.n_steps} steps "
            f"({int(self.iterations.sum())} Newton iterations), {peak}, max displacement "
            f"{self.displacement.max() if self.n_steps else 0:.4g} µm, {len(self.limit_points)} events, "
            f"{unstable} steps flagged unstable"
        )

    def __repr__(self) -> str:
        return f"CompressionResult({self.summary()})"
