"""FitModel.predict (every fit model): the force a model predicts for a curve, with the curve's
own terms, against socbjax.compress directly; contact_point ≡ −contact_offset; fits of both
branches with the hysteresis; the data-driven start of a free contact point."""

import jax
import numpy as np
import pytest

import socbjax as sj


@pytest.fixture(scope="module")
def column():
    return sj.ColumnModel(4, supports=("pinned", "pinned"), dim=2)


C = np.linspace(-0.05, 0.2, 11)


def test_predict_is_compress_plus_curve_terms(column):
    values = {"EI": 0.09, "contact_point": 0.03, "baseline": 0.4, "baseline_tilt": -1.5, "force_scale": 2.0}
    F = np.asarray(column.predict(values, C, reach=0.25))
    u = C - 0.03
    direct = sj.compress(column.network({"EI": 0.09}), 0.25, at=np.clip(u, 0.25e-6, None)).force
    expected = 2.0 * np.where(u > 0, np.asarray(direct), 0.0) + 0.4 - 1.5 * C
    np.testing.assert_allclose(F, expected, rtol=1e-8, atol=1e-10)
    offset = np.asarray(column.predict({**values, "contact_point": 0.0, "contact_offset": -0.03}, C, reach=0.25))
    np.testing.assert_allclose(offset, F, rtol=1e-12)
    with pytest.raises(ValueError, match="no parameter"):
        column.predict({"stiffness": 1.0}, C)
    with pytest.raises(ValueError, match="branch"):
        column.predict({}, C, branch="retract")


def test_predict_is_differentiable(column):
    def f(EI, cp):
        return column.predict({"EI": EI, "contact_point": cp}, C, reach=0.25)[-1]

    g = jax.grad(f, argnums=(0, 1))(0.08, 0.01)
    h = 1e-6
    np.testing.assert_allclose(float(g[0]), float((f(0.08 + h, 0.01) - f(0.08 - h, 0.01)) / (2 * h)), rtol=1e-6)
    np.testing.assert_allclose(float(g[1]), float((f(0.08, 0.01 + h) - f(0.08, 0.01 - h)) / (2 * h)), rtol=1e-5)


def test_both_branch_residuals_vanish_at_the_truth(column):
    """branch="both": approach points first, then retract points, each on its own branch of
    one path; the residuals of a curve made by the model vanish at its values only."""
    c = np.linspace(-0.05, 0.2, 11)
    up = np.asarray(column.predict({"EI": 0.1}, c))
    down = np.asarray(column.predict({"EI": 0.1}, c, branch="unloading"))
    curve = sj.ForceCurve(np.r_[c, c[::-1]], np.r_[up, down[::-1]], np.r_[np.zeros(11), np.ones(11)].astype(np.int8))
    problem = sj.fit_problem(curve, column, free=("EI",), initial={"EI": 0.1}, branch="both")
    assert problem.retract.tolist() == [False] * 11 + [True] * 11
    assert np.abs(np.asarray(problem.residuals(problem.z0))).max() < 1e-6 * up.max()
    with pytest.raises(ValueError, match="needs a socbjax.ForceCurve"):
        sj.fit((c, up), column, settings=sj.FitSettings(branch="both"))


@pytest.mark.slow  # 30 s; the default suite checks the both-branch residuals at the truth
def test_both_branches_fit_and_hysteresis(column):
    """A pinned–pinned column is elastic: approach and retract coincide (no hysteresis); a fit
    of both branches recovers EI and reports data and model hysteresis ≈ 0."""
    c = np.linspace(-0.05, 0.2, 11)
    up = np.asarray(column.predict({"EI": 0.1}, c))
    down = np.asarray(column.predict({"EI": 0.1}, c, branch="unloading"))
    np.testing.assert_allclose(up, down, rtol=1e-6, atol=1e-9)
    curve = sj.ForceCurve(np.r_[c, c[::-1]], np.r_[up, down[::-1]], np.r_[np.zeros(11), np.ones(11)].astype(np.int8))
    result = sj.fit(curve, column, free=("EI",), initial={"EI": 0.07}, settings=sj.FitSettings(branch="both"))
    assert result.converged and abs(result.values["EI"] / 0.1 - 1) < 1e-6
    assert result.compression.size == 22
    assert abs(result.goodness["hysteresis_data"]) < 1e-6 and abs(result.goodness["hysteresis_model"]) < 1e-6
    with pytest.raises(ValueError, match="needs a socbjax.ForceCurve"):
        sj.fit((c, up), column, settings=sj.FitSettings(branch="both"))


@pytest.mark.slow  # 26 s; the default suite checks predict's contact shift
def test_contact_point_start_and_recovery(column):
    """Data shifted by 0.05 µm: the free contact point starts where the force leaves the
    baseline and the fit recovers the shift and EI.  The force of an inextensible column
    jumps to its plateau within 1e-4 µm of contact, so the data fix the contact only between
    the two points around the jump (one spacing, 0.01 µm), and EI to the plateau's slope
    times that (< 1 %)."""
    c = np.linspace(-0.1, 0.2, 31)
    F = np.asarray(column.predict({"EI": 0.1, "contact_point": 0.05}, c))
    problem = sj.fit_problem((c, F), column, free=("EI", "contact_point"))
    start = float(problem.to_values(problem.z0)["contact_point"])
    assert 0.04 <= start <= 0.06
    result = sj.fit((c, F), column, free=("EI", "contact_point"))
    assert abs(result.values["contact_point"] - 0.045) <= 0.0051 and abs(result.values["EI"] / 0.1 - 1) < 0.01
    with pytest.raises(ValueError, match="same shift"):
        sj.fit((c, F), column, free=("EI", "contact_point", "contact_offset"))
