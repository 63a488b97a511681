"""The contact slots of a path's start state: their locations at the roots of their rows.

The straight reference state of a network with probe and substrate is an exact equilibrium
with a singular Jacobian (its axial forces are indeterminate until the settle load acts), so
a path's start must satisfy every row exactly: a Newton step on that Jacobian is not finite.
The contact slots' location rows are the only rows that the reference state does not satisfy
by construction (a slot near an obstacle or a pair near each other starts at σ = ½, not at
its closest point).  :func:`settle_locations` moves those σ alone to the roots of their
rows at the fixed geometry: Newton steps on decoupled rows (an obstacle slot's row depends on
its own σ, a pair's two rows on its two, taken in turn; the curve does not depend on σ while
the forces are zero).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._checks import is_traced

__all__ = ["settle_locations", "check_start_gaps"]

_ITERATIONS = 8  # alternations between the two sides of the pairs
_INNER = 12  # safeguarded Newton steps per side
_JOINT = 6  # joint Newton steps at the end


@eqx.filter_jit  # one compiled program: op by op, its Newton loops took 12 s on a 126-segment outcrop
def settle_locations(model, state, control):
    """(``state`` with the σ of every obstacle slot and pair slot at the root of its location
    row, the gaps [c] µm of its c = S·C + P slots there, +inf where a slot is not counted)
    (``model``: a :class:`socbjax.SOCBModel` with contact; ``control``: the start's)."""
    state = jax.tree_util.tree_map(jnp.asarray, state)  # the reference state may hold numpy arrays
    frames = model.frames(state)
    S, C, w = state.contacts.shape
    P, pw = state.pairs.shape

    def rows(sig_slots, sig_pairs):
        st = eqx.tree_at(lambda s: (s.contacts, s.pairs), state,
                         (state.contacts.at[..., 0].set(sig_slots), state.pairs.at[:, 2:4].set(sig_pairs)))
        r = model.residual(st, control, frames)
        tail = r[r.shape[0] - S * C * w - P * pw:]  # the slots' rows, then the pairs' (last)
        return tail[: S * C * w].reshape(S, C, w)[..., 0], tail[S * C * w:].reshape(P, pw)[:, 2:4]

    def side(sig, k):
        """The obstacle slots' σ (k = 0) and side k of the pairs' σ (the other side held) at
        the roots of their rows, by safeguarded Newton: a row is −(something ≥ 0) at σ = 0 and
        ≥ 0 at σ = 1 (a projection onto [0, 1], or the rest rows), so each keeps a bracket
        and bisects where a Newton step would leave it (plain Newton cycles between the
        branches of a projection, and a joint 2 × 2 step between a pair's ends)."""
        held_s, held_p = sig

        def one(_, carry):
            x_s, x_p, lo, hi = carry
            (r_s, r_p), (d_s, d_p) = jax.jvp(lambda a, b: rows(a, held_p.at[:, k].set(b)), (x_s, x_p),
                                             (jnp.ones_like(x_s), jnp.ones_like(x_p)))
            x, r, d = jnp.concatenate([x_s.ravel(), x_p]), jnp.concatenate([r_s.ravel(), r_p[:, k]]), \
                jnp.concatenate([d_s.ravel(), d_p[:, k]])
            lo, hi = jnp.where(r < 0, x, lo), jnp.where(r > 0, x, hi)
            newton = x - r / jnp.where(d != 0, d, jnp.inf)
            x = jnp.where(r == 0, x, jnp.where((newton > lo) & (newton < hi), newton, 0.5 * (lo + hi)))
            return x[: x_s.size].reshape(x_s.shape), x[x_s.size:], lo, hi

        n = held_s.size + held_p.shape[0]
        x_s, x_p, _, _ = jax.lax.fori_loop(0, _INNER, one, (held_s, held_p[:, k], jnp.zeros(n), jnp.ones(n)))
        return (x_s if k == 0 else held_s), held_p.at[:, k].set(x_p)

    def alternate(_, sig):
        return side(side(sig, 0), 1)

    def joint(_, sig):
        """A 2 × 2 Newton step per pair (and one per slot) near the roots, where alternating
        converges only linearly (a pair's two closest points move each other)."""
        sig_s, sig_p = sig
        zs, zp = jnp.zeros_like(sig_s), jnp.zeros_like(sig_p)
        (r_s, r_p), (d_s, c0) = jax.jvp(rows, (sig_s, sig_p), (jnp.ones_like(sig_s), zp.at[:, 0].set(1.0)))
        c1 = jax.jvp(rows, (sig_s, sig_p), (zs, zp.at[:, 1].set(1.0)))[1][1]
        step_s = -r_s / jnp.where(d_s != 0, d_s, jnp.inf)
        det = c0[:, 0] * c1[:, 1] - c1[:, 0] * c0[:, 1]  # the pair's block [[∂r/∂σ_i ∂r/∂σ_j]]
        safe = jnp.where(det != 0, det, jnp.inf)
        step_p = -jnp.stack([c1[:, 1] * r_p[:, 0] - c1[:, 0] * r_p[:, 1], c0[:, 0] * r_p[:, 1] - c0[:, 1] * r_p[:, 0]],
                            axis=1) / safe[:, None]
        new_s, new_p = jnp.clip(sig_s + step_s, 0.0, 1.0), jnp.clip(sig_p + step_p, 0.0, 1.0)
        n_s, n_p = rows(new_s, new_p)  # keep a step only where it reduces its rows
        better_s = jnp.abs(n_s) <= jnp.abs(r_s)
        better_p = jnp.max(jnp.abs(n_p), axis=1) <= jnp.max(jnp.abs(r_p), axis=1)
        return jnp.where(better_s, new_s, sig_s), jnp.where(better_p[:, None], new_p, sig_p)

    sig = (state.contacts[..., 0], state.pairs[:, 2:4])
    if P == 0:
        sig = side(sig, 0)
    else:
        sig = jax.lax.fori_loop(0, _ITERATIONS, alternate, sig)
        sig = jax.lax.fori_loop(0, _JOINT, joint, sig)
    sig = jax.lax.stop_gradient(sig)
    settled = eqx.tree_at(lambda s: (s.contacts, s.pairs), state,
                          (state.contacts.at[..., 0].set(sig[0]), state.pairs.at[:, 2:4].set(sig[1])))
    _, gaps, _, counted = model.contact_geometry(settled, control)[:4]
    return settled, jax.lax.stop_gradient(jnp.where(counted, gaps, jnp.inf))


def check_start_gaps(model, state, gaps) -> None:
    """Raise a ValueError that names the two pieces when a counted slot of the start
    ``state`` has its gap ``gaps`` [c] (µm, :func:`settle_locations`) below the activation
    distance δ: there the law already pushes, so the start is not the force-free equilibrium
    a path starts from (it would stop at once with ``RESULTS.not_equilibrium``), and below
    zero the filaments overlap as built.  Nothing to check for traced values."""
    if is_traced(gaps):
        return
    gaps = np.asarray(gaps)
    k = int(np.argmin(gaps)) if gaps.size else 0
    setup = model.contact
    if not gaps.size or gaps[k] >= setup.activation:
        return
    S, C = model.network.n_segments, model.n_obstacles
    if k < S * C:
        name = setup.names[k % C]
        what = f"segment {k // C} and {'the ' if name in ('probe face', 'substrate') else ''}{name}"
    else:
        i, j = np.asarray(state.pairs)[k - S * C, :2].astype(int)
        what = f"segments {i} and {j}"
    raise ValueError(f"contact: as built, {what} are {gaps[k] * 1e3:.3g} nm apart surface to surface (negative: "
                     f"overlapping), below the contact activation distance δ = {float(setup.activation) * 1e3:.3g} nm; a "
                     "path starts from a state without contact forces. Build the network with them farther apart, "
                     "or give a smaller Contact(diameter=...) or activation")
