"""Outcomes: the one status enumeration :class:`RESULTS`, :class:`ConvergenceError` and the
rule that makes failures loud, eagerly and under ``jax.jit``.

Every result type of socbjax (:class:`socbjax.Solution`, :class:`socbjax.CompressionResult`,
:class:`socbjax.EnsembleResult`, :class:`socbjax.FitResult`) carries ``.result``, an item of
:class:`RESULTS` (an ``equinox`` enumeration extending ``optimistix.RESULTS``, so the
messages of optimistix and lineax are available too).  ``RESULTS.successful`` is the only
answer; anything else says why a solve stopped.
"""

from __future__ import annotations

import numpy as np
import optimistix as optx

__all__ = ["RESULTS", "ConvergenceError", "result_name", "result_from_name", "result_message", "LEGACY_STATUS"]


class RESULTS(optx.RESULTS):  # pyright: ignore
    """Why a socbjax solve stopped (``RESULTS[result]`` gives the message)."""

    max_iterations = "Newton reached its iteration limit without converging"
    line_search_failed = "the line search could not reduce the residual (singular or ill-posed system)"
    step_too_small = "continuation cut the step below its minimum without converging"
    critical_point = (
        "the load path reaches a critical point (limit load or bifurcation: the tangent stiffness turns singular), "
        "beyond which no equilibrium continues this path under load control; add a small imperfection load, or stop "
        "below the critical load"
    )
    fold = (
        "the path turns back in its control parameter (a fold: a limit point or snap-back) where natural-parameter "
        "control cannot follow it; use method='arclength' to follow the path through folds"
    )
    max_steps = "the continuation used up its step budget (PathSettings.max_steps / max_attempts)"
    contact_capacity = (
        "more filament pairs, or more segments near an obstacle, came within contact range than the lists hold "
        "(socbjax.Contact capacity / per_segment, or slot_capacity); raise them"
    )
    not_equilibrium = "the start of the path is not an equilibrium (Newton did not converge there)"
    not_reached = "a requested sample lies beyond the part of the path that was followed"
    did_not_move = (
        "the optimiser accepted no step: the parameters are still their initial values, so nothing was fitted (the data "
        "may be in other units or far outside the model's range: check the curve's units, the initial values and bounds)"
    )
    poor_fit = (
        "the fitted model explains none of the data's variation (R² ≤ 0: residuals as large as the data's spread about "
        "their mean), so the values mean nothing; check the curve's units, its contact point and the model"
    )
    surface_crossed = (
        "nodes of the network crossed the surface or the probe plane: computed without contact (contact=None), filaments "
        "pass through both, and the path from that step on is not physical (planar networks: use "
        "contact=socbjax.Contact(self_contact=False)); otherwise stop before it (a smaller displacement: "
        "see the 'surface_crossing' event in result.limit_points)"
    )
    colour_capacity = (
        "the sparse Jacobian of the contact pairs needs more colours than socbjax.PairedSparseLU prepared (a crowded "
        "contact set); socbjax.compress doubles them and goes on; elsewhere pass linear_solver='dense' or fewer pairs "
        "per segment (socbjax.Contact(per_segment=...))"
    )


# Status codes of format_version 1 result files (socbjax 0.1 `Status`), by name.
LEGACY_STATUS = ("successful", "max_iterations", "nonfinite", "line_search_failed", "step_too_small", "critical_point",
                 "max_steps")


class ConvergenceError(RuntimeError):
    """Raised (``throw=True``, untraced inputs) when a solve does not produce an answer; the
    partial result is ``error.result`` where there is one."""


def result_name(item) -> str:
    """The name of a concrete :class:`RESULTS` item (e.g. ``"successful"``)."""
    value = int(np.asarray(item._value))
    for name, candidate in RESULTS._name_to_item.items():
        if int(np.asarray(candidate._value)) == value:
            return name
    raise ValueError(f"not a RESULTS item: {item!r}")


def result_from_name(name: str):
    """The :class:`RESULTS` item called ``name``."""
    if name not in RESULTS._name_to_item:
        raise ValueError(f"unknown result {name!r}; known: {sorted(RESULTS._name_to_item)}")
    return RESULTS._name_to_item[name]


def result_message(item) -> str:
    """Human-readable message of a concrete item ("converged" for success)."""
    message = RESULTS[item]
    return "converged" if message == "" else message
