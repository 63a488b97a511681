"""Goodness of fit without fitting a model (numpy only, fast): the runs test against its exact
distribution and hand-computed values, the noise estimator on sloped baselines, χ²_red of a
correctly specified linear fit, the misfit verdict, and AIC/BIC of nested polynomial fits."""

import itertools
import math

import numpy as np
import pytest

import socbjax as sj


def test_runs_test_hand_computed_examples():
    """n₊ = n₋ = 3 (C(6,3) = 20 orders): P(R=2) = 2/20, P(R=3) = 4/20, P(R=4) = 8/20;
    E[R] = 2·3·3/6 + 1 = 4, Var R = 2·9·(18 − 6)/(36·5) = 1.2."""
    t = sj.runs_test([1.0, 2.0, 0.5, -1.0, -3.0, -0.1])
    assert (t.runs, t.n_positive, t.n_negative) == (2, 3, 3)
    assert t.expected == pytest.approx(4.0) and t.variance == pytest.approx(1.2)
    assert t.z == pytest.approx(-2.0 / math.sqrt(1.2)) and t.p_value == pytest.approx(0.1)
    assert sj.runs_test([1, 1, -1, 1, -1, -1]).p_value == pytest.approx(14 / 20)  # 4 runs: (2 + 4 + 8)/20
    assert sj.runs_test([1, -1, 1, -1, 1, -1]).p_value == pytest.approx(1.0)
    assert sj.runs_test([1, 0, 1, 0, -1, -1, -1]).runs == 2  # zeros are dropped
    assert sj.runs_test([1, 1, 1, -1]).p_value == 1.0  # one sign with < 2 points: no test


def test_runs_test_matches_its_enumerated_distribution():
    """Every order of 7 positive and 5 negative signs (792): the mean and variance of the
    number of runs are the textbook 2n₁n₂/n + 1 and 2n₁n₂(2n₁n₂ − n)/(n²(n − 1)), and
    ``p_value`` is the enumerated P(R ≤ r)."""
    n1, n2 = 7, 5
    runs, p = [], {}
    for where in itertools.combinations(range(n1 + n2), n2):
        signs = np.ones(n1 + n2)
        signs[list(where)] = -1
        t = sj.runs_test(signs)
        runs.append(t.runs)
        p[t.runs] = t.p_value
    runs = np.array(runs)
    n = n1 + n2
    assert runs.mean() == pytest.approx(2 * n1 * n2 / n + 1, rel=1e-12)
    assert runs.var() == pytest.approx(2 * n1 * n2 * (2 * n1 * n2 - n) / (n**2 * (n - 1)), rel=1e-12)
    for r, value in p.items():
        assert value == pytest.approx(np.mean(runs <= r), rel=1e-12)


def test_runs_test_false_alarms_on_white_noise():
    """Independent signs: P(p < α) ≤ α (the exact test is conservative by discreteness)."""
    rng = np.random.default_rng(1)
    p = np.array([sj.runs_test(rng.standard_normal(50)).p_value for _ in range(3000)])
    assert np.mean(p < 0.05) <= 0.05 + 3 * math.sqrt(0.05 * 0.95 / 3000)
    assert np.mean(p < 0.05) >= 0.02  # and it is a test at all


def test_noise_estimate_is_blind_to_baseline_offset_and_slope():
    """A linear baseline shifts every first difference equally: the MAD estimate is unchanged
    (exactly, on evenly spaced points)."""
    rng = np.random.default_rng(2)
    noise = 0.3 * rng.standard_normal(40)
    c = np.linspace(-0.2, 0.0, 40)
    tilted = noise + 12.0 + 500.0 * c  # slope 500 pN/µm: 85 pN over the baseline, 280× the noise
    assert sj.estimate_noise(tilted) == pytest.approx(sj.estimate_noise(noise), rel=1e-9, abs=1e-12)
    assert math.isnan(sj.estimate_noise([1.0, 2.0]))


