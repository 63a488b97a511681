"""The compression protocol as data over the path engine: phases, their problems, and the
host driver of full (adaptive, variable-length) compressions with progress and checkpoints.

Phases (each one path of :func:`socbjax._path.follow_path`; all share one compiled program,
since they differ only in values):

0. **settle** — the network's fixed loads (e.g. the lateral perturbation) are ramped on with
   the probe free along its direction (zero probe force), so the start state is an
   equilibrium that is not a taut straight strand (an inextensible straight strand spanning
   probe and surface carries any axial force: its stiffness matrix is singular);
1. **loading** — the probe displacement u goes from the settled u₀ to the requested travel;
2. **unloading** — u goes back to u₀ + 10⁻⁴ (travel − u₀): there the strands are straight
   again and the stiffness turns singular (the force falls from ~Euler to 0 over a
   vanishing displacement), which no step size resolves reliably.
"""

from __future__ import annotations

import dataclasses
import hashlib
import time
import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from ._contact_near import grow_near_list
from ._paired import PairedSparseLU
from ._path import PathProblem, StepRecorder, follow_path, path_weights, start_path, state_unravel
from ._path_settings import PathSettings
from ._probe import observe
from ._progress import Progress
from ._residual import Control
from ._solution import RESULTS, result_name

__all__ = ["UNLOAD_MARGIN", "CHUNK_SECONDS", "Checkpoint", "phase_problem", "settled_displacement", "run_phases"]

UNLOAD_MARGIN = 1e-4  # unloading ends at u0 + margin × (travel − u0)
# Wall time aimed at by one compiled chunk of the path while progress is reported: half a
# second, so that the time per step may double (rejections, slow Newton) and the report still
# moves every second.
CHUNK_SECONDS = 0.5


@dataclasses.dataclass(frozen=True)
class Checkpoint:
    """Where and how often a long :func:`socbjax.compress` writes its state.

    path : HDF5 file written atomically every ``every`` accepted steps; ``resume=True``
    continues from it and ends with the same curve as an uninterrupted run."""

    path: str | Path
    every: int = 50
    resume: bool = False

    def __post_init__(self):
        if isinstance(self.every, bool) or not isinstance(self.every, (int, np.integer)) or self.every < 1:
            raise ValueError(f"Checkpoint.every must be a positive number of steps, got {self.every!r}")
        if not isinstance(self.path, (str, Path)) or not str(self.path):
            raise TypeError(f"Checkpoint.path must be a file path, got {self.path!r}")
        if not isinstance(self.resume, bool):
            raise TypeError(f"Checkpoint.resume must be True or False, got {self.resume!r}")


def phase_problem(model, index, u0, u_max, settings: PathSettings) -> PathProblem:
    """The path problem of phase ``index`` (0 settle, 1 loading, 2 unloading; may be traced)."""
    index = jnp.asarray(index)
    u_end = u0 + UNLOAD_MARGIN * (u_max - u0)
    settle = index == 0
    lam0 = jnp.where(settle, 0.0, 1.0)
    u_from = jnp.where(settle, 0.0, jnp.where(index == 1, u0, u_max))
    u_to = jnp.where(settle, 0.0, jnp.where(index == 1, u_max, u_end))
    held = jnp.where(settle, 0.0, 1.0)
    scale = jnp.where(settle, 4.0 * settings.max_step, jnp.abs(u_to - u_from))
    weights = path_weights(model, scale)
    return PathProblem(model, Control.make(lam0, u_from, held), Control.make(1.0, u_to, held), weights, weights)


def settled_displacement(model, x) -> jax.Array:
    """u₀ (µm): the mean displacement of the probe nodes along the probe direction in state x."""
    net = model.network
    positions = state_unravel(model)(x).positions
    moved = (positions - net.positions)[np.flatnonzero(net.probe)] @ jnp.asarray(net.probe_direction)
    return jnp.mean(moved)


@eqx.filter_jit
def _chunk(problem, state, settings, inner, recorder, chunk):
    """At most ``chunk`` more accepted steps (a traced count: every chunk length runs the same
    compiled program), and the probe force (pN) at the last one, for the progress report."""
    state = follow_path(problem, state, settings, inner, recorder, stop_after=chunk)
    return state, observe(problem.model, state.x[None], problem.model.network.loads)[4][0]


