"""AFM force-curve input (socbjax._afm): synthetic curves with a known contact point, baseline,
spring constant and force law; unit conversions; the real afmformats test files; bad input."""

import os
import sys

import numpy as np
import pytest

import socbjax
from socbjax import ForceCurve, load_curve, save_curve

DATA = socbjax.example_file("force-save-example.jpk-force").parent
K = 0.05  # N/m
C0 = 1.0  # contact tip position, µm
SPACING = 0.005  # µm between tip positions (JPK-like)
NOISE = 5.0  # pN
SLOPE, OFFSET = 40.0, -600.0  # baseline pN/µm of height, pN


def hertz(delta):
    return 2.0e4 * np.clip(delta, 0.0, None) ** 1.5  # pN, δ in µm


def linear(delta):
    return 5.0e3 * np.clip(delta, 0.0, None)


def synthetic(law=hertz, seed=0, retract=False, noise=NOISE):
    """Tip positions from C0 + 3 µm to C0 − 0.5 µm (and back if ``retract``): true tip (µm),
    true force (pN), measured height (µm), raw force with baseline and noise (pN), segment."""
    rng = np.random.default_rng(seed)
    tip = np.arange(C0 + 3.0, C0 - 0.5, -SPACING)
    seg = np.zeros(len(tip), np.int8)
    if retract:
        tip, seg = np.concatenate([tip, tip[::-1]]), np.concatenate([seg, np.ones_like(seg)])
    f_true = law(C0 - tip)
    height = tip - f_true * 1e-6 / K
    f_raw = f_true + OFFSET + SLOPE * height + rng.normal(0.0, noise, len(tip))
    return tip, f_true, height, f_raw, seg


