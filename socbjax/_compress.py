"""Displacement-controlled compression of a network by a rigid probe: :func:`compress`.

The protocol (settle, loading, optional unloading; :mod:`socbjax._protocol`) runs on the
path engine.  Without ``at`` the whole adaptive path is recorded, host-driven (progress,
checkpoints, resume); with ``at`` the requested displacements are sampled and the whole
computation is a traced JAX function (:mod:`socbjax._sampled`): ``jax.jit``, ``jax.grad``,
``jax.jacfwd`` and ``jax.vmap`` apply, with implicit derivatives.

Units: µm, pN.  The measured force is the probe's reaction along the probe direction,
compressive positive.
"""

from __future__ import annotations

from pathlib import Path

import equinox as eqx

from ._contact import Contact
from ._contact_model import contact_setup
from ._network import Network, is_traced
from ._path_settings import PathSettings
from ._probe import (
    applied_loads,
    check_compress_inputs,
    compress_settings,
    package_path,
)
from ._progress import Progress
from ._protocol import Checkpoint, run_phases
from ._quadrature import get_quadrature
from ._residual import SOCBModel
from ._result import CompressionResult
from ._sampled import compress_at
from ._solution import RESULTS, ConvergenceError, result_message
from ._sparsity import linear_solver_for

__all__ = ["compress"]


def _checkpoint(checkpoint) -> Checkpoint | None:
    if checkpoint is None or isinstance(checkpoint, Checkpoint):
        return checkpoint
    if isinstance(checkpoint, (str, Path)):
        return Checkpoint(checkpoint)
    raise TypeError(f"checkpoint must be a file path or a socbjax.Checkpoint, got {type(checkpoint).__name__}")


