"""The lawn model (socbjax.LawnModel, fit model "lawn"): a probe on a film of random outcrops.

References are independent of the lawn's own arithmetic: each realisation compressed on its
own by socbjax.compress (flat disc: ρ A × their mean), a brute-force sum over rings of
outcrops under a sphere (the sphere's integral identity), central finite differences for the
derivatives, and the exact scaling F ∝ EI · ρ for the identifiability refusal.
"""

import math

import jax
import numpy as np
import pytest

import socbjax as sj

LAWN = dict(generations=3, n_outcrops=2, film_height=3.0, dim=2)
C = np.array([-0.05, 0.02, 0.08, 0.15, 0.22, 0.3])  # µm, one point before contact
REACH = 0.3


@pytest.fixture(scope="module")
def flat():
    return sj.LawnModel(probe_area=12.0, **LAWN)


@pytest.fixture(scope="module")
def realisations(flat):
    """Each outcrop compressed on its own: probe force (pN) at C (0 before contact)."""
    out = []
    for net in flat.members:
        r = sj.compress(net, REACH, at=np.clip(C, 1e-6, REACH), throw=False)
        assert bool(np.all(np.asarray(r.converged)))
        out.append(np.where(C > 0, np.asarray(r.force), 0.0))
    return np.array(out)


def test_registered_with_contract_parameters(flat):
    assert sj.FIT_MODELS["lawn"] is sj.LawnModel
    assert isinstance(sj.make_fit_model("lawn", **LAWN), sj.LawnModel)
    table = {**flat.parameters, **sj.NUISANCE_PARAMETERS}
    for name in ("EI", "branch_angle", "density", "contact_point", "baseline"):
        assert name in table
    assert table["density"].unit == "µm⁻²"
    assert [m.n_segments for m in flat.members] and flat.gap == 3.0


def test_flat_disc_is_density_area_mean(flat, realisations):
    values = {"EI": 0.071, "density": 2.5}
    F = np.asarray(flat.predict(values, C, reach=REACH))
    np.testing.assert_allclose(F, 2.5 * 12.0 * realisations.mean(axis=0), rtol=1e-9, atol=1e-12)
    assert F[0] == 0.0 and np.all(F[1:] > 0)
    # stress (Pa = pN/µm²) and strain
    np.testing.assert_allclose(np.asarray(flat.stress(F, C)), F / 12.0)
    np.testing.assert_allclose(np.asarray(flat.strain(C)), C / 3.0)
    # the curve's own terms: contact point shifts, baseline and tilt add
    shifted = np.asarray(flat.predict({**values, "contact_point": 0.05, "baseline": 1.5, "baseline_tilt": 2.0},
                                      C + 0.05, reach=REACH))
    np.testing.assert_allclose(shifted, F + 1.5 + 2.0 * (C + 0.05), rtol=1e-8, atol=1e-9)


def test_forces_scale_with_ei_and_density(flat):
    """F ∝ EI · ρ at fixed geometry (builder loads scaled with EI): why a fit refuses both free."""
    a = np.asarray(flat.predict({"EI": 0.071, "density": 1.0}, C, reach=REACH))
    b = np.asarray(flat.predict({"EI": 0.142, "density": 0.5}, C, reach=REACH))
    np.testing.assert_allclose(a, b, rtol=1e-7, atol=1e-10)
    curve = (C, a)
    with pytest.raises(ValueError, match="density, EI are not separately identifiable"):
        sj.fit(curve, flat, free=("EI", "density"))
    with pytest.raises(ValueError, match="branch_angle is its outcrops' topology"):
        sj.fit(curve, flat, free=("EI", "branch_angle"))


def test_gradients_match_finite_differences(flat):
    def f(EI, cp):
        return flat.predict({"EI": EI, "density": 1.0, "contact_point": cp}, C, reach=REACH)[-2]

    g = jax.grad(f, argnums=(0, 1))(0.071, 0.01)
    h1, h2 = 1e-5, 1e-6
    fd_ei = (f(0.071 + h1, 0.01) - f(0.071 - h1, 0.01)) / (2 * h1)
    fd_cp = (f(0.071, 0.01 + h2) - f(0.071, 0.01 - h2)) / (2 * h2)
    np.testing.assert_allclose(float(g[0]), float(fd_ei), rtol=1e-6)
    np.testing.assert_allclose(float(g[1]), float(fd_cp), rtol=1e-5)