def write(path, header, *cols, delim=",", comments=()):
    lines = [f"# {c}" for c in comments] + [delim.join(header)]
    lines += [delim.join(repr(v) if isinstance(v, float) else str(v) for v in row) for row in zip(*cols, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    return path


def si_file(tmp_path, law=hertz, **kw):
    tip, f_true, height, f_raw, seg = synthetic(law, **kw)
    path = write(tmp_path / "curve.csv", ["height_m", "force_N", "segment"],
                 (height * 1e-6).tolist(), (f_raw * 1e-12).tolist(), seg.tolist())
    return path, tip, f_true


# ---------------------------------------------------------------- synthetic curves
@pytest.mark.parametrize("law", [hertz, linear])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_synthetic_contact_baseline_and_law(tmp_path, law, seed):
    path, tip, f_true = si_file(tmp_path, law, seed=seed)
    curve = load_curve(path, spring_constant=K)
    m = curve.metadata
    assert abs(m["contact_point_um"] - C0) <= 3 * SPACING
    assert m["noise_pN"] == pytest.approx(NOISE, rel=0.2)
    assert m["baseline_slope_pN_per_um"] == pytest.approx(SLOPE, abs=5.0)
    assert m["spring_constant_N_per_m"] == K and m["n_raw_points"] == len(tip)
    # baseline removed: force before contact is zero within noise
    pre = curve.force[curve.compression < -0.05]
    assert abs(pre.mean()) < 3 * NOISE / np.sqrt(len(pre)) + 1.0
    assert pre.std() == pytest.approx(NOISE, rel=0.2)
    # compression is the true compression shifted by the contact-point error (deflection-corrected)
    shift = curve.compression - (C0 - tip)
    assert np.ptp(shift) < 1e-3
    assert abs(shift.mean()) <= 3 * SPACING
    assert np.abs(curve.force - f_true).max() < 6 * NOISE
    assert curve.compression.max() == pytest.approx(0.5, abs=3 * SPACING)


def test_given_contact_point_recovers_law_exactly(tmp_path):
    path, tip, _ = si_file(tmp_path)
    curve = load_curve(path, spring_constant=K, contact_point=C0)
    np.testing.assert_allclose(curve.compression, C0 - tip, atol=1e-3)
    contact = curve.select(min_compression=0.05)
    resid = contact.force - hertz(contact.compression)
    assert np.abs(resid).max() < 6 * NOISE
    assert curve.metadata["steps"] == ["segment:approach", "baseline:linear", "contact_point:given"]


def test_without_deflection_correction_compression_would_be_wrong(tmp_path):
    """Guards the tip = height + F/k step: a 10x stiffer k moves deep points by > 0.1 µm."""
    path, tip, _ = si_file(tmp_path)
    soft = load_curve(path, spring_constant=K, contact_point=C0)
    stiff = load_curve(path, spring_constant=10 * K, contact_point=C0)
    assert np.abs(soft.compression - (C0 - tip)).max() < 1e-3
    assert np.abs(stiff.compression - (C0 - tip)).max() > 0.1


def test_constant_baseline_and_segments(tmp_path):
    tip, _, height, f_raw, seg = synthetic(retract=True)
    f_raw = f_raw - SLOPE * height  # leave a constant offset only
    path = write(tmp_path / "c.csv", ["tip_position_um", "force_pN", "segment"],
                 (height + (f_raw - OFFSET) * 1e-6 / K).tolist(), f_raw.tolist(),
                 ["approach" if s == 0 else "retract" for s in seg])
    both = load_curve(path, baseline="constant", segment="both")
    assert both.metadata["baseline_pN"] == pytest.approx(OFFSET, abs=2.0)
    assert len(both.approach) == len(both.retract) == len(tip) // 2
    assert (both.approach.segment == 0).all() and (both.retract.segment == 1).all()
    assert len(load_curve(path, segment="retract")) == len(tip) // 2
    assert abs(both.metadata["contact_point_um"] - C0) <= 3 * SPACING


def test_missing_segment_column_is_split_at_the_turning_point(tmp_path):
    _, _, height, f_raw, seg = synthetic(retract=True)
    path = write(tmp_path / "c.tsv", ["height_nm", "force_pN"], (height * 1e3).tolist(), f_raw.tolist(),
                 delim="\t")
    curve = load_curve(path, spring_constant=K, segment="both")
    assert abs(int((curve.segment == 1).sum()) - int(seg.sum())) <= 1
    assert "split" in curve.metadata["segments_from"]


# ---------------------------------------------------------------- units and formats
def test_unit_conversions(tmp_path):
    rng = np.random.default_rng(3)
    comp = np.linspace(-0.2, 1.0, 50)
    force = np.clip(comp, 0, None) * 800.0 + rng.normal(0, 2, 50)
    ref = load_curve(write(tmp_path / "a.csv", ["compression_um", "force_pN"], comp.tolist(), force.tolist()),
                     preprocess=False)
    for name, lu, fu in [("b", "nm", "nN"), ("c", "m", "N"), ("d", "µm", "pN")]:
        ls = {"nm": 1e3, "m": 1e-6, "µm": 1.0}[lu]
        fs = {"nN": 1e-3, "N": 1e-12, "pN": 1.0}[fu]
        other = load_curve(write(tmp_path / f"{name}.csv", [f"compression_{lu}", f"force_{fu}"],
                                 (comp * ls).tolist(), (force * fs).tolist()), preprocess=False)
        np.testing.assert_allclose(other.compression, ref.compression, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(other.force, ref.force, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ref.compression, comp)
    np.testing.assert_allclose(ref.force, force)


@pytest.mark.parametrize("delim,suffix", [(",", ".csv"), ("\t", ".tsv"), (";", ".csv"), ("  ", ".txt"),
                                          (" ", ".dat")])
def test_delimiters_and_comments(tmp_path, delim, suffix):
    comp, force = np.linspace(0, 1, 10), np.linspace(0, 90, 10)
    path = write(tmp_path / f"x{suffix}", ["compression_um", "force_pN", "time_s"], comp.tolist(),
                 force.tolist(), list(range(10)), delim=delim, comments=["exported by hand", "k = 0.02"])
    curve = load_curve(path)
    np.testing.assert_allclose(curve.compression, comp)
    np.testing.assert_allclose(curve.force, force)
    assert curve.metadata["format"] == "socbjax native text"


def test_columns_renames_header(tmp_path):
    path = write(tmp_path / "r.csv", ["Indentation (nm)", "F (nN)"], [0.0, 100.0, 200.0], [0.0, 0.5, 1.0])
    curve = load_curve(path, columns={"Indentation (nm)": "compression_nm", "F (nN)": "force_nN"})
    np.testing.assert_allclose(curve.compression, [0.0, 0.1, 0.2])
    np.testing.assert_allclose(curve.force, [0.0, 500.0, 1000.0])


# ---------------------------------------------------------------- ForceCurve
def test_binned_preserves_means_and_bin_count():
    rng = np.random.default_rng(0)
    comp = np.concatenate([np.sort(rng.uniform(-1, 2, 3000)), np.sort(rng.uniform(-1, 2, 1000))[::-1]])
    force = comp**2 + rng.normal(0, 0.1, 4000)
    seg = np.r_[np.zeros(3000), np.ones(1000)].astype(np.int8)
    curve = ForceCurve(comp, force, seg, {"source": "x"})
    b = curve.binned(100)
    counts = np.asarray(b.metadata["bin_counts"])
    for s, n in ((0, 3000), (1, 1000)):
        m = b.segment == s
        assert 90 <= m.sum() <= 100
        assert counts[m].sum() == n
        assert np.sum(counts[m] * b.force[m]) / n == pytest.approx(force[seg == s].mean(), rel=1e-12)
        assert np.sum(counts[m] * b.compression[m]) / n == pytest.approx(comp[seg == s].mean(), rel=1e-12)
    assert np.all(np.diff(b.approach.compression) > 0) and np.all(np.diff(b.retract.compression) < 0)
    assert b.compression.min() >= comp.min() and b.compression.max() <= comp.max()
    assert np.abs(b.force - b.compression**2).max() < 0.2  # bins are narrow (width 0.03)
    assert b.metadata["source"] == "x" and len(curve.approach.binned(7)) <= 7
    # each point's span: the first and last raw compression of its bin (bins of width 0.03)
    span = np.asarray(b.metadata["bin_span"])
    edges = np.linspace(comp.min(), comp.max(), 101)
    for (first, last), s, c in zip(span, b.segment, b.compression, strict=True):
        k = min(np.searchsorted(edges, c, side="right") - 1, 99)
        inside = comp[(seg == s) & (comp >= edges[k]) & ((comp < edges[k + 1]) | (k == 99))]
        assert (first, last) == (inside.min(), inside.max())
    with pytest.raises(ValueError, match="n_bins"):
        curve.binned(2)


def test_select_and_validation():
    curve = ForceCurve(np.linspace(-1, 1, 21), np.linspace(0, 1, 21))
    assert len(curve) == 21 and (curve.segment == 0).all()
    assert curve.select(min_compression=0).compression.min() >= 0
    assert len(curve.select(min_compression=0, max_compression=0.5)) == 6
    with pytest.raises(ValueError, match="at least 3"):
        curve.select(max_compression=-0.95)
    with pytest.raises(ValueError, match="retract"):
        _ = curve.retract
    with pytest.raises(ValueError, match=r"2 NaN.*1 in compression.*1 in force"):
        ForceCurve([0.0, np.nan, 1.0], [0.0, 1.0, np.nan])
    with pytest.raises(ValueError, match="length"):
        ForceCurve([0.0, 1.0, 2.0], [0.0, 1.0])
    with pytest.raises(ValueError, match="at least 3"):
        ForceCurve([0.0, 1.0], [0.0, 1.0])
    with pytest.raises(ValueError, match="segment"):
        ForceCurve([0.0, 1.0, 2.0], [0.0, 1.0, 2.0], [0, 1, 2])
    with pytest.raises(ValueError):
        curve.compression[0] = 5.0  # read-only


def test_save_curve_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    comp = np.r_[np.linspace(-0.3, 1.0, 40), np.linspace(1.0, -0.3, 40)] + rng.normal(0, 1e-3, 80) / 7
    curve = ForceCurve(comp, rng.normal(size=80) * 1e3, np.r_[np.zeros(40), np.ones(40)], {"source": "a\nb"})
    path = tmp_path / "out.csv"
    path.write_text("old")
    assert save_curve(curve, path) == path
    back = load_curve(path, preprocess=False)
    np.testing.assert_array_equal(back.compression, curve.compression)
    np.testing.assert_array_equal(back.force, curve.force)
    np.testing.assert_array_equal(back.segment, curve.segment)
    assert sorted(os.listdir(tmp_path)) == ["out.csv"]  # no temporary file left
    assert len(load_curve(path)) == 40  # preprocess=True on a compression file: approach only
    with pytest.raises(ValueError, match=r"\.csv"):
        save_curve(curve, tmp_path / "out.jpk-force")


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize("text,match", [
    ("", "empty"),
    ("# only a comment\n", "empty"),
    ("compression_um,force_pN\n", "no data rows"),
    ("compression_um,force_pN\n0.1,2.0\n", "at least 3"),
    ("compression_um,force_pN\n0,0\n0.2,1\n0.1,2\n0.3,3\n0.15,4\n0.4,5\n", "monotonic"),
    ("compression_um,force_pN\n0,0\nnan,1\n0.2,nan\n0.3,nan\n", r"3 NaN.*compression_um.*force_pN"),
    ("compression_um,force_kg\n0,0\n1,1\n2,2\n", "unknown unit 'kg'.*force_pN"),
    ("compression,force_pN\n0,0\n1,1\n2,2\n", "no unit"),
    ("compression_um,time_s\n0,0\n1,1\n2,2\n", "missing force.*force_pN"),
    ("time_s,force_pN\n0,0\n1,1\n2,2\n", "missing position.*tip_position"),
    ("compression_um,force_pN\n0,0\n1,x\n2,2\n", "line 3.*'x'"),
    ("compression_um,force_pN\n0,0\n1\n2,2\n", "line 3 has 1 fields"),
    ("compression_um,force_pN,segment\n0,0,0\n1,1,up\n2,2,0\n", "approach/retract"),
    ("compression_um,compression_nm,force_pN\n0,0,0\n1,1,1\n2,2,2\n", "more than one compression"),
])
def test_bad_native_files(tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        load_curve(path)


def test_bad_arguments_and_physics(tmp_path):
    path, _, _ = si_file(tmp_path)
    with pytest.raises(FileNotFoundError, match="not found"):
        load_curve(tmp_path / "nope.csv")
    for k in (0.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="positive"):
            load_curve(path, spring_constant=k)
    with pytest.raises(ValueError, match="spring_constant"):
        load_curve(path)
    with pytest.raises(ValueError, match="segment"):
        load_curve(path, spring_constant=K, segment="up")
    with pytest.raises(ValueError, match="baseline"):
        load_curve(path, spring_constant=K, baseline="quadratic")
    with pytest.raises(ValueError, match="contact_point"):
        load_curve(path, spring_constant=K, contact_point="manual")
    with pytest.raises(ValueError, match="preprocess=False"):
        load_curve(path, spring_constant=K, preprocess=False)
    tip, _, height, f_raw, _ = synthetic()
    away = write(tmp_path / "away.csv", ["height_um", "force_pN"], (-height).tolist(), f_raw.tolist())
    with pytest.raises(ValueError, match="toward the surface"):
        load_curve(away, spring_constant=K)
    flat = write(tmp_path / "flat.csv", ["tip_position_um", "force_pN"], tip.tolist(),
                 np.random.default_rng(0).normal(0, 5, len(tip)).tolist())
    with pytest.raises(ValueError, match="no contact"):
        load_curve(flat)
    comp = write(tmp_path / "comp.csv", ["compression_um", "force_pN"], [0.0, 1.0, 2.0], [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="already preprocessed"):
        load_curve(comp, baseline="constant")
    with pytest.raises(ValueError, match="retract points"):
        load_curve(comp, segment="retract")


def test_missing_afmformats_gives_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "afmformats", None)
    with pytest.raises(ImportError, match=r"pip install 'socbjax\[afm\]' \(afmformats\)"):
        load_curve(DATA / "force-save-example.jpk-force")


# ---------------------------------------------------------------- real files (afmformats)
REAL = {  # file: (spring constant N/m, setpoint pN, approach points, raw points)
    "force-save-example.jpk-force": (0.0223, 6000.0, 6000, 8400),
    "fmt-jpk-fd_spot3-0192.jpk-force": (0.0435, 4000.0, 2000, 4000),
    "fmt-tab-fd_version_0.13.3.tab": (0.0223, 6000.0, 3146, 4028),
    "fmt-igor-fd_SiN_FD_plot.ibw": (1.1841, 10000.0, 1008, 2016),
}


@pytest.mark.parametrize("name", sorted(REAL))
def test_real_files(name):
    pytest.importorskip("afmformats")
    k, setpoint, n_app, n_raw = REAL[name]
    curve = load_curve(DATA / name)
    m = curve.metadata
    assert m["spring_constant_N_per_m"] == pytest.approx(k, abs=1e-4)
    assert len(curve) == n_app and m["n_raw_points"] == n_raw and (curve.segment == 0).all()
    # the approach is stopped at the setpoint force (relative to the baseline)
    assert curve.force.max() == pytest.approx(setpoint, rel=0.03)
    # force rises with compression past contact; before contact it is ≈ 0 (baseline removed)
    assert curve.compression.max() > 0.005 and curve.compression.min() < -0.1
    deep = curve.select(min_compression=0.8 * curve.compression.max())
    assert deep.force.mean() > 0.5 * setpoint
    pre = curve.select(max_compression=-0.05)
    assert abs(np.median(pre.force)) < 2 * m["noise_pN"] and m["noise_pN"] < 20.0
    b = curve.select(min_compression=0).binned(10)
    assert np.corrcoef(b.compression, b.force)[0, 1] > 0.8 and b.force[-1] > b.force[0] + 0.5 * setpoint
    both = load_curve(DATA / name, segment="both")
    assert len(both) == n_raw and len(both.retract) == n_raw - n_app


def test_real_igor_split_and_jpk_metadata():
    pytest.importorskip("afmformats")
    igor = load_curve(DATA / "fmt-igor-fd_SiN_FD_plot.ibw", segment="retract")
    assert "split" in igor.metadata["segments_from"] and "every point approach" in igor.metadata["segments_from"]
    assert igor.force.max() > 5000.0  # the retract starts at the deepest point
    jpk = load_curve(DATA / "force-save-example.jpk-force", spring_constant=0.03)
    assert jpk.metadata["spring_constant_source"] == "argument"
    assert jpk.metadata["file_spring_constant_N_per_m"] == pytest.approx(0.0223, abs=1e-4)
    assert "JPK" in jpk.metadata["format"] and jpk.metadata["source"].endswith("force-save-example.jpk-force")
    with pytest.raises(ValueError, match="curve_index"):
        load_curve(DATA / "force-save-example.jpk-force", curve_index=3)
    with pytest.raises(ValueError, match="preprocess=False"):
        load_curve(DATA / "force-save-example.jpk-force", preprocess=False)


def test_unsupported_extension(tmp_path):
    pytest.importorskip("afmformats")
    path = tmp_path / "curve.xyz"
    path.write_text("1 2 3\n")
    with pytest.raises(ValueError, match="unsupported"):
        load_curve(path)


@pytest.mark.parametrize("content, match", [
    (bytes(range(256)) * 8, r"binary.csv: a binary file"),
    ("compression_um,force_pN\n0,0\n1,1\n".encode("utf-16"), r"binary.csv: a binary file"),  # UTF-16: NUL bytes
    (b"compression_um,force_pN\n0,0\n1,\xff\n2,2\n", r"binary.csv: not UTF-8 text \(byte 30 is 0xff\)"),
])
def test_binary_or_undecodable_text_files_name_the_file(tmp_path, content, match):
    path = tmp_path / "binary.csv"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=match):
        load_curve(path)


@pytest.mark.parametrize("content", [b"", b"not a jpk archive at all", bytes(4096)])
def test_damaged_instrument_files_are_value_errors(tmp_path, content):
    """afmformats' reader errors derive from BaseException (escaping ``except Exception``):
    they come back as one ValueError that names the file."""
    pytest.importorskip("afmformats")
    path = tmp_path / "damaged.jpk-force"
    path.write_bytes(content)
    with pytest.raises(ValueError, match="damaged.jpk-force"):
        load_curve(path)


def test_hysteresis_is_the_loop_area():
    """A triangle loop: approach F = 2c, retract F = c on [0, 1] µm → area ½ (2 − 1) = 0.5 pN·µm;
    reversed retract order and extra points before contact do not change it."""
    c = np.linspace(-0.2, 1.0, 61)
    approach = np.where(c > 0, 2 * c, 0.0)
    retract = np.where(c > 0, c, 0.0)
    curve = ForceCurve(np.concatenate([c, c[::-1]]), np.concatenate([approach, retract[::-1]]),
                          np.concatenate([np.zeros(c.size), np.ones(c.size)]).astype(np.int8))
    assert abs(curve.hysteresis() - 0.5) < 1e-4
    assert np.isnan(ForceCurve(c, approach).hysteresis())