def compress(network: Network, displacement, *, at=None, unload: bool = False, method: str | None = None,
             perturbation=None, settings: PathSettings | None = None, checkpoint=None, progress: bool = False,
             throw: bool = True, parameters: dict | None = None, contact: Contact | None = None) -> CompressionResult:
    """Compress ``network`` with its probe by ``displacement`` µm (and withdraw it if ``unload``).

    Parameters
    ----------
    network : a network with probe nodes (e.g. :func:`socbjax.dendritic_outcrop`), or a single
        filament such as :func:`socbjax.column`, whose last node then becomes the probe and
        moves toward the first (its lateral support is kept: "free" = frictionless push).
    displacement : total probe travel (µm) from the as-built probe position; must be smaller
        than the probe–surface gap.
    at : probe displacements (µm, [M]) at which to return the equilibria instead of the
        adaptive path steps: the path is followed adaptively, then each requested point is
        solved exactly, warm-started from the path, with derivatives by the implicit function
        theorem with respect to ``at``, every value of the network (EI, lengths, positions,
        tangents, loads) and ``perturbation``.  The whole computation is traced: ``jax.jit``,
        ``jax.grad``, ``jax.jacfwd`` and ``jax.vmap`` apply.  Without ``at``, traced inputs
        sample 64 equal steps up to ``displacement``.  See :mod:`socbjax._sampled`.
    unload : then withdraw the probe back toward the settled start u₀, stopping at
        u₀ + 1e-4 (displacement − u₀) (reversibility, hysteresis).
    method : "displacement" (natural-parameter control; stops with ``RESULTS.fold`` at a
        fold) or "arclength" (pseudo-arclength: follows folds and snap-backs); overrides
        ``settings.method`` (default "displacement").
    perturbation : lateral force (pN) on the middle node of every strand, added to the
        network's ``loads``.  Default: the network's loads or, if it has none, 1e-4 EI/L² per
        strand (L: the longest strand) — an imperfection is needed: a straight inextensible
        strand between probe and surface carries any axial force (singular stiffness).  Far
        smaller ones leave the start too sharp a near-bifurcation for the path: 1e-7 pN on a
        pinned–pinned column of EI 0.071, 70× below the default, stops at the start (a fold
        under displacement control, a critical point under arclength); 1e-8 pN on a
        clamped–clamped one still gives the unbuckled branch under arclength
        (docs/equations.md, "The start of an arclength path").
    settings : :class:`socbjax.PathSettings` (steps in µm, max step capped at displacement/4;
        Newton tolerance 1e-10; ``linear_solver``, ``quadrature_order``).
    checkpoint : a file path or :class:`socbjax.Checkpoint` (path, every=50 steps,
        resume=False): write the run's state atomically; resume ends with the same curve.
    progress : True for progress on stderr: ``compiling … 12 s`` while JAX compiles, then per
        phase the probe displacement (µm), probe force (pN), accepted steps and elapsed time,
        refreshed about once a second on a terminal (every 10 s in a log); or a callable
        ``progress(phase, u, steps, done)`` called between chunks of the path (phase name,
        µm, accepted steps of the phase, whether it ended).  Either way the path runs in
        chunks of about half a second; the result is the same as without progress.
    throw : raise :class:`socbjax.ConvergenceError` when the protocol does not complete (the
        partial result is ``error.result``; under ``jax.jit`` an ``equinox`` runtime error);
        with ``throw=False`` check ``result.completed`` / ``result.result``.
    parameters : extra JSON-able metadata stored in the result (e.g. builder arguments).
    contact : None (default: no contact, filaments pass through each other and the surfaces)
        or a :class:`socbjax.Contact`: with ``surfaces=True`` the probe face and the substrate
        become rigid frictionless planes, plus the contact's own planes and spheres (2D
        networks so far).  The result then reports ``contact_count``, ``min_gap`` and
        ``contact_force`` per step, and the probe force includes the probe face's contacts.
    """
    network, displacement = check_compress_inputs(network, displacement, unload=unload, method=method,
                                                  perturbation=perturbation, parameters=parameters, throw=throw,
                                                  progress=progress)  # all before any work
    settings = compress_settings(settings, method, displacement)
    checkpoint = _checkpoint(checkpoint)
    model = SOCBModel(network, get_quadrature(settings.quadrature_order), contact_setup(network, contact))
    if contact is not None:  # the obstacles' names, in slot order (CompressionResult.obstacle_forces)
        parameters = {**(parameters or {}), "contact": {**contact.as_dict(), "obstacles": list(model.contact.names)}}
    if at is not None or is_traced(network, perturbation, displacement):
        if checkpoint is not None:
            raise ValueError("checkpoint applies to full paths; compress(..., at=...) is one traced computation")
        return compress_at(model, displacement, at, unload=unload, perturbation=perturbation, settings=settings,
                           throw=throw, parameters=parameters)
    bar = Progress(progress, float(displacement))
    bar.start()  # before the set-up below: its first run compiles too (op by op)
    try:
        model = eqx.tree_at(lambda m: m.network, model, network.replace(loads=applied_loads(network, perturbation)))
        # the path's start; with contact, one inside the law's range is refused here, before the
        # sparse solver's set-up (minutes with pairs on large networks)
        start = model.initial_state(check=True) if contact is not None else model.initial_state()
        inner = linear_solver_for(model, settings.linear_solver)
        rec, extra, result = run_phases(model, start, displacement, unload, settings, inner, progress=bar,
                                        checkpoint=checkpoint)
    finally:
        bar.close()
    out = package_path(model, rec, extra, result, settings, float(displacement), unload, parameters)
    if throw and not out.completed:
        if out.result == RESULTS.surface_crossed:
            k = out.first_crossing.step
            raise _error(out, f"compress: {result_message(out.result)}; first at step {k}, u = {out.displacement[k]:.4g} µm "
                         "(throw=False returns the path)")
        steps = f"{out.n_steps} step{'' if out.n_steps == 1 else 's'}"
        raise _error(out, f"compress stopped: {result_message(out.result)} (reached u = {out.displacement[-1]:.4g} µm, "
                     f"{steps}). Try method='arclength', smaller PathSettings steps, or throw=False.")
    return out


def _error(result: CompressionResult, message: str) -> ConvergenceError:
    err = ConvergenceError(message)
    err.result = result
    return err