@pytest.mark.parametrize("n", [16, 200])
def test_noise_estimate_recovers_sigma_on_a_sloped_baseline(n):
    """σ = 0.25 pN on a sloped, curved baseline: the estimate averaged over 400 baselines of n
    points is within 4 % (n = 16; its small-sample bias is −1 %) or 1 % (n = 200) of σ, and a
    single long baseline within 3 of its standard errors (Var σ̂² = 2σ⁴/ν, ν ≈ 0.3 (n − 1))."""
    rng = np.random.default_rng(3)
    c = np.linspace(-0.3, 0.0, n)
    drift = 4.0 - 20.0 * c + 30.0 * c**2
    estimates = np.array([sj.estimate_noise(drift + 0.25 * rng.standard_normal(n)) for _ in range(400)])
    assert estimates.mean() == pytest.approx(0.25, rel=0.04 if n == 16 else 0.01)
    if n == 200:
        relative_se = 1.0 / math.sqrt(2 * 0.3 * (n - 1))
        assert np.all(np.abs(estimates / 0.25 - 1.0) < 4.5 * relative_se)
        assert np.std(estimates / 0.25) == pytest.approx(relative_se, rel=0.2)


def _linear_fit(c, y, degree=1, mask=None):
    mask = np.ones(c.size, bool) if mask is None else mask
    coefficients = np.polyfit(c[mask], y[mask], degree)
    return np.polyval(coefficients, c)


def _line_curve(seed, sigma=0.2, m=80):
    """A 'force curve' whose model is known: zero before contact, 2 + 30 c after; noise σ."""
    rng = np.random.default_rng(seed)
    c = np.linspace(-0.1, 0.3, m)
    clean = np.where(c > 0, 2.0 + 30.0 * c, 0.0)
    return c, clean, clean + sigma * rng.standard_normal(m)


def _line_model(c, y):
    """Least squares of the correct 2-parameter model: 0 before contact, a + b c after."""
    fitted = np.zeros_like(y)
    fitted[c > 0] = _linear_fit(c, y, 1, c > 0)[c > 0]
    return fitted


def test_chi2_reduced_is_one_for_a_correctly_specified_fit():
    """With the true σ given (no baseline points): χ²_red within 4 of its standard errors
    √(2/(m − p)) of 1 on every seed, and its mean over 200 seeds within 3 standard errors; no
    misfit flagged (the false-alarm rate is at most a few in 1000)."""
    chi2, misfits = [], 0
    for seed in range(200):
        c, _, y = _line_curve(seed)
        g = sj.goodness_of_fit(c, y, _line_model(c, y), 2, sigma=0.2, baseline=np.zeros(c.size, bool))
        assert g.noise_source == "sigma" and g.noise == pytest.approx(0.2) and g.dof == c.size - 2
        assert abs(g.chi2_reduced - 1.0) < 4 * math.sqrt(2 / g.dof)
        chi2.append(g.chi2_reduced)
        misfits += g.misfit
    assert np.mean(chi2) == pytest.approx(1.0, abs=3 * math.sqrt(2 / 78 / 200))
    assert misfits <= 2


def test_baseline_noise_and_its_fallbacks():
    c, _, y = _line_curve(7, sigma=0.2, m=160)  # 40 points before contact
    fitted = _line_model(c, y)
    g = sj.goodness_of_fit(c, y, fitted, 2)
    assert g.noise_source == "baseline" and g.n_baseline == 40
    assert g.noise == pytest.approx(sj.estimate_noise(y[c < 0]))
    assert g.noise == pytest.approx(0.2, rel=3 / math.sqrt(2 * 0.3 * 39))
    assert math.isfinite(g.chi2_p) and not g.misfit and not g.notes
    # fewer than 8 points before contact: the given sigma, else the residuals (χ² no test)
    few = c > -0.012
    g = sj.goodness_of_fit(c[few], y[few], fitted[few], 2, sigma=0.2)
    assert g.noise_source == "sigma" and g.n_baseline < 8
    g = sj.goodness_of_fit(c[few], y[few], fitted[few], 2)
    assert g.noise_source == "residuals" and math.isnan(g.chi2_p)
    assert g.noise == pytest.approx(0.2, rel=0.3)
    assert any("χ² is not a test" in note for note in g.notes)


def _bent_line(seed, bend, n_extra, sigma=0.2):
    """Goodness of a line fitted to a line with a wiggle of amplitude ``bend`` (pN) in
    contact (60 of 80 points), with ``n_extra`` cropped approach points of the same noise."""
    rng = np.random.default_rng(seed)
    c = np.linspace(-0.1, 0.3, 80)
    y = np.where(c > 0, 2.0 + 30.0 * c + bend * np.sin(c / 0.3 * 6 * np.pi), 0.0) + sigma * rng.standard_normal(c.size)
    extra = (sigma * rng.standard_normal(n_extra), np.zeros(n_extra)) if n_extra else None
    return sj.goodness_of_fit(c, y, _line_model(c, y), 2, extra_baseline=extra)


