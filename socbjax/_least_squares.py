"""Least-squares minimisers and Gauss–Newton uncertainties of :func:`socbjax.fit`.

Optimisers.  ``"lm"`` (default): Levenberg–Marquardt on the unconstrained parameters (bounds
by transforms, :class:`socbjax.Parameter`) with Marquardt's diagonal scaling; the residual
Jacobian costs one linear solve per parameter and data point.  A step is taken only if the
loss decreases; otherwise the damping grows ×4 and the step is retried, which also rejects
steps into a region where the path cannot be followed — this is what keeps the fit robust at
the collapse, where the force and its derivatives change fast.  ``"adam"`` and ``"lbfgs"``
(optax) minimise the same loss with ``jax.value_and_grad``.

Uncertainties (Gauss–Newton).  With J the residual Jacobian in the unconstrained variables
z at the optimum, s² = Σ r²/(m − p) and Cz = s² (JᵀJ)⁻¹; the values' covariance is
D Cz D with D = dθ/dz (delta method).  Standard errors are its square roots and the
correlation matrix its normalisation.  A correlation of magnitude ≥ 0.995 (or a singular
JᵀJ) marks the fit as not identifiable.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["CORRELATION_LIMIT", "gauss_newton_uncertainties", "levenberg_marquardt", "optax_minimise", "residual_variance",
           "within_standard_errors"]

CORRELATION_LIMIT = 0.995  # |correlation| at or above which two fitted values are not separately identifiable


def residual_variance(J, r) -> float:
    """s² = |r|²/(m − p): the residual variance that scales the Gauss–Newton covariance."""
    m, p = J.shape
    return float(r @ r) / max(m - p, 1)


def within_standard_errors(J, r, step, fraction: float) -> bool:
    """Every component of ``step`` (unconstrained variables) is below ``fraction`` of that
    variable's Gauss–Newton standard error at (J, r): s² = |r|²/(m − p), SE² = s² diag((JᵀJ)⁺)."""
    if not fraction > 0:
        return False
    se = np.sqrt(np.abs(residual_variance(J, r) * np.diag(np.linalg.pinv(J.T @ J))))
    return bool(np.all(np.abs(step) <= fraction * se))


def levenberg_marquardt(jac, z, max_iterations, tolerance, report, rejected=lambda iteration, damping: None,
                         se_tolerance: float = 0.0):
    """Minimise ½|r(z)|²; ``jac(z)`` -> (J [m, p], r [m]).  Returns (z, r, J, history, converged,
    message, evaluations).  Stops at a gradient, relative loss decrease or step below
    ``tolerance``, or an accepted step below ``se_tolerance`` standard errors in every variable."""
    J, r = (np.asarray(a) for a in jac(z))
    loss, damping, history, evaluations = 0.5 * float(r @ r), 1e-3, [], 1
    converged, message = False, f"reached max_iterations={max_iterations}"
    for iteration in range(1, max_iterations + 1):
        A, g = J.T @ J, J.T @ r
        scale = np.maximum(np.diag(A), 1e-12 * max(np.diag(A).max(), 1e-300))
        if np.max(np.abs(g) / np.sqrt(scale)) <= tolerance * max(math.sqrt(2 * loss), 1e-300):
            converged, message = True, "converged (gradient below tolerance)"
            break
        for _ in range(12):
            step = np.linalg.solve(A + damping * np.diag(scale), -g)
            trial = z + step
            J_new, r_new = (np.asarray(a) for a in jac(jnp.asarray(trial)))
            # NaN residuals: the path could not be followed at the trial values; reject the step
            loss_new = 0.5 * float(r_new @ r_new) if np.all(np.isfinite(r_new)) and np.all(np.isfinite(J_new)) else math.inf
            evaluations += 1
            if loss_new < loss:
                break
            damping *= 4.0
            rejected(iteration, damping)
        else:
            message = "stopped: no step decreased the loss (at a minimum to within the path's accuracy)"
            converged = True
            break
        decrease = loss - loss_new
        z, J, r, loss, damping = jnp.asarray(trial), J_new, r_new, loss_new, max(damping / 3.0, 1e-9)
        history.append({"iteration": iteration, "loss": loss, "damping": damping, "z": np.asarray(z).tolist()})
        report(iteration, loss, z)
        if decrease <= tolerance * loss or np.max(np.abs(step)) <= tolerance * (1.0 + float(np.max(np.abs(z)))):
            converged, message = True, "converged (relative loss decrease or step below tolerance)"
            break
        if within_standard_errors(J, r, step, se_tolerance):
            converged, message = True, f"converged (the last step moved every parameter by < {se_tolerance:g} SE)"
            break
    return z, r, J, history, converged, message, evaluations


