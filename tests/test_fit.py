"""fit: parameter recovery from synthetic curves with noise, uncertainties that cover the
truth, identifiability, the optax optimisers, and clear errors for bad input."""

import json

import numpy as np
import pytest

import socbjax as sj
from socbjax import ColumnModel, UnitMeshModel

TRUTH = {"EI": 0.071, "branch_angle": 70.0}


def _synthetic(model, values, compression, seed, noise=0.02, displacement=None, **extra):
    network = model.network({k: v for k, v in values.items() if k in model.parameters})
    u = compression + extra.get("contact_offset", 0.0)
    clean = np.asarray(sj.compress(network, displacement or float(u.max()), at=np.maximum(u, 1e-6),
                                   perturbation=values.get("perturbation")).force)
    clean = np.where(u > 0, clean, 0.0) + extra.get("baseline", 0.0)
    rng = np.random.default_rng(seed)
    return clean + noise * np.abs(clean) * rng.standard_normal(clean.size)


@pytest.fixture(scope="module")
def unit_mesh():
    return UnitMeshModel(dim=2)


# the default suite checks a recovery in notebooks/fit_afm_curve.ipynb (within its standard errors)
@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_recovers_EI_and_branch_angle_from_noisy_curves(unit_mesh, seed):
    """2 % noise; start 50 % off in EI and 15° off in angle; EI within 2 %, angle within 1°,
    and the Gauss–Newton standard errors cover the truth (within 3 σ)."""
    c = np.linspace(0.005, 0.38, 40)  # below u ≈ 0.43 µm, where the mother crosses the surface
    F = _synthetic(unit_mesh, TRUTH, c, seed)
    result = sj.fit((c, F), unit_mesh, free=("EI", "branch_angle"), initial={"EI": 1.5 * 0.071, "branch_angle": 55.0})
    assert result.converged and result.identifiable, result.summary()
    assert result.values["EI"] == pytest.approx(0.071, rel=0.02)
    assert result.values["branch_angle"] == pytest.approx(70.0, abs=1.0)
    for name in ("EI", "branch_angle"):
        assert abs(result.values[name] - TRUTH[name]) <= 3 * result.standard_errors[name], result.summary()
    assert result.rms == pytest.approx(np.sqrt(np.mean((0.02 * F) ** 2)), rel=0.35)  # residuals ≈ the noise
    assert result.history[0]["loss"] > result.loss
    assert not any("systematic" in w for w in result.warnings)  # the right model leaves noise only


@pytest.mark.slow
def test_recovers_contact_offset_and_baseline_on_a_column():
    """An imperfect column (lateral force 0.1 pN, 14 % of its Euler load) stiffens smoothly
    from contact, so the contact point is determined by the data.  Pinned–pinned: it bulges
    through its supports' planes only past u ≈ 0.54 µm (the data reach 0.43 µm)."""
    model = ColumnModel(5, supports=("pinned", "pinned"), dim=2)
    c = np.linspace(-0.1, 0.4, 30)
    extra = {"contact_offset": 0.03, "baseline": 0.05}
    F = _synthetic(model, {"EI": 0.071, "perturbation": 0.1}, c, seed=4, noise=0.005, displacement=0.45, **extra)
    result = sj.fit((c, F), model, free=("EI", "contact_offset", "baseline"), initial={"EI": 0.05},
                    fixed={"perturbation": 0.1})
    assert result.converged, result.summary()
    assert result.values["EI"] == pytest.approx(0.071, rel=0.02)
    assert result.values["contact_offset"] == pytest.approx(0.03, abs=3e-3)
    assert result.values["baseline"] == pytest.approx(0.05, abs=0.02)
    assert result.correlation.shape == (3, 3) and np.allclose(np.diag(result.correlation), 1.0)