def _fingerprint(model, u_max, unload, settings) -> str:
    h = hashlib.sha256(model.network.topology.key.encode())
    for leaf in jax.tree_util.tree_leaves(model.network):
        h.update(np.ascontiguousarray(np.asarray(leaf)).tobytes())
    h.update(repr((float(u_max), bool(unload), settings, model.quad)).encode())
    return h.hexdigest()


def _named_leaves(tree) -> dict:
    return {jax.tree_util.keystr(k): np.asarray(v) for k, v in jax.tree_util.tree_flatten_with_path(tree)[0]}


# Path-state fields added after checkpoints were first written; a checkpoint without them
# resumes with the fresh path's values (no step size to return to).
_LATER_FIELDS = (".recover", ".streak")


def _from_named(template, arrays: dict, where):
    """The path state ``template`` with its leaves from ``arrays``, each checked for the
    template's shape and dtype (a damaged or foreign checkpoint is refused, not resumed)."""
    paths, treedef = jax.tree_util.tree_flatten_with_path(template)
    arrays = {**{k: np.asarray(v) for k, v in _named_leaves(template).items() if k in _LATER_FIELDS}, **arrays}
    missing = [jax.tree_util.keystr(k) for k, _ in paths if jax.tree_util.keystr(k) not in arrays]
    if missing:
        raise ValueError(f"{where} is not a valid socbjax checkpoint: it lacks the path-state fields {missing[:4]} "
                         "(damaged or from another version); delete it to start afresh")
    leaves = []
    for key, leaf in paths:
        value, name = np.asarray(arrays[jax.tree_util.keystr(key)]), jax.tree_util.keystr(key)
        if value.shape != np.shape(leaf) or value.dtype != np.asarray(leaf).dtype:
            raise ValueError(f"{where} is not a valid socbjax checkpoint: field {name} has shape {value.shape} and dtype "
                             f"{value.dtype}, this run needs {np.shape(leaf)} {np.asarray(leaf).dtype}; delete it to "
                             "start afresh")
        leaves.append(jnp.asarray(value))
    return jax.tree_util.tree_unflatten(treedef, leaves)


def _check_records(records: dict, n: int, where) -> None:
    """Recorded steps of a checkpoint: equal lengths, states of ``n`` unknowns, finite."""
    lengths = {k: np.shape(v)[0] if np.ndim(v) else -1 for k, v in records.items()}
    if set(records) != {"X", "U", "SIGN", "ITER", "PHASE"} or len(set(lengths.values())) != 1 \
            or np.shape(records["X"])[1:] != (n,) or not np.all(np.isfinite(records["X"])):
        raise ValueError(f"{where} is not a valid socbjax checkpoint: its recorded steps are damaged "
                         f"({ {k: np.shape(v) for k, v in records.items()} }); delete it to start afresh")