def optax_minimise(loss_and_grad, loss_fn, z, optimizer, max_iterations, tolerance, learning_rate, report):
    import optax

    opt = optax.adam(learning_rate) if optimizer == "adam" else optax.lbfgs()
    state, history, previous = opt.init(z), [], math.inf
    converged, message = False, f"reached max_iterations={max_iterations}"
    for iteration in range(1, max_iterations + 1):
        loss, grad = loss_and_grad(z)
        if not (np.isfinite(float(loss)) and np.all(np.isfinite(np.asarray(grad)))):
            z = jnp.asarray(history[-2]["z"]) if len(history) > 1 else z
            message = (f"stopped at iteration {iteration}: the path could not be followed at the optimiser's step; "
                       "use the 'lm' optimizer (which rejects such steps) or a smaller Adam learning rate")
            break
        if optimizer == "lbfgs":
            updates, state = opt.update(grad, state, z, value=loss, grad=grad, value_fn=loss_fn)
        else:
            updates, state = opt.update(grad, state, z)
        z = optax.apply_updates(z, updates)
        history.append({"iteration": iteration, "loss": float(loss), "damping": None, "z": np.asarray(z).tolist()})
        report(iteration, float(loss), z)
        if abs(previous - float(loss)) <= tolerance * float(loss):
            converged, message = True, "converged (relative loss change below tolerance)"
            break
        previous = float(loss)
    return z, history, converged, message, iteration


def gauss_newton_uncertainties(J, r, z, table, free):
    """Gauss–Newton covariance of the values, correlation, identifiability and warnings."""
    p = J.shape[1]
    s2 = residual_variance(J, r)
    A = J.T @ J
    warnings = []
    for i, name in enumerate(free):
        lo, hi = table[name].lower, table[name].upper
        value = float(table[name].to_value(float(z[i])))
        near = 1e-3 * (hi - lo) if lo is not None and hi is not None else 1e-9 * max(abs(value), 1e-300)
        if (lo is not None and value - lo <= near) or (hi is not None and hi - value <= near):
            warnings.append(f"{name} = {value:.4g} {table[name].unit} is at its bound ({lo}, {hi}): the data push it "
                            "further, the model does not describe them there; its error is not meaningful")
    cond = np.linalg.cond(A) if p else 1.0
    D = np.array([float(jax.grad(table[n].to_value)(float(z[i]))) for i, n in enumerate(free)])
    singular = not np.isfinite(cond) or cond > 1e14
    if singular:
        warnings.append(f"JᵀJ is singular (condition number {cond:.3g}): the data do not determine all of {list(free)}")
        cov = np.full((p, p), np.inf)
    else:
        cov = D[:, None] * (s2 * np.linalg.inv(A)) * D[None, :]
    se = np.sqrt(np.abs(np.diag(cov)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    identifiable = not singular
    for i in range(p):
        for j in range(i + 1, p):
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) >= CORRELATION_LIMIT:
                identifiable = False
                warnings.append(f"{free[i]} and {free[j]} are correlated {corr[i, j]:+.4f}: not separately identifiable "
                                "from this curve; fix one of them")
    return se, corr, cov, identifiable, warnings