@pytest.mark.slow
@pytest.mark.parametrize("optimizer", ["adam", "lbfgs"])
def test_optax_optimisers_reach_the_least_squares_EI(optimizer):
    """One parameter: the least-squares EI of a noisy curve is known in closed form because the
    force is exactly proportional to EI: EI* = EI₀ Σ F f / Σ f² (f the model at EI₀)."""
    model = ColumnModel(4, supports=("pinned", "pinned"), dim=2)
    c = np.linspace(0.02, 0.3, 12)
    F = _synthetic(model, {"EI": 0.071}, c, seed=2)
    f0 = np.asarray(sj.compress(model.network({"EI": 0.071}), 0.3, at=c).force)
    best = 0.071 * float(F @ f0) / float(f0 @ f0)
    kwargs = {"learning_rate": 0.1, "max_iterations": 150} if optimizer == "adam" else {"max_iterations": 30}
    result = sj.fit((c, F), model, free="EI", initial={"EI": 0.05},
                    settings=sj.FitSettings(optimizer=optimizer, tolerance=1e-12, **kwargs))
    assert result.values["EI"] == pytest.approx(best, rel=2e-3)
    lm = sj.fit((c, F), model, free="EI", initial={"EI": 0.05})
    # LM stops on a relative loss decrease of 1e-8: far inside the standard error (~1 %)
    assert lm.values["EI"] == pytest.approx(best, rel=1e-4)
    assert abs(lm.values["EI"] - best) < 0.01 * lm.standard_errors["EI"]


def test_EI_and_force_scale_are_refused_together():
    c, F = np.linspace(0.01, 0.2, 5), np.ones(5)
    with pytest.raises(ValueError, match="not separately identifiable"):
        sj.fit((c, F), "column", model_options={"dim": 2}, free=("EI", "force_scale"))
    model = UnitMeshModel(dim=2)
    with pytest.raises(ValueError, match="not separately identifiable"):
        sj.fit((c, F), model, free=("EI_mother", "EI_daughter", "force_scale"), fixed={})
    # one group free and the other fixed is not degenerate: accepted up to the data check
    problem = sj.fit_problem((c, F), model, free=("EI_mother", "force_scale"), fixed={"EI_daughter": 0.07})
    assert problem.free == ("EI_mother", "force_scale")


@pytest.mark.slow
def test_correlated_parameters_are_reported_not_identifiable():
    """Contact offset and EI on a flat post-buckling plateau: shifting the contact point and
    changing EI are nearly the same change of the curve → flagged, with a warning."""
    model = ColumnModel(4, supports=("pinned", "pinned"), dim=2)
    c = np.linspace(0.25, 0.3, 8)  # a short piece of the plateau only
    F = _synthetic(model, {"EI": 0.071}, c, seed=5, noise=0.0, displacement=0.35)
    result = sj.fit((c, F), model, free=("EI", "baseline"), initial={"EI": 0.06}, settings=sj.FitSettings(max_iterations=10))
    assert not result.identifiable and any("correlated" in w for w in result.warnings)


@pytest.mark.slow
def test_fit_result_json_round_trip(tmp_path):
    model = ColumnModel(3, supports=("pinned", "pinned"), dim=2)
    c = np.linspace(0.02, 0.2, 6)
    F = _synthetic(model, {"EI": 0.071}, c, seed=0)
    result = sj.fit((c, F), model, free="EI", initial={"EI": 0.06})
    path = tmp_path / "fit.json"
    result.save(path)
    data = json.loads(path.read_text())
    assert data["values"]["EI"] == pytest.approx(result.values["EI"])
    assert data["units"]["EI"] == "pN·µm²" and len(data["residuals"]) == c.size
    assert [p.name for p in tmp_path.iterdir()] == ["fit.json"]  # no temporary left behind