class _Run:
    """The phases of one host-driven compression, with their records and checkpoints."""

    def __init__(self, model, start, u_max, unload, settings, inner, progress, checkpoint):
        self.model, self.u_max, self.settings, self.inner = model, float(u_max), settings, inner
        self.x0 = ravel_pytree(start)[0]
        self.recorder = StepRecorder(settings.max_steps)
        self.names = ["settle", "loading"] + (["unloading"] if unload else [])
        self.progress, self.checkpoint = progress, checkpoint
        # Reported runs start with one step (the first chunk compiles: the bar appears right after)
        # and adapt the length to CHUNK_SECONDS; others run whole (or checkpoint to checkpoint).
        self.chunk = 1 if progress.active else (checkpoint.every if checkpoint else settings.max_steps)
        self.fingerprint = _fingerprint(model, u_max, unload, settings)
        self.start, self.saved, self.extra, self.parts = 0, None, {}, []

    def resume(self):
        from ._io import load_checkpoint

        where = self.checkpoint.path
        arrays, meta = load_checkpoint(where)
        if not isinstance(meta, dict) or meta.get("fingerprint") != self.fingerprint:
            raise ValueError(f"checkpoint {where} belongs to a different run (network, loads or settings differ); "
                             "rerun with the same arguments, or delete it to start afresh")
        index = meta.get("phase_index")
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(self.names):
            raise ValueError(f"{where} is not a valid socbjax checkpoint: phase_index {index!r}; delete it to start afresh")
        self.start = index
        self.saved = {k[6:]: v for k, v in arrays.items() if k.startswith("carry/")}
        extra = {k[6:]: v for k, v in arrays.items() if k.startswith("extra/")}
        if any(np.shape(v) != () or not np.isfinite(v) for v in extra.values()):
            raise ValueError(f"{where} is not a valid socbjax checkpoint: damaged extra values; delete it to start afresh")
        self.extra = {k: float(v) for k, v in extra.items()}
        records = {k[8:]: v for k, v in arrays.items() if k.startswith("records/")}
        if records:
            _check_records(records, self.x0.shape[0], where)
        self.parts = [records] if records else []
        if index > 0 and (not self.parts or "u0" not in self.extra):
            raise ValueError(f"{where} is not a valid socbjax checkpoint: phase {index} without the settled start; "
                             "delete it to start afresh")

    def _save(self, index, state):
        if not self.checkpoint:
            return
        from ._io import save_checkpoint

        arrays = {f"carry/{k}": v for k, v in _named_leaves(state).items()}
        arrays.update({f"extra/{k}": np.asarray(v) for k, v in self.extra.items()})
        if self.parts:
            arrays.update({f"records/{k}": v for k, v in concat(self.parts).items()})
        save_checkpoint(self.checkpoint.path, arrays, {"fingerprint": self.fingerprint, "phase_index": index})

    def _finish(self, index, state):
        k = int(state.steps)
        rec = state.recorder.rows(k)
        if index == 0:  # only the settled end state is part of the curve
            x = np.asarray(state.x)
            self.extra["u0"] = float(settled_displacement(self.model, jnp.asarray(x)))
            self.parts = [dict(X=x[None], U=np.array([self.extra["u0"]]), SIGN=np.zeros(1), ITER=np.array([k], np.int32),
                               PHASE=np.zeros(1, np.int8))]
            return
        if index == 1:
            self.extra["sign_ref"] = float(state.sign0)
            self.parts[0]["SIGN"] = np.array([self.extra["sign_ref"]])
        u_from, u_to = (self.extra["u0"], self.u_max) if index == 1 else (self.u_max, self.extra["u0"] + UNLOAD_MARGIN * (self.u_max - self.extra["u0"]))
        self.parts.append(dict(X=rec["X"], U=u_from + rec["P"] * (u_to - u_from), SIGN=rec["SIGN"], ITER=rec["ITER"],
                               PHASE=np.full(k, index, np.int8)))

    def _phase(self, index):
        u0 = self.extra.get("u0", 0.0)
        problem = phase_problem(self.model, index, u0, self.u_max, self.settings)
        x = self.x0 if index == 0 else jnp.asarray(self.parts[-1]["X"][-1])
        template = start_path(x, 0.0, self.settings, self.recorder)
        resumed = self.saved is not None and index == self.start
        state = _from_named(template, self.saved, self.checkpoint.path) if resumed else template
        ends = (0.0, 0.0) if index == 0 else ((u0, self.u_max) if index == 1 else (self.u_max, u0 + UNLOAD_MARGIN * (self.u_max - u0)))
        settings = self.settings.traced()
        every = self.checkpoint.every if self.checkpoint else None
        next_save = int(state.steps) + every if every else None
        while True:
            before, t = int(state.steps), time.perf_counter()
            length = self.chunk if next_save is None else max(min(self.chunk, next_save - before), 1)
            state, force = _chunk(problem, state, settings, self.inner, self.recorder, jnp.asarray(length, jnp.int32))
            steps = int(state.steps)  # waits for the chunk
            u = ends[0] + float(state.p) * (ends[1] - ends[0])
            if self._grow(state, u):
                problem = phase_problem(self.model, index, u0, self.u_max, self.settings)
                state = eqx.tree_at(lambda s: (s.result, s.done), state, (RESULTS.successful, jnp.asarray(False)))
                continue
            self._adapt(steps - before, time.perf_counter() - t)
            done = bool(state.done) or steps >= self.settings.max_steps
            if not done and next_save is not None and steps >= next_save:  # saved before reporting: an
                self._save(index, state)  # interrupt in the report loses nothing
                next_save = steps + every
            self.progress(self.names[index], u, steps, float(force), done)
            if done:
                return state

    def _grow(self, state, u: float) -> bool:
        """After an overflow that a larger capacity mends, that capacity doubled; the path goes
        on from its last accepted state, which the overflowing step left unchanged (one more
        compilation).  Returns whether anything grew.

        * ``RESULTS.colour_capacity``: the pair solver's colours
          (:class:`socbjax.PairedSparseLU` ``max_colors``);
        * ``RESULTS.contact_capacity`` with the near list in use (more segments near a surface
          than ``Contact(slot_capacity)``): the list
          (:func:`socbjax._contact_near.grow_near_list`).
        """
        if result_name(state.result) == "colour_capacity" and isinstance(self.inner, PairedSparseLU):
            size = 2 * self.inner.max_colors
            warnings.warn(f"compress: the contact pairs' Jacobian needed more than the {self.inner.max_colors} colours "
                          f"prepared at u = {u:.4g} µm; the solver grows to {size} and the path goes on from its last "
                          "step (one more compilation)", stacklevel=6)
            self.inner = dataclasses.replace(self.inner, max_colors=size)
            return True
        setup = getattr(self.model, "contact", None)
        if setup is None or not setup.listed or result_name(state.result) != "contact_capacity":
            return False
        grown = grow_near_list(setup, self.model.network.n_segments)
        size = grown.slot_capacity or self.model.network.n_segments
        warnings.warn(f"compress: more than slot_capacity={setup.slot_capacity} segments came near a surface at "
                      f"u = {u:.4g} µm; the near list grows to {size} and the path goes on from its last step (one "
                      f"more compilation; Contact(slot_capacity={size}) starts with it)", stacklevel=6)
        self.model = eqx.tree_at(lambda m: m.contact, self.model, grown)
        return True

    def _adapt(self, steps: int, seconds: float) -> None:
        """The next chunk's length: CHUNK_SECONDS at the last chunk's time per step, at most 4×
        the last length (the first chunk's time includes compilation: it only shortens)."""
        if self.progress.active:
            target = CHUNK_SECONDS * max(steps, 1) / max(seconds, 1e-6)
            self.chunk = int(max(1, min(target, 4 * self.chunk, self.settings.max_steps)))

    def run(self):
        result = RESULTS.successful
        for index in range(self.start, len(self.names)):
            state = self._phase(index)
            self._finish(index, state)
            result = state.result
            if result_name(result) != "successful":
                break
        return result


def concat(parts: list[dict]) -> dict:
    """The records of several phases, concatenated."""
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def run_phases(model, start, u_max, unload, settings, inner, *, progress=None, checkpoint=None):
    """Run the settle/loading/unloading phases on the host (concrete values) from ``start``
    (the model's initial state); returns (records of every recorded step, extra {u0,
    sign_ref}, result)."""
    run = _Run(model, start, u_max, unload, settings, inner, progress or Progress(False, u_max), checkpoint)
    if checkpoint and Path(checkpoint.path).exists():
        if checkpoint.resume:
            run.resume()
        else:  # never discard another run's checkpoint silently
            warnings.warn(f"checkpoint {checkpoint.path} exists and resume=False: this run overwrites it at its first "
                          "checkpoint (pass resume=True to continue that run instead)", stacklevel=3)
    elif checkpoint and checkpoint.resume:
        warnings.warn(f"resume=True but there is no checkpoint at {checkpoint.path}: starting from the beginning",
                      stacklevel=3)
    try:
        result = run.run()
    finally:  # also on an error or Ctrl-C: the ticker stops, the line ends
        run.progress.close()
    return concat(run.parts), run.extra, result
