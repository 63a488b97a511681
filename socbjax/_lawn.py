"""A lawn of dendritic outcrops under an AFM probe: :class:`LawnModel` (fit model ``"lawn"``).

An AFM probe compresses a film of outcrops (:func:`socbjax.dendritic_outcrop`) nucleated on
the substrate at areal density ρ (µm⁻²).  The model keeps ``n_outcrops`` random
realisations (seeds ``seed``, ``seed + 1``, …), all grown to the film height, and treats the
outcrops as mechanically independent (no contact between them yet), so the force is the
number of outcrops under the probe times their mean force F̄(u) (pN) at probe travel u:

* **flat disc** of area A (µm²): every outcrop under it is compressed by u,
  ``F(u) = ρ A F̄(u)``;
* **sphere** of radius R (µm): an outcrop at distance r from the axis is compressed by
  u − r²/(2R) (the parabolic gap of the sphere, r ≪ R), so with 2πr dr = 2πR dw,
  ``F(δ) = 2π R ρ ∫₀^δ F̄(w) dw``; the contact area grows as π a² = 2π R δ.

F̄ is the average over the realisations, evaluated as one vmapped
:func:`socbjax.compress` (``at=`` the probe travels, exact equilibria with implicit
derivatives): every realisation is padded to the universal tree of its growth rules
(:func:`socbjax.pad_outcrop`, inert free tails and subtrees), so all seeds are one batch of
one topology and a new seed reuses the compiled program.  A realisation that does not fit
the tree (a last growth of more pieces than a generation's; not with the default 1 µm
growth in 0.5 µm segments) is solved in a batch of its own topology.  The same seeds are
used at every evaluation — common random numbers across the iterations of a fit — and
:meth:`LawnModel.realisation_spread` gives the spread of the
realisations; a fit's ``realisation_errors`` propagate it, for the model's finite sample
and for the experiment's own ρA outcrops under the probe
(:meth:`LawnModel.realisation_covariance`).  Without a contact model, ``screen=u`` keeps
only realisations that can be followed to the travel u without crossing a surface.

Identifiability: at fixed geometry the force scales exactly with EI (GJ scaled with it) and ρ, so one curve
determines only ρ · EI; a fit refuses both free (fix one at an independently measured value).
The branch angle changes the random growth discretely (which strands reach the surface), so
it is a topology option here, not a fitted parameter.

Units: µm, pN, pN·µm²; stress in Pa (pN/µm² = Pa); strain = compression / film height.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import check_int, check_real
from ._compress import compress
from ._curved import ACTIN_GJ
from ._dendritic import dendritic_outcrop
from ._fit_model import FitModel, contact_shift
from ._padding import pad_outcrop
from ._parameters import NUISANCE_PARAMETERS, Parameter
from ._solution import RESULTS

__all__ = ["LawnModel"]

_ACTIN_EI = 0.071
_BUILT_PERTURBATION = 1e-4  # pN, the outcrop builder's default lateral force per strand
_GRID = 48  # probe travels at which F̄ is solved for the sphere's integral


class LawnModel(FitModel):
    """A probe pressing a film of random dendritic outcrops (see the module docstring).

    Parameters
    ----------
    probe_radius : sphere radius R (µm), or None for a flat disc.
    probe_area : flat disc area A (µm², default 20); not with ``probe_radius``.
    film_height : film thickness (µm): the outcrops' probe–substrate gap.
    generations, growth, segment_length, branch_angle, dim : of each outcrop
        (:func:`socbjax.dendritic_outcrop`; branch angle in degrees fixes the topology).
    GJ : torsional stiffness (pN·µm²) at the built EI = 0.071: actin's 8e-3 by default
        (3D Kirchhoff rods), None for the paper's torsion-free model.  A fitted EI scales GJ
        with it (GJ/EI stays at its built ratio), so the force stays exactly ∝ EI.
    n_outcrops : realisations averaged (seeds ``seed`` … ``seed + n_outcrops − 1``).
    seeds : explicit outcrop seeds (a sequence of distinct integers ≥ 0) instead of
        ``seed`` and ``n_outcrops``.
    screen : None, or a probe travel (µm, below ``film_height``): keep only realisations
        that can be followed to it at the built loads — whose nodes do not cross the
        substrate or the probe plane before (3D networks have no contact yet: such a path is not
        physical and a fit could not evaluate it). Seeds are drawn ``seed``, ``seed + 1``, …
        until ``n_outcrops`` pass (with ``seeds``: those of them that pass); the seeds
        refused are ``screened_out``. The lawn is then that of the screened population.

    Fit parameters: ``EI`` (pN·µm²), ``density`` (µm⁻²), ``perturbation`` (pN), and
    ``branch_angle`` (deg, fixed only: it is the topology's angle), plus the curve's own
    ``contact_point`` (µm), ``baseline`` (pN), ``baseline_tilt`` (pN/µm).

    Attributes: ``members`` (the realisations as built, one network per seed), ``padded``
    (indices of those padded to the universal tree, :func:`socbjax.pad_outcrop`: all of
    them with the default growth) and ``topology_groups`` (the batches, one compiled program
    each: the padded realisations first, then any that did not fit, by topology).
    """

    name = "lawn"
    force_scales = ("density",)

    def __init__(self, probe_radius: float | None = None, probe_area: float | None = None, *,
                 film_height: float = 3.0, generations: int = 4, n_outcrops: int = 8, seed: int = 0,
                 branch_angle: float = 70.0, growth: float = 1.0, segment_length: float = 0.5, dim: int = 3,
                 seeds=None, screen: float | None = None, GJ: float | None = ACTIN_GJ):
        if probe_radius is not None and probe_area is not None:
            raise ValueError("give probe_radius (sphere, µm) or probe_area (flat disc, µm²), not both")
        self.probe_radius = None if probe_radius is None else check_real("probe_radius", probe_radius, "µm", low=0.0, traced_ok=False)
        self.probe_area = None if probe_radius is not None else check_real(
            "probe_area", 20.0 if probe_area is None else probe_area, "µm²", low=0.0, traced_ok=False)
        self.film_height = check_real("film_height", film_height, "µm", low=0.0, traced_ok=False)
        self.branch_angle = float(branch_angle)
        self.generations = int(generations)

        def grow(k):
            return dendritic_outcrop(generations=generations, gap=self.film_height, growth=growth,
                                     segment_length=segment_length, branch_angle=branch_angle, EI=_ACTIN_EI, seed=k,
                                     dim=dim, GJ=GJ)

        self.seeds, self.screened_out, self.screen = _seeds(seeds, seed, n_outcrops), (), None
        built = {}
        if screen is not None:
            self.screen = check_real("screen", screen, "µm", low=0.0, traced_ok=False)
            if not self.screen < self.film_height:
                raise ValueError(f"screen must be a probe travel below film_height={self.film_height:g} µm, got "
                                 f"{self.screen:g}")
            built = _screened(grow, self.seeds, seeds is None, self.screen, self.generations)
            self.seeds, self.screened_out = tuple(built["passed"]), built.pop("refused")
        self.n_outcrops, self.seed = len(self.seeds), self.seeds[0]
        self.members = [built["passed"][k] if k in built.get("passed", {}) else grow(k) for k in self.seeds]
        self.base = self.members[0]
        self.groups = {}  # EI groups of FitModel (none: one EI for all filaments)
        self.topology_groups, self.padded, self._stacked = _batches(self.members, self.generations)
        self.parameters = {
            "EI": Parameter("EI", _ACTIN_EI, "pN·µm²", lower=0.0, doc="bending stiffness of all filaments"),
            "density": Parameter("density", 1.0, "µm⁻²", lower=0.0, doc="areal density of outcrops on the substrate"),
            "branch_angle": Parameter("branch_angle", self.branch_angle, "deg", lower=0.0, upper=90.0,
                                      doc="daughter–mother angle (topology: fixed only)"),
            "perturbation": Parameter("perturbation", 1e-5, "pN", lower=0.0,
                                      doc="lateral force on the middle of every strand"),
        }

    # ------------------------------------------------------------------ description
    @property
    def gap(self) -> float:
        return self.film_height

    @property
    def probe(self) -> str:
        if self.probe_radius is None:
            return f"flat disc of area {self.probe_area:g} µm²"
        return f"sphere of radius {self.probe_radius:g} µm"

    def describe(self) -> str:
        sizes = [m.n_segments for m in self.members]
        n_topo = len(self.topology_groups)
        lines = [(f"lawn: {self.probe}, film {self.film_height:g} µm, {self.n_outcrops} outcrop realisation(s) "
                  f"({min(sizes)}–{max(sizes)} segments; {len(self.padded)} padded to one topology, "
                  f"{n_topo} compiled program{'' if n_topo == 1 else 's'})")]
        if self.screen is not None:
            lines.append(f"  screened: realisations followed to {self.screen:g} µm without crossing a surface "
                         f"({len(self.screened_out)} seed(s) refused)")
        for p in self.parameters.values():
            lines.append(f"  {p.name:<14s} default {p.value:<10.4g} {p.unit:<8s} bounds ({p.lower}, {p.upper})  {p.doc}")
        return "\n".join(lines)

    def area(self, compression):
        """Probe–film contact area (µm²) at probe travel ``compression`` (µm): A for the disc,
        2π R δ for the sphere."""
        if self.probe_radius is None:
            return self.probe_area * jnp.ones_like(jnp.asarray(compression, jnp.float64))
        return 2 * math.pi * self.probe_radius * jnp.maximum(jnp.asarray(compression, jnp.float64), 0.0)

    def stress(self, force, compression):
        """Mean stress under the probe (Pa = pN/µm²): force / contact area (NaN at zero area)."""
        a = self.area(compression)
        return jnp.where(a > 0, jnp.asarray(force) / jnp.where(a > 0, a, 1.0), jnp.nan)

    def strain(self, compression):
        """Engineering strain of the film: compression / film height."""
        return jnp.asarray(compression, jnp.float64) / self.film_height

    # ------------------------------------------------------------------ the physics
    def _member_values(self, values: dict, stacked):
        EI = values.get("EI", self.parameters["EI"].value)
        EI_arr = jnp.ones_like(stacked.EI) * EI
        if "perturbation" in values:
            loads = stacked.loads * (values["perturbation"] / _BUILT_PERTURBATION)
        else:  # the builder's loads, scaled with EI so that forces scale exactly with EI
            loads = stacked.loads * (EI / _ACTIN_EI)
        # GJ scales with EI (zeros when torsion-free): every stiffness, hence the force, ∝ EI
        return stacked.replace(EI=EI_arr, loads=loads, GJ=stacked.GJ * (EI / _ACTIN_EI))

    def network(self, values: dict):
        """The first realisation at ``values`` (what a diagnosis of a failed path inspects)."""
        self._check_values(values)
        return self._member_values({k: v for k, v in values.items() if k in ("EI", "perturbation")}, self.members[0])

    def _check_values(self, values: dict) -> None:
        unknown = set(values) - set(self.parameters)
        if unknown:
            raise ValueError(f"lawn has no parameter(s) {sorted(unknown)}; it has {sorted(self.parameters)}")
        angle = values.get("branch_angle", self.branch_angle)
        p = values.get("perturbation", 1.0)
        if not isinstance(p, jax.core.Tracer) and not float(p) > 0:
            raise ValueError(f"the lawn's perturbation must be a positive lateral force (pN), got {float(p)!r}: the "
                             "outcrops' loads carry it, and a straight strand between probe and surface needs one")
        if not isinstance(angle, jax.core.Tracer) and abs(float(angle) - self.branch_angle) < 1e-12:
            return
        raise ValueError(f"the lawn's branch_angle is its outcrops' topology ({self.branch_angle:g}°): it changes "
                         "their random growth discretely and cannot be fitted or changed per evaluation; build "
                         "socbjax.LawnModel(branch_angle=...) at each angle (a grid), or fit the angle on the unit mesh")

    def outcrop_forces(self, values: dict, u, *, reach: float, retract=None, method: str = "displacement",
                       settings=None) -> tuple:
        """(forces [n_outcrops, m], ok [n_outcrops]): each realisation's probe force (pN) at
        probe travels ``u`` [m] (µm), in seed order; ``ok`` False where its path failed or its
        nodes crossed the surface or probe plane."""
        self._check_values({k: v for k, v in values.items() if k in self.parameters})
        u = jnp.asarray(u, jnp.float64)
        at = jnp.clip(u, 1e-6 * reach, reach)
        forces, oks, order = [], [], []
        for group, stacked in zip(self.topology_groups, self._stacked):
            nets = self._member_values(values, stacked)

            def one(net):
                # perturbation=None: the loads already carry it (scaled in _member_values)
                r = compress(net, reach, at=at, unload=retract is not None, method=method, settings=settings,
                             throw=False)
                f = r.force[:u.shape[0]]
                if retract is not None:
                    f = jnp.where(np.asarray(retract, bool), r.force[u.shape[0]:][::-1], f)
                return f, _followed_to_the_end(r)

            f, ok = jax.vmap(one)(nets)
            forces.append(f)
            oks.append(ok)
            order.extend(group)
        inverse = np.argsort(np.asarray(order))
        forces, oks = jnp.concatenate(forces)[inverse], jnp.concatenate(oks)[inverse]
        return jnp.where(u[None, :] > 0, forces, 0.0), oks

    def lawn_forces(self, values: dict, u, *, reach: float, retract=None, method: str = "displacement",
                    settings=None) -> tuple:
        """(forces [n_outcrops, m], ok [n_outcrops]): the lawn force (pN) at probe travels
        ``u`` [m] (µm) if every outcrop under the probe were realisation k (ρ A F_k, or
        2π R ρ ∫₀^δ F_k for the sphere); their mean is the model's force.  ``ok[k]`` is False
        where realisation k's path failed or its nodes crossed the surface or probe plane."""
        density = values.get("density", self.parameters["density"].value)
        u = jnp.asarray(u, jnp.float64)
        if self.probe_radius is None:
            forces, ok = self.outcrop_forces(values, u, reach=reach, retract=retract, method=method, settings=settings)
            return density * self.probe_area * forces, ok
        # sphere: F_k solved on a grid of probe travels and integrated exactly as its
        # piecewise-linear interpolant (so d/dδ of the force is 2π R ρ F_k(δ) interpolated)
        grid = _travel_grid(reach)
        on_retract = np.zeros(u.shape[0], bool) if retract is None else np.asarray(retract, bool)
        total = jnp.zeros((self.n_outcrops, u.shape[0]))
        ok = jnp.ones(self.n_outcrops, bool)
        for branch in sorted(set(on_retract.tolist())):
            forces, fine = self.outcrop_forces(values, grid, reach=reach,
                                               retract=np.ones(grid.shape[0], bool) if branch else None, method=method,
                                               settings=settings)
            value = jax.vmap(lambda f: _integral(grid, f, u))(forces)
            total = jnp.where(on_retract[None, :] == branch, 2 * math.pi * self.probe_radius * density * value, total)
            ok = ok & fine
        return jnp.where(u[None, :] > 0, total, 0.0), ok

    def probe_force(self, values: dict, u, *, reach: float, retract=None, method: str = "displacement",
                    settings=None, throw: bool = False) -> tuple:
        """(force [m], ok): the lawn's probe force (pN) at probe travels ``u`` [m] (µm), the
        mean of :meth:`lawn_forces` over the realisations; see
        :meth:`socbjax.FitModel.probe_force` (``throw`` is ignored: the realisations are vmapped)."""
        forces, ok = self.lawn_forces(values, u, reach=reach, retract=retract, method=method, settings=settings)
        return jnp.mean(forces, axis=0), jnp.all(ok)

    def _realisations(self, values: dict, c: np.ndarray, *, reach: float, retract=None, method="displacement",
                      settings=None) -> np.ndarray:
        """[n_outcrops, m] :meth:`lawn_forces` (pN, numpy) at the data compressions ``c`` with
        the contact shift of ``values`` applied, the curve's other terms left out."""
        physical = {k: v for k, v in values.items() if k not in NUISANCE_PARAMETERS}
        u = c + float(contact_shift(values))
        forces, _ = self.lawn_forces(physical, u, reach=reach, retract=retract, method=method, settings=settings)
        return np.asarray(forces)

    def outcrops_under_probe(self, values: dict, compression) -> float:
        """How many outcrops the experiment's probe presses at ``values`` (its ``density``,
        µm⁻²): ρ A for the flat disc; ρ 2π R δ_max for the sphere, those within the contact
        area at the deepest probe travel δ_max (µm; ``compression`` with the contact terms of
        ``values`` applied)."""
        density = float(values.get("density", self.parameters["density"].value))
        if self.probe_radius is None:
            return density * self.probe_area
        deepest = float(np.max(np.asarray(compression, float) + float(contact_shift(values))))
        return density * 2 * math.pi * self.probe_radius * max(deepest, 0.0)

    def realisation_covariance(self, values: dict, compression, *, reach: float, retract=None, method="displacement",
                               settings=None, experiment: bool = True) -> np.ndarray:
        """[m, m] covariance (pN²) of the model force at the data compressions (µm; contact
        terms of ``values`` applied) that comes from random outcrops: S (1/n_outcrops + 1/n_p),
        S the sample covariance of :meth:`lawn_forces` over the realisations.  1/n_outcrops:
        the model averages a finite sample of realisations; 1/n_p (``experiment``): the
        experiment's curve is itself the force of the n_p random outcrops under its probe
        (:meth:`outcrops_under_probe`; for the sphere an approximation, n_p at the deepest
        travel), which differ from the population's mean just as the model's do.  Zeros for a
        single realisation (no spread to estimate)."""
        c = np.asarray(compression, float)
        forces = self._realisations(values, c, reach=reach, retract=retract, method=method, settings=settings)
        forces = forces * float(values.get("force_scale", 1.0))
        if self.n_outcrops < 2:
            return np.zeros((c.size, c.size))
        n_p = self.outcrops_under_probe(values, c) if experiment else math.inf
        share = 1.0 / self.n_outcrops + (1.0 / n_p if n_p > 0 else 0.0)
        return np.cov(forces, rowvar=False, ddof=1).reshape(c.size, c.size) * share

    def realisation_spread(self, values: dict, compression, *, reach: float | None = None):
        """(mean [m], standard error [m]) of the lawn force (pN) over the realisations at the
        data compressions (µm; contact terms of ``values`` applied): the standard error of the
        mean over ``n_outcrops`` realisations is the part of the prediction's uncertainty that
        comes from the finite sample of random outcrops."""
        c = np.asarray(compression, float)
        if reach is None:
            reach = min(float(np.max(c + float(contact_shift(values)))), 0.95 * self.gap)
        forces = self._realisations(values, c, reach=reach)
        se = forces.std(axis=0, ddof=1) / np.sqrt(self.n_outcrops) if self.n_outcrops > 1 else np.zeros(c.size)
        return forces.mean(axis=0), se

    def realisation_errors(self, problem, values: dict, J, z) -> dict:
        """Standard error of each free parameter (in its unit) that comes from random
        outcrops — the model's finite sample and the experiment's own outcrops under the
        probe (:meth:`realisation_covariance`) — by the delta method: with the residual
        Jacobian J [m, p] in the unconstrained variables z at the optimum, A = JᵀJ, Σ_r = Σ_F/σσᵀ (Σ_F from
        :meth:`realisation_covariance`), Cov_z = A⁻¹ Jᵀ Σ_r J A⁻¹, mapped by D = dθ/dz."""
        table = problem.table
        D = np.array([float(jax.grad(table[n].to_value)(float(z[i]))) for i, n in enumerate(problem.free)])
        cov_f = self.realisation_covariance(values, problem.compression, reach=problem.reach, retract=problem.retract)
        sigma = np.asarray(problem.sigma, float)
        cov_r = cov_f / np.outer(sigma, sigma)
        A_inv = np.linalg.pinv(J.T @ J)
        cov_z = A_inv @ J.T @ cov_r @ J @ A_inv
        se = np.abs(D) * np.sqrt(np.abs(np.diag(cov_z)))
        return dict(zip(problem.free, map(float, se)))


def _seeds(seeds, seed, n_outcrops) -> tuple:
    """The outcrop seeds: ``seeds`` checked (distinct integers ≥ 0), else ``seed`` …
    ``seed + n_outcrops − 1``."""
    if seeds is None:
        n = check_int("n_outcrops", n_outcrops, minimum=1, maximum=4096)
        first = check_int("seed", seed, minimum=0)
        return tuple(range(first, first + n))
    if isinstance(seeds, (str, bytes)) or not hasattr(seeds, "__len__"):
        raise TypeError(f"seeds must be a sequence of integers, got {type(seeds).__name__}")
    out = tuple(check_int("seeds", k, minimum=0) for k in seeds)
    if not 1 <= len(out) <= 4096 or len(set(out)) != len(out):
        raise ValueError(f"seeds must be 1 to 4096 distinct integers ≥ 0 (equal seeds are equal outcrops), "
                         f"got {list(out)}")
    return out


_SCREEN_ROUNDS = 16


def _screened(grow, seeds: tuple, draw: bool, screen: float, generations: int) -> dict:
    """{"passed": {seed: network}, "refused": seeds}: the realisations ``grow(k)`` that can be
    followed to ``screen`` µm (:func:`_followed`), built once and kept for the lawn;
    ``draw``: candidates in rounds of len(seeds) consecutive seeds until that many pass (one
    compiled program for every round), else ``seeds`` once."""
    want, passed, refused = len(seeds), {}, []
    candidates = seeds
    for _ in range(_SCREEN_ROUNDS if draw else 1):
        members = [grow(k) for k in candidates]
        groups, _, stacked = _batches(members, generations)
        ok = np.zeros(len(candidates), bool)
        for group, nets in zip(groups, stacked):
            ok[list(group)] = np.asarray(_followed(nets, screen))
        passed.update((k, net) for k, net, good in zip(candidates, members, ok) if good)
        refused += [k for k, good in zip(candidates, ok) if not good]
        if len(passed) >= want or not draw:
            break
        candidates = tuple(range(candidates[-1] + 1, candidates[-1] + 1 + want))
    if not passed or (draw and len(passed) < want):
        raise ValueError(f"screen={screen:g} µm: only {len(passed)} of {len(passed) + len(refused)} realisations can "
                         f"be followed that far (the others' nodes cross the substrate or the probe plane: no contact "
                         f"model yet); screen to a smaller travel, or give fewer n_outcrops")
    kept = list(passed)[:want] if draw else list(passed)
    return {"passed": {k: passed[k] for k in kept},
            "refused": tuple(k for k in refused if not draw or k < kept[-1])}


def _followed_to_the_end(result) -> jnp.ndarray:
    """Whether a :func:`socbjax.compress` result reached its travel: converged, and no node
    crossed the substrate or the probe plane (no contact model: such a path is not physical)."""
    return jnp.all(result.converged) & (result.result != RESULTS.surface_crossed)


@functools.partial(jax.jit, static_argnames=("reach",))
def _followed(stacked, reach: float):
    """[n] bool: each of a batch of networks followed to ``reach`` µm without failing or
    crossing the substrate or the probe plane."""

    def one(net):
        return _followed_to_the_end(compress(net, reach, at=jnp.asarray([reach]), throw=False))

    return jax.vmap(one)(stacked)


def _batches(members, generations: int):
    """(index groups, padded indices, stacked networks): the realisations that fit the
    universal tree (:func:`socbjax.pad_outcrop`) padded and stacked as one batch (one
    compiled program for every seed), each other realisation grouped by its own topology."""
    padded, rest = {}, {}
    for k, net in enumerate(members):
        try:
            padded[k] = pad_outcrop(net, generations)[0]
        except ValueError:
            rest.setdefault(net.topology, []).append(k)
    groups = ([tuple(padded)] if padded else []) + [tuple(v) for v in rest.values()]
    stacked = [jax.tree_util.tree_map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]),
                                      *[padded.get(k, members[k]) for k in g]) for g in groups]
    return groups, tuple(padded), stacked