def test_bad_input_is_refused_with_clear_messages():
    c, F = np.linspace(0.01, 0.2, 6), np.linspace(1, 2, 6)
    with pytest.raises(ValueError, match="unknown parameter 'stiffness'"):
        sj.fit((c, F), "column", model_options={"dim": 2}, free=("stiffness",))
    with pytest.raises(ValueError, match="both free and fixed"):
        sj.fit((c, F), "column", model_options={"dim": 2}, free=("EI",), fixed={"EI": 0.1})
    with pytest.raises(ValueError, match="NaN"):
        sj.fit((c, np.where(c > 0.1, np.nan, F)), "column", model_options={"dim": 2})
    with pytest.raises(ValueError, match="at least 3"):
        sj.fit((c[:2], F[:2]), "column", model_options={"dim": 2})
    with pytest.raises(ValueError, match="non-decreasing"):
        sj.fit((c[::-1], F), "column", model_options={"dim": 2})
    with pytest.raises(ValueError, match="never passes the contact"):
        sj.fit((-c[::-1], F), "column", model_options={"dim": 2})
    with pytest.raises(ValueError, match="crop the curve"):
        sj.fit((c * 10, F), "column", model_options={"dim": 2})
    with pytest.raises(ValueError, match="outside its bounds"):
        sj.fit((c, F), "unit-mesh", model_options={"dim": 2}, free=("branch_angle",), initial={"branch_angle": 95.0})
    with pytest.raises(ValueError, match="optimizer"):
        sj.fit((c, F), "column", model_options={"dim": 2}, settings=sj.FitSettings(optimizer="newton"))
    with pytest.raises(ValueError, match="unknown model"):
        sj.fit((c, F), "spring")
    with pytest.raises(ValueError, match="no parameter"):
        UnitMeshModel(dim=2).network({"EI_gen3": 1.0})


@pytest.mark.slow
def test_unloading_branch_fit():
    """The retract/unloading branch: a reversible column curve gives the same EI."""
    model = ColumnModel(4, supports=("pinned", "pinned"), dim=2)
    c = np.linspace(0.02, 0.2, 6)
    F = _synthetic(model, {"EI": 0.08}, c, seed=1, noise=0.0)
    result = sj.fit((c, F), model, free="EI", initial={"EI": 0.05}, settings=sj.FitSettings(branch="unloading"))
    assert result.values["EI"] == pytest.approx(0.08, rel=1e-5)
    with pytest.raises(ValueError, match="branch"):
        sj.fit((c, F), model, settings=sj.FitSettings(branch="retract"))


def test_a_fit_that_explains_nothing_is_not_converged():
    """Data in the wrong units (forces 1e12× the model's, as if N were read as pN): the
    optimiser cannot reduce the loss; the fit must say so (not converged, R² ≤ 0, a
    RESULTS item other than successful), never report success with unmoved parameters."""
    model = ColumnModel(3, supports=("pinned", "pinned"), dim=2)
    c = np.linspace(0.02, 0.2, 6)
    F = _synthetic(model, {"EI": 0.071}, c, seed=0, noise=0.0) * 1e12
    result = sj.fit((c, F), model, free="EI", initial={"EI": 0.06}, settings=sj.FitSettings(max_iterations=5))
    assert result.converged is False and result.result in (sj.RESULTS.poor_fit, sj.RESULTS.did_not_move)
    assert result.to_dict()["converged"] is False and result.to_dict()["result"] == "poor_fit"
    assert result.r_squared <= 0 and result.warnings and "R²" in result.message


def test_a_curve_beyond_the_model_names_cause_and_python_fixes():
    """Past the probe–surface gap (checked before any solve): a ValueError subclass naming the
    gap, a model size that reaches and a crop, in this API's spelling."""
    c, F = np.linspace(0.01, 2.0, 8), np.linspace(1.0, 2.0, 8)
    with pytest.raises(ValueError) as err:
        sj.fit((c, F), "unit-mesh", model_options={"dim": 2})
    text = str(err.value)
    assert err.value.cause == "gap" and "probe–surface gap" in text
    assert "model_options={'mother_length': 6.8}" in text and "curve.select(max_compression=0.27)" in text
    assert "--" not in text  # no command-line option
    with pytest.raises(ValueError, match=r"model_options=\{'length': 5.8\}"):
        sj.fit((c, F), "column", model_options={"dim": 2})


