"""Figure of a lawn model's prediction: :func:`plot_lawn` (force and stress–strain, with every
realisation and the standard error of their mean).  Units: µm, pN, Pa."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from ._lawn import LawnModel
from ._mplfigure import new_figure

__all__ = ["plot_lawn"]


def plot_lawn(model: LawnModel, values: dict | None = None, compression=None, *, title: str | None = None) -> Figure:
    """Two panels for ``model`` at ``values`` (default: its defaults) over ``compression``
    (µm; default 40 points to 0.1 × the film height): the lawn force (pN) if every outcrop
    under the probe were realisation k (thin lines, one per realisation; dashed red where its
    path failed or its nodes crossed a surface), their mean — the model — with its standard
    error over the realisations (band), and the mean stress (Pa) against strain
    (compression / film height)."""
    values = dict(values or {})
    if compression is None:
        compression = np.linspace(0.0, 0.1 * model.film_height, 40)
    c = np.asarray(compression, float)
    if c.ndim != 1 or c.size < 2 or not np.all(np.isfinite(c)):
        raise ValueError(f"compression must be a 1-D array of at least 2 finite compressions (µm), got shape {c.shape}")
    reach = float(c.max())
    if not 0 < reach < model.gap:
        raise ValueError(f"compression must reach above 0 and stay below the film height {model.gap:g} µm, "
                         f"got a largest value of {reach:g} µm")
    # the force of an inextensible network rises to its plateau within ~1e-4 µm of contact:
    # drawn as the jump it is, from the point at contact to its limit just after (0⁺)
    c = np.unique(np.concatenate([c, [1e-6 * reach]])) if np.any(c <= 0) else c
    forces, ok = model.lawn_forces(values, np.clip(c, 0.0, None), reach=reach)
    forces, ok = np.asarray(forces), np.asarray(ok)
    mean = forces.mean(axis=0)
    n = forces.shape[0]
    se = forces.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros_like(mean)
    fig = new_figure((9.6, 3.9))
    left, right = fig.subplots(1, 2)
    for k, f in enumerate(forces):
        label = "every outcrop as realisation k" if k == 0 else None
        left.plot(c, f, color="0.7" if ok[k] else "C3", lw=0.8, ls="-" if ok[k] else "--", label=label)
    if not ok.all():
        left.plot([], [], color="C3", ls="--", lw=0.8, label=f"{int((~ok).sum())} crossed a surface / failed")
    left.fill_between(c, mean - se, mean + se, color="C0", alpha=0.25, lw=0, label="± standard error of the mean")
    left.plot(c, mean, color="C0", lw=2.0, label=f"model: mean of {n} realisation{'s' if n > 1 else ''}")
    left.set_xlabel("compression (µm)")
    left.set_ylabel("probe force (pN)")
    left.legend(fontsize="small", loc="lower right")
    strain = np.asarray(model.strain(c))
    stress = np.asarray(model.stress(mean, c))
    right.plot(100 * strain, stress, color="C1", lw=2.0)
    right.set_xlabel("strain (% of the film height)")
    right.set_ylabel("mean stress under the probe (Pa)")
    EI = values.get("EI", model.parameters["EI"].value)
    rho = values.get("density", model.parameters["density"].value)
    note = (f"{model.probe}\nfilm {model.film_height:g} µm, ρ = {float(rho):g} µm⁻², EI = {float(EI):.3g} pN·µm²"
            + ("" if ok.all() else "\nmodel NaN: a realisation's nodes crossed a surface (no contact model)"))
    right.text(0.03, 0.97, note, transform=right.transAxes, ha="left", va="top", fontsize="small",
               bbox={"boxstyle": "round,pad=0.35", "fc": "white", "ec": "0.75", "alpha": 0.9})
    fig.suptitle((f"{title}: " if title else "") + "lawn of random dendritic outcrops under the probe", fontsize="medium")
    return fig