def _travel_grid(reach):
    """Probe travels (µm) at which F̄ is solved for the sphere: geometric near contact, where
    the force of an inextensible network rises to its buckling plateau within ~1e-4 of the
    travel, then uniform; the first point is F̄'s limit at contact (1e-7 of the reach).
    ``reach`` may be traced (a fit's compiled residuals): the grid is a fixed shape × reach."""
    unit = np.concatenate([np.geomspace(1e-7, 0.02, _GRID // 4, endpoint=False), np.linspace(0.02, 1.0, _GRID - _GRID // 4)])
    return reach * jnp.asarray(unit)


def _integral(grid, values, x):
    """∫₀^x of the piecewise-linear interpolant of ``values`` on ``grid`` (increasing; the
    interpolant is continued flat from grid[0] to 0), exact; x clipped to [0, grid[-1]]."""
    grid = jnp.asarray(grid)
    h = jnp.diff(grid)
    cumulative = jnp.concatenate([jnp.zeros(1), jnp.cumsum(0.5 * (values[1:] + values[:-1]) * h)])
    x = jnp.clip(x, 0.0, grid[-1])
    k = jnp.clip(jnp.searchsorted(grid, x, side="right") - 1, 0, grid.shape[0] - 2)
    t = jnp.maximum(x - grid[k], 0.0)
    slope = (values[k + 1] - values[k]) / h[k]
    head = values[0] * jnp.minimum(x, grid[0])  # [0, grid[0]]: F̄(0⁺)
    return head + cumulative[k] + values[k] * t + 0.5 * slope * t**2