@pytest.mark.slow  # 30 s; the default suite checks the flat disc against independent compressions
def test_sphere_matches_sum_over_rings(flat):
    """Sphere of radius R: an outcrop at distance r is compressed by δ − r²/(2R); summing
    ρ 2πr dr F̄ over fine rings (midpoint rule in r, each ring's F̄ from the realisations)
    must match the lawn's integral form 2πRρ ∫₀^δ F̄."""
    R, rho = 4.0, 1.5
    sphere = sj.LawnModel(probe_radius=R, **LAWN)
    delta = np.array([0.1, 0.25])
    F = np.asarray(sphere.predict({"EI": 0.071, "density": rho}, delta, reach=REACH))
    for d, value in zip(delta, F):
        a = math.sqrt(2 * R * d)
        edges = np.linspace(0.0, a, 121)
        r = 0.5 * (edges[1:] + edges[:-1])
        u = d - r**2 / (2 * R)
        forces, ok = flat.outcrop_forces({"EI": 0.071}, u, reach=REACH)
        assert bool(np.all(np.asarray(ok)))
        ring_sum = rho * np.sum(2 * math.pi * r * np.diff(edges) * np.asarray(forces).mean(axis=0))
        np.testing.assert_allclose(value, ring_sum, rtol=5e-3)
    np.testing.assert_allclose(np.asarray(sphere.area(delta)), 2 * math.pi * R * delta)


def test_plot_lawn_shows_realisations_mean_and_stress(flat, realisations):
    fig = sj.plot_lawn(flat, {"EI": 0.071, "density": 2.5}, np.r_[0.01, C[1:]])  # 6 points: the compiled program
    force_axes, stress_axes = fig.axes[:2]
    assert force_axes.get_ylabel() == "probe force (pN)" and stress_axes.get_ylabel().endswith("(Pa)")
    mean = force_axes.lines[-1].get_ydata()
    np.testing.assert_allclose(mean[1:], 2.5 * 12.0 * realisations.mean(axis=0)[1:], rtol=1e-9, atol=1e-12)
    assert len(force_axes.lines) == flat.n_outcrops + 1
    np.testing.assert_allclose(stress_axes.lines[0].get_ydata()[1:], mean[1:] / 12.0)
    assert fig._repr_png_()[:4] == b"\x89PNG"
    with pytest.raises(ValueError, match="film height"):
        sj.plot_lawn(flat, None, [0.0, 5.0])


def test_realisation_covariance_counts_model_and_experiment_samples(flat, realisations):
    """The lawn force's covariance from random outcrops: the sample covariance S of the
    lawn force as if every outcrop were realisation k (ρ A F_k, F_k compressed on its own)
    times 1/n_outcrops (the model's sample) + 1/(ρ A) (the experiment's outcrops)."""
    values = {"EI": 0.071, "density": 1.5}
    S = np.cov(1.5 * 12.0 * realisations, rowvar=False, ddof=1)
    assert np.max(np.abs(S)) > 0  # the two realisations differ
    assert flat.outcrops_under_probe(values, C) == pytest.approx(18.0)
    both = flat.realisation_covariance(values, C, reach=REACH)
    np.testing.assert_allclose(both, S * (1 / 2 + 1 / 18), rtol=1e-8, atol=1e-12 * np.max(np.abs(S)))
    model_only = flat.realisation_covariance(values, C, reach=REACH, experiment=False)
    np.testing.assert_allclose(model_only, S / 2, rtol=1e-8, atol=1e-12 * np.max(np.abs(S)))


def test_explicit_seeds_choose_the_realisations(flat, realisations):
    swapped = sj.LawnModel(probe_area=12.0, seeds=(1, 0), **{k: v for k, v in LAWN.items() if k != "n_outcrops"})
    assert swapped.seeds == (1, 0) and swapped.n_outcrops == 2
    forces, ok = swapped.outcrop_forces({"EI": 0.071}, C, reach=REACH)
    np.testing.assert_allclose(np.asarray(forces), realisations[::-1], rtol=1e-9, atol=1e-12)
    assert bool(np.all(np.asarray(ok)))
    with pytest.raises(ValueError, match="distinct"):
        sj.LawnModel(seeds=(3, 3), generations=2)
    with pytest.raises(TypeError, match="seeds must be a sequence"):
        sj.LawnModel(seeds=5, generations=2)