@pytest.mark.slow
def test_surface_crossing_inside_the_data_is_diagnosed():
    """Data to 0.6 µm on the 1-µm unit mesh (70°): its nodes cross the surface at ≈ 0.43 µm,
    before the data end — refused at the start, naming the crossing and the fixes (not
    "use method='arclength'", which would cross the surface too)."""
    c = np.linspace(0.01, 0.6, 12)
    with pytest.raises(ValueError) as err:
        sj.fit((c, np.ones(12)), "unit-mesh", model_options={"dim": 2})
    assert err.value.cause == "surface" and 0.4 < err.value.limit < 0.46
    assert "cross the surface" in str(err.value) and "arclength" not in str(err.value)
    assert "model_options={'mother_length': 2}" in str(err.value)


def test_free_force_scale_starts_at_its_least_squares_value():
    """With EI fixed 50 × too soft and force_scale free, the start is scaled to the data's
    force level: the force is exactly proportional to force_scale, so the least-squares value
    is Σ F f / Σ f² (f the model at the fixed EI), reached already by the start — one
    Levenberg–Marquardt iteration from the default 1 (log-transformed) could not get there."""
    model = ColumnModel(4, supports=("pinned", "pinned"), dim=2)
    c = np.linspace(0.02, 0.3, 12)
    F = _synthetic(model, {"EI": 0.071}, c, seed=3)
    f0 = np.asarray(sj.compress(model.network({"EI": 0.071 / 50}), 0.3, at=c).force)
    best = float(F @ f0) / float(f0 @ f0)
    result = sj.fit((c, F), model, free="force_scale", fixed={"EI": 0.071 / 50},
                    settings=sj.FitSettings(max_iterations=1))
    assert best == pytest.approx(50.0, rel=0.05)
    assert result.values["force_scale"] == pytest.approx(best, rel=1e-6)


def test_step_below_a_fraction_of_the_standard_errors_stops_at_the_tight_optimum():
    """FitSettings.se_tolerance: the default fit stops when a step moves every parameter by
    < 2 % of its standard error; its values agree with a fit run to a 1e-12 relative loss
    change without that criterion to within 5 % of a standard error."""
    model = ColumnModel(5, supports=("pinned", "pinned"), dim=2)
    c = np.linspace(0.02, 0.4, 20)
    F = _synthetic(model, {"EI": 0.071, "perturbation": 0.1}, c, seed=3, noise=0.02, displacement=0.4)
    kwargs = dict(free=("EI", "baseline"), initial={"EI": 0.05}, fixed={"perturbation": 0.1})
    loose = sj.fit((c, F), model, **kwargs)
    tight = sj.fit((c, F), model, **kwargs, settings=sj.FitSettings(se_tolerance=0.0, tolerance=1e-12))
    assert loose.converged and tight.converged, (loose.summary(), tight.summary())
    for name in ("EI", "baseline"):
        assert abs(loose.values[name] - tight.values[name]) <= 0.05 * tight.standard_errors[name]
    assert loose.n_evaluations <= tight.n_evaluations
    with pytest.raises(ValueError, match="se_tolerance"):
        sj.FitSettings(se_tolerance=-1.0)


class _CountingColumn(ColumnModel):
    """A column that records how many distinct probe travels each evaluation asks for (the
    list is padded by repeating its last travel, so that curves share a compiled program)."""

    def probe_force(self, values, u, **kwargs):
        self.asked.append(int(np.unique(np.asarray(u)).size))
        return super().probe_force(values, u, **kwargs)