def test_cropped_approach_joins_the_noise_estimate():
    """The approach cropped before the fitted window (``extra_baseline``) joins the baseline:
    400 more points make σ̂ 4.6 × more precise, and χ² a test with power: a wiggle of twice
    the noise's amplitude is caught by χ² in ≥ 80 of 100 seeds (measured 91) where the 20
    in-window baseline points catch it in ≤ 5 (measured 0); no more false alarms (≤ 2 in 200)
    on the correct model."""
    g = _bent_line(3, 0.0, 400)
    assert g.noise_source == "baseline" and g.n_baseline == 420
    assert g.noise_dof == pytest.approx(0.3 * 419)
    assert g.noise == pytest.approx(0.2, rel=3 / math.sqrt(2 * 0.3 * 419))
    caught = {n: sum(_bent_line(seed, 0.4, n).chi2_p < 1e-3 for seed in range(100)) for n in (0, 400)}
    assert caught[400] >= 80 and caught[0] <= 5
    assert sum(_bent_line(seed, 0.0, 400).misfit for seed in range(200)) <= 2
    # differences never span the crop: a baseline offset between the two parts changes nothing
    rng = np.random.default_rng(5)
    c, _, y = _line_curve(5)
    extra = (0.2 * rng.standard_normal(400), np.zeros(400))
    shifted = (extra[0] + 50.0, extra[1])
    a, b = (sj.goodness_of_fit(c, y, _line_model(c, y), 2, extra_baseline=e) for e in (extra, shifted))
    assert a.noise == pytest.approx(b.noise, rel=1e-12)


def test_structured_residuals_are_a_misfit():
    """A straight line fitted to a curve with a bend: few long runs, positive autocorrelation,
    and a too large χ²: flagged, with the evidence in the warning."""
    rng = np.random.default_rng(4)
    c = np.linspace(-0.1, 0.3, 100)
    y = np.where(c > 0, 2.0 + 3.0 * np.sin(12 * c), 0.0) + 0.1 * rng.standard_normal(c.size)
    g = sj.goodness_of_fit(c, y, _linear_fit(c, y, 1, c > 0) * (c > 0), 2)
    assert g.misfit and g.runs.p_value < 1e-6 and g.autocorrelation > 0.5 and g.chi2_p < 1e-3
    text = g.warning()
    assert text.startswith("the model misfits the data systematically: ")
    assert "runs test z = " in text and "autocorrelation" in text and "χ²_red" in text
    assert sj.goodness_of_fit(c, y, y, 2).warning() is None  # exact residuals: nothing to test


def test_aic_bic_formulas_and_nested_polynomials():
    """Truth: a quadratic with 1 % noise.  AIC and BIC follow m ln(RSS/m) + 2p and + p ln m;
    both always reject the line (p = 2); against the cubic (p = 4, one parameter too many) AIC
    keeps the true quadratic in about 84 % of noise draws (P(χ²₁ < 2)) and BIC more often."""
    rng = np.random.default_rng(5)
    c = np.linspace(0.0, 1.0, 60)
    aic_picks, bic_picks = [], []
    for _ in range(300):
        y = 1.0 + 2.0 * c - 1.5 * c**2 + 0.01 * rng.standard_normal(c.size)
        scores = {}
        for degree in (1, 2, 3):
            r = _linear_fit(c, y, degree) - y
            rss, p = float(r @ r), degree + 1
            aic, bic = sj.information_criteria(rss, c.size, p)
            assert aic == pytest.approx(c.size * math.log(rss / c.size) + 2 * p)
            assert bic == pytest.approx(c.size * math.log(rss / c.size) + p * math.log(c.size))
            g = sj.goodness_of_fit(c, y, y + r, p, sigma=0.01)
            assert (g.aic, g.bic) == pytest.approx((c.size * math.log(float((r / 0.01) @ (r / 0.01)) / c.size) + 2 * p,
                                                    c.size * math.log(float((r / 0.01) @ (r / 0.01)) / c.size)
                                                    + p * math.log(c.size)))
            scores[degree] = (aic, bic)
        assert scores[2][0] < scores[1][0] and scores[2][1] < scores[1][1]
        aic_picks.append(min(scores, key=lambda d: scores[d][0]))
        bic_picks.append(min(scores, key=lambda d: scores[d][1]))
    assert np.mean(np.array(aic_picks) == 2) == pytest.approx(0.843, abs=0.07)
    assert np.mean(np.array(bic_picks) == 2) > np.mean(np.array(aic_picks) == 2)