def test_screen_keeps_realisations_that_can_be_followed(flat):
    """Both realisations of the fixture are followed to REACH on their own (the
    ``realisations`` fixture asserts it), so a screen at REACH keeps them and refuses none."""
    screened = sj.LawnModel(probe_area=12.0, screen=REACH, **LAWN)
    assert screened.seeds == flat.seeds and screened.screened_out == ()
    assert "screened" in screened.describe()
    with pytest.raises(ValueError, match="screen must be a probe travel below film_height"):
        sj.LawnModel(screen=3.0, film_height=3.0, generations=2)


@pytest.mark.slow  # 150 s: compiles a padded 3D Kirchhoff lawn
def test_a_twisting_3d_lawn_is_its_own_outcrops_and_scales_with_ei():
    """3D lawns twist by default (actin GJ); GJ scales with the fitted EI, so the force stays
    exactly ∝ EI, and the padded lawn is the mean of its outcrops compressed on their own."""
    lawn = sj.LawnModel(generations=2, n_outcrops=2, film_height=2.0, probe_area=5.0)
    assert all(m.twisting for m in lawn.members)
    c = np.array([0.0, 0.05, 0.1])
    F = np.asarray(lawn.predict({"EI": 0.071, "density": 1.0}, c, reach=0.1))
    np.testing.assert_allclose(np.asarray(lawn.predict({"EI": 0.142, "density": 1.0}, c, reach=0.1)), 2 * F,
                               rtol=1e-9, atol=1e-12)
    own = [np.asarray(sj.compress(m, 0.1, at=c[1:]).force) for m in lawn.members]
    np.testing.assert_allclose(F[1:], 5.0 * np.mean(own, axis=0), rtol=1e-9)


@pytest.mark.slow
def test_screen_refuses_realisations_that_cross_the_surface():
    """Planar outcrops of 4 generations at a 3 µm film: seeds 0 and 1 cross the surface
    before 0.3 µm when compressed on their own, seeds 2 and 3 do not; the screen draws on
    until two pass."""
    lawn = sj.LawnModel(generations=4, film_height=3.0, dim=2, n_outcrops=2, screen=0.3)
    assert lawn.seeds == (2, 3) and lawn.screened_out == (0, 1)
    for seed in (0, 1, 2, 3):
        r = sj.compress(sj.dendritic_outcrop(generations=4, gap=3.0, dim=2, seed=seed), 0.3, throw=False)
        assert (r.result == sj.RESULTS.surface_crossed) == (seed < 2)


def test_bad_options_are_named():
    with pytest.raises(ValueError, match="probe_radius .* or probe_area"):
        sj.LawnModel(probe_radius=2.0, probe_area=3.0)
    with pytest.raises(ValueError, match="n_outcrops"):
        sj.LawnModel(n_outcrops=0)
    with pytest.raises(ValueError, match="film_height"):
        sj.LawnModel(film_height=-1.0)


@pytest.mark.slow
def test_recovers_ei_and_contact_point_from_other_realisations():
    """Synthetic experiment: a 3D lawn of *other* outcrop seeds (the truth: random azimuths,
    so the realisations differ), 2 % noise, contact point shifted by 0.04 µm; the model (its
    own seeds) recovers EI within 5 % at the known density, the contact point within one
    point spacing, and reports the realisations' share of the uncertainty."""
    lawn = dict(generations=3, film_height=3.0, dim=2, n_outcrops=4, probe_area=12.0)  # 3D: > 25 CPU-min
    truth = sj.LawnModel(seed=100, **lawn)
    c = np.linspace(-0.1, 0.3, 41)
    EI, cp = 0.09, 0.04
    F = np.asarray(truth.predict({"EI": EI, "density": 1.0, "contact_point": cp}, c, reach=REACH))
    noisy = F + 0.02 * F.max() * np.random.default_rng(0).standard_normal(c.size)
    model = sj.LawnModel(seed=0, **lawn)
    result = sj.fit((c, noisy), model, free=("EI", "contact_point", "baseline"), fixed={"density": 1.0})
    assert result.converged and not result.misfit
    assert abs(result.values["EI"] / EI - 1) < 0.05
    assert abs(result.values["EI"] - EI) < 3 * result.standard_errors["EI"] + 3 * result.realisation_errors["EI"]
    assert abs(result.values["contact_point"] - cp) < 0.011
    assert 0 <= result.realisation_errors["EI"] < result.standard_errors["EI"] * 10