def test_points_before_contact_at_every_allowed_shift_cost_no_equilibria():
    """A long approach (31 of 41 points before contact): the points that lie before contact at
    every contact point the bounds allow are not sent to the model, and the residuals equal
    model.predict's over all points (which solves every one)."""
    model = _CountingColumn(4, supports=("pinned", "pinned"), dim=2)
    model.asked = []
    c = np.linspace(-0.6, 0.2, 41)
    F = _synthetic(model, {"EI": 0.071}, c - 0.01, seed=5)
    problem = sj.fit_problem((c, F), model, free=("EI", "contact_point", "baseline"))
    z = problem.z0 + 0.01
    values = problem.to_values(z)
    reference = np.asarray(model.predict(values, c, reach=problem.reach)) - F
    assert model.asked[-1] == c.size
    r = np.asarray(problem.residuals(z))
    lower = problem.table["contact_point"].lower  # −0.1 × the largest compression by default
    assert model.asked[-1] == int(np.sum(c - lower > 0)) < c.size // 2
    np.testing.assert_allclose(r, reference, rtol=1e-9, atol=1e-9 * np.abs(F).max())
    open_bounds = sj.fit_problem((c, F), model, free=("EI", "contact_point", "baseline"),
                                 bounds={"contact_point": (None, None)})
    z_open = np.array([open_bounds.table[n].to_z(float(values[n])) for n in open_bounds.free])  # the same values
    np.testing.assert_allclose(np.asarray(open_bounds.residuals(z_open)), reference, rtol=1e-9,
                               atol=1e-9 * np.abs(F).max())
    assert model.asked[-1] == c.size


def test_contact_point_start_ignores_a_noise_spike_in_the_baseline():
    """The start of a free contact point is where the force leaves the baseline and stays
    out: one baseline point pushed 6 noise levels up (a spike, not contact) does not move it
    there, and the fit recovers the contact point within a point spacing."""
    model = ColumnModel(4, supports=("pinned", "pinned"), dim=2)
    c = np.linspace(-0.06, 0.2, 60)
    truth = 0.05
    F = _synthetic(model, {"EI": 0.071}, c - truth, seed=2, noise=0.0)
    rng = np.random.default_rng(2)
    sigma = 0.01 * F.max()
    F = F + sigma * rng.standard_normal(c.size)
    spike = 5  # c = −0.038 µm
    F[spike] += 6 * sigma
    problem = sj.fit_problem((c, F), model, free=("EI", "contact_point", "baseline"))
    spacing = c[1] - c[0]
    assert abs(float(problem.to_values(problem.z0)["contact_point"]) - truth) <= spacing
    result = sj.fit((c, F), model, free=("EI", "contact_point", "baseline"))
    assert abs(result.values["contact_point"] - truth) <= spacing
    assert result.values["EI"] == pytest.approx(0.071, rel=0.02)


def test_the_cropped_approach_enters_the_noise_estimate():
    """A measured curve's approach reaches far before the fitted window (−¼ of the largest
    compression): the cropped points are kept in ``FitProblem.baseline``, averaged in bins of
    the fitted points' width (4 raw points each here), so their noise is that of a fitted
    point (σ/2), and the fit's noise estimate uses them (ν grows from ~1 to ~30); arrays
    cropped by ``min_compression`` keep their raw cropped points."""
    model = ColumnModel(4, supports=("pinned", "pinned"), dim=2)
    c = np.round(np.arange(-1.0, 0.2 + 1e-9, 0.0025), 10)  # µm, raw spacing 2.5 nm
    sigma = 0.05  # pN per raw point
    clean = np.zeros(c.size)
    touch = c > 0
    clean[touch] = _synthetic(model, {"EI": 0.071}, c[touch], seed=0, noise=0.0)
    F = clean + sigma * np.random.default_rng(3).standard_normal(c.size)
    curve = sj.ForceCurve(c, F)
    problem = sj.fit_problem(curve, model, free=("EI",), max_points=25)
    window = curve.select(min_compression=-0.05)
    width = (window.compression.max() - window.compression.min()) / 25
    base = problem.data.baseline
    assert isinstance(base, sj.ApproachBaseline) and not base.retract.any()
    assert base.compression.max() < -0.05 and base.compression.min() < -0.9
    assert np.mean(np.diff(base.compression)) == pytest.approx(width, rel=0.01)
    n = base.force.size
    assert sj.estimate_noise(base.force) == pytest.approx(sigma / 2, rel=3 / np.sqrt(2 * 0.3 * n))
    result = sj.fit(curve, model, free=("EI", "contact_point"), settings=sj.FitSettings(max_points=25))
    in_window = int(np.sum(problem.compression < 0))
    assert result.goodness["n_baseline"] == n + in_window and in_window < 8 < n
    assert result.noise_source == "baseline"
    assert result.noise == pytest.approx(sigma / 2, rel=3 / np.sqrt(2 * 0.3 * n))
    assert result.values["EI"] == pytest.approx(0.071, rel=0.02) and not result.misfit
    assert abs(result.values["contact_point"]) < 0.0025  # the raw spacing
    arrays = sj.fit_problem((c, F), model, free=("EI",), min_compression=-0.05)
    np.testing.assert_array_equal(arrays.data.baseline.force, F[c < -0.05])
    assert sj.fit_problem((c[c >= -0.05], F[c >= -0.05]), model, free=("EI",)).data.baseline is None


def test_bins_of_an_unevenly_sampled_curve_are_the_cells_of_their_raw_points():
    """A simulated curve's adaptive steps grow from nanometres at contact: each bin stands for
    the cells of its raw points (half-way to each neighbour), so the bins tile the curve
    without gaps or overlaps and the first starts half a first step before its first point.
    (With the median spacing a tenth of the first bin lay before contact, where the model's
    force is 0: a simulated column's EI came out 1 % off, R² 0.26.)"""
    c = np.geomspace(1e-6, 0.2, 40)
    curve = sj.ForceCurve(c, 10.0 + c)
    data = sj.fit_problem(curve, ColumnModel(4, dim=2), free=("EI",), max_points=12).data
    cells = np.concatenate([[1.5 * c[0] - 0.5 * c[1]], 0.5 * (c[1:] + c[:-1]), [1.5 * c[-1] - 0.5 * c[-2]]])
    assert 3 <= data.low.size <= 12 and data.low[0] == pytest.approx(cells[0], abs=1e-15)
    np.testing.assert_allclose(data.low[1:], data.high[:-1], rtol=1e-12)  # contiguous
    assert data.high[-1] == pytest.approx(cells[-1], rel=1e-12)
    assert np.all(np.isin(np.round(data.low, 12), np.round(cells, 12)))  # every edge between raw points


def test_a_binned_point_astride_contact_is_the_mean_over_its_bin():
    """The force of inextensible filaments jumps at contact, so the bin that holds the contact
    point averages raw points at zero force and in contact: the residuals compare each binned
    point with the model's mean over its bin's raw points (reference: the model at every raw
    point, binned like the data).  That mean is a staircase in the contact point (a step per
    raw point crossing), which the residuals follow linearly: exact (1 % of the jump) with
    contact midway between raw points, within half a step (jump / 2k, k = 4 raw points per
    bin) elsewhere; the model at the bin's mean compression is off by a fifth of the jump."""
    model = ColumnModel(4, supports=("pinned", "pinned"), dim=2)
    c = np.round(np.arange(-0.05, 0.2 + 1e-9, 0.0025), 10)  # µm, 101 raw points, 4 per bin
    F = np.zeros(c.size)  # the data do not matter: residuals plus data are the model's bin means
    problem = sj.fit_problem(sj.ForceCurve(c, F), model, free=("EI", "contact_point"), max_points=25)
    for contact, tolerance in ((0.00375, 0.01), (0.00375 + 0.0008, 0.125)):  # a raw midpoint, and not
        values = {"EI": 0.071, "contact_point": contact}
        z = np.array([problem.table[n].to_z(values[n]) for n in problem.free])
        binned_model = np.asarray(problem.residuals(z)) + problem.force
        raw = np.asarray(model.predict(values, c, reach=problem.reach))
        reference = sj.ForceCurve(c, raw).binned(25).force
        np.testing.assert_allclose(binned_model, reference, atol=tolerance * raw.max())
    at_means = np.asarray(model.predict(values, problem.compression, reach=problem.reach))
    assert np.max(np.abs(at_means - reference)) > 0.2 * raw.max()
