"""Batch fits (``socbjax.fit_batch``, ``socbjax fit A B DIR ... --out DIR``): order-independent
rows, the CSV/JSON tables against direct fits, failure rows, symbolic links skipped, atomic
writes, the figures, results of ``socbjax simulate`` and the dimension check.

Default-suite models are planar (``dim=2``) 4-node columns on curves of a few points."""

import csv
import hashlib
import json
import math
import os
import re
import types
from pathlib import Path

import numpy as np
import pytest

import socbjax as sj
import socbjax._batch as batch_module
import socbjax.cli

SETTINGS = dict(max_iterations=8, max_points=12)
COLUMN = dict(n_nodes=4, supports=("pinned", "pinned"), dim=2)
TRUE_EI = {"a.csv": 0.5, "b.csv": 0.9, "c.csv": 0.5}  # c.csv: a copy of a.csv (same data: one compilation less)
CLI_MODEL = ["--model", "column", "--dim", "2", "--model-option", "n_nodes=4", "--supports", "pinned,pinned",
             "--max-iterations", "8", "--max-points", "12", "--quiet"]


def _pinned_pinned_force(shortening, EI):
    """Closed-form elastica of a pinned–pinned column of 1 µm (first mode): Δ = 2(1 − E(m)/K(m)),
    P = 4 K(m)² EI (as in tests/test_compress.py): synthetic curves without a solve."""
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipk

    m = [brentq(lambda m, d=d: 2 * (1 - ellipe(m) / ellipk(m)) - d, 1e-14, 0.999) for d in shortening]
    return 4 * ellipk(np.asarray(m)) ** 2 * EI


def _write_curves(folder: Path) -> None:
    c = np.linspace(0.02, 0.25, 8)
    rng = np.random.default_rng(3)
    for name in ("a.csv", "b.csv"):
        F = _pinned_pinned_force(c, TRUE_EI[name]) * (1.0 + 0.01 * rng.standard_normal(c.size))
        sj.save_curve(sj.ForceCurve(c, F), folder / name)  # the native CSV writer (load_curve reads it back)
    (folder / "c.csv").write_bytes((folder / "a.csv").read_bytes())  # another file with the same content


@pytest.fixture(scope="module")
def curves(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("curves")
    _write_curves(folder)
    (folder / "notes.md").write_text("not a curve")
    (folder / "broken.csv").write_text("time_s,voltage_V\n0,1\n1,2\n3,4\n")  # no force column: a failure row
    return folder


@pytest.fixture(scope="module")
def cli_run(curves, tmp_path_factory):
    """``socbjax fit FOLDER --out DIR`` once for the module: (exit status, stdout, out folder)."""
    out = tmp_path_factory.mktemp("cli") / "fits"  # created by the command
    import contextlib
    import io

    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = socbjax.cli.main(["fit", str(curves), *CLI_MODEL, "--out", str(out)])
    return code, stdout.getvalue(), out


def _rows(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_cli_batch_writes_tables_figures_and_progress_lines(cli_run, curves):
    code, stdout, out = cli_run
    assert code == 0
    rows = _rows(out / "results.csv")
    assert [Path(r["file"]).name for r in rows] == ["a.csv", "b.csv", "broken.csv", "c.csv"]  # sorted, notes.md skipped
    header = list(rows[0])
    for column in ("file", "sha256", "model", "EI", "EI_se", "contact_point_um", "fit_min_compression_um",
                   "fit_max_compression_um", "n_points", "noise_pN", "chi2_reduced", "misfit", "converged", "message",
                   "warnings"):
        assert column in header, column
    assert header.index("EI_se") == header.index("EI") + 1
    for r in rows:
        assert r["sha256"] == hashlib.sha256((curves / Path(r["file"]).name).read_bytes()).hexdigest() and r["model"] == "column"
    assert rows[0]["sha256"] == rows[3]["sha256"] and rows[0]["EI"] == rows[3]["EI"]  # a.csv and its copy c.csv
    good = [r for r in rows if r["status"] != "failed"]
    for r in good:
        assert float(r["EI"]) == pytest.approx(TRUE_EI[Path(r["file"]).name], rel=0.03)
        assert float(r["EI_se"]) > 0 and r["n_points"] == "8" and float(r["fit_max_compression_um"]) == pytest.approx(0.25)
        assert (out / r["figure"]).stat().st_size > 10_000 and r["figure"] == Path(r["file"]).stem + ".png"
    broken = next(r for r in rows if r["file"].endswith("broken.csv"))
    assert broken["status"] == "failed" and "missing force column" in broken["message"] and broken["EI"] == "nan"
    assert broken["converged"] == "False" and broken["figure"] == ""
    assert (out / "summary.png").stat().st_size > 20_000
    lines = [line for line in stdout.splitlines() if line.startswith("[")]
    assert len(lines) == 4 and lines[0].startswith("[1/4] a.csv: EI = ") and "± " in lines[0]
    assert re.search(r"χ²_red|R²", lines[0]) and lines[2].startswith("[3/4] broken.csv: FAILED: ")
    report = json.loads((out / "results.json").read_text())
    assert report["n_curves"] == 4 and report["n_failed"] == 1 and report["columns"] == header
    assert report["units"]["EI"] == "pN·µm²" and report["settings"]["dim"] == 2
    assert [r["file"] for r in report["rows"]] == [r["file"] for r in rows]
    assert report["rows"][2]["EI"] is None  # strict JSON: NaN as null
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]


def test_rows_do_not_depend_on_argument_order(cli_run, curves, tmp_path):
    """The same files given one by one, in another order, one of them twice (directly and
    through the folder): the same bytes in results.csv and results.json."""
    _, _, first = cli_run
    files = [str(curves / n) for n in ("c.csv", "broken.csv", "a.csv", "b.csv")]
    out = tmp_path / "second"
    result = sj.fit_batch([files[0], str(curves), *files[1:]], "column", out=out, model_options=COLUMN,
                          settings=sj.FitSettings(**SETTINGS))
    assert [Path(r["file"]).name for r in result.rows] == ["a.csv", "b.csv", "broken.csv", "c.csv"]
    assert (out / "results.csv").read_bytes() == (first / "results.csv").read_bytes()
    assert (out / "results.json").read_bytes() == (first / "results.json").read_bytes()
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in first.iterdir())


def test_rows_match_a_direct_fit_of_the_same_file(cli_run, curves):
    _, _, out = cli_run
    rows = {Path(r["file"]).name: r for r in _rows(out / "results.csv")}
    curve = sj.load_curve(curves / "b.csv")
    direct = sj.fit(curve, sj.ColumnModel(**COLUMN), free=("EI",), settings=sj.FitSettings(**SETTINGS))
    row = rows["b.csv"]
    assert float(row["EI"]) == pytest.approx(direct.values["EI"], rel=1e-9)
    assert float(row["EI_se"]) == pytest.approx(direct.standard_errors["EI"], rel=1e-6)
    assert row["converged"] == str(direct.converged) and row["message"] == direct.message
    assert float(row["r_squared"]) == pytest.approx(direct.r_squared, rel=1e-9)
    chi2 = getattr(direct, "chi2_reduced", math.nan)
    assert (math.isnan(chi2) and row["chi2_reduced"] == "nan") or float(row["chi2_reduced"]) == pytest.approx(chi2, rel=1e-9)
    assert row["contact_point_source"] == "curve" and float(row["contact_shift_um"]) == 0.0


def test_a_batch_where_every_curve_fails_exits_1_with_a_row_each(tmp_path, capsys):
    """Unreadable and out-of-range curves are rows with their messages (the command's own
    fixes, --max-compression); the exit status is 1 only because every curve failed."""
    (tmp_path / "empty.csv").write_text("")
    deep = tmp_path / "deep.csv"
    sj.save_curve(sj.ForceCurve(np.linspace(0.1, 3.0, 6), np.linspace(1.0, 2.0, 6)), deep)  # beyond a 1-µm column
    out = tmp_path / "out"
    assert socbjax.cli.main(["fit", str(tmp_path / "empty.csv"), str(deep), *CLI_MODEL, "--out", str(out)]) == 1
    rows = _rows(out / "results.csv")
    assert [r["status"] for r in rows] == ["failed", "failed"]
    assert "probe–surface gap" in rows[0]["message"] and "--max-compression" in rows[0]["message"]
    assert "empty file" in rows[1]["message"]
    assert "every curve failed" in capsys.readouterr().err


def test_folders_skip_symlinks_hidden_files_and_subfolders(tmp_path):
    inside, outside = tmp_path / "inside", tmp_path / "outside"
    inside.mkdir()
    outside.mkdir()
    for folder, name in ((inside, "real.csv"), (outside, "secret.csv"), (inside / "sub", "deeper.csv")):
        folder.mkdir(exist_ok=True)
        (folder / name).write_text("compression_um,force_pN\n0.1,1\n0.2,2\n0.3,3\n")
    os.symlink(outside / "secret.csv", inside / "link.csv")
    os.symlink(outside, inside / "linked-folder")
    (inside / ".hidden.csv").write_text("compression_um,force_pN\n0.1,1\n0.2,2\n0.3,3\n")
    (inside / "readme.txt").write_text("just notes\n")
    (inside / "table.txt").write_text("compression_um\tforce_pN\n0.1\t1\n0.2\t2\n0.3\t3\n")
    os.mkfifo(inside / "pipe.csv")
    found = sj.collect_curve_files([inside])
    assert [f.path.name for f in found] == ["real.csv", "table.txt"]
    assert sj.collect_curve_files([inside, inside / "real.csv"])[0].label == str(inside / "real.csv")
    with pytest.raises(FileNotFoundError, match="nothing.csv"):
        sj.collect_curve_files([tmp_path / "nothing.csv"])
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no curve files"):
        sj.fit_batch([tmp_path / "empty"], "column", model_options=COLUMN)


def test_a_failing_write_keeps_the_previous_results(cli_run, tmp_path, monkeypatch):
    """The table is written to a temporary file and renamed: a writer that fails midway
    leaves the previous results.csv and results.json untouched and no temporary file."""
    _, _, out = cli_run
    rows = _rows(out / "results.csv")
    result = sj.BatchResult(rows=rows, columns=list(rows[0]), units={}, settings={})
    target = tmp_path / "results.csv"
    target.write_text("previous results\n")

    class DiskFull:
        """A cell whose text cannot be written: the disk fills up inside the second row."""

        def __str__(self):
            raise OSError(28, "No space left on device")

    broken = [rows[0], {**rows[1], "message": DiskFull()}, *rows[2:]]
    with pytest.raises(OSError, match="previous file there is unchanged"):
        sj.BatchResult(rows=broken, columns=list(rows[0]), units={}, settings={}).to_csv(target)
    assert target.read_text() == "previous results\n"
    (tmp_path / "results.json").write_text("{}")
    monkeypatch.setattr(json, "dumps", lambda *a, **k: (_ for _ in ()).throw(ValueError("boom")))
    with pytest.raises(ValueError, match="boom"):
        result.to_json(tmp_path / "results.json")
    assert (tmp_path / "results.json").read_text() == "{}"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.csv", "results.json"]


@pytest.fixture(scope="module")
def simulated(tmp_path_factory) -> Path:
    run = tmp_path_factory.mktemp("simulated") / "column.h5"
    assert socbjax.cli.main(["simulate", "column", "--dim", "2", "--nodes", "4", "--supports", "pinned,pinned",
                             "--displacement", "0.2", "--no-unload", "--out", str(run), "--quiet"]) == 0
    return run


SIMULATED_FIT = ["--model", "column", "--model-option", "n_nodes=4", "--supports", "pinned,pinned", "--max-iterations",
                 "8", "--max-points", "12", "--quiet"]


def test_simulated_results_are_read_and_their_dimension_is_enforced(simulated, tmp_path, capsys):
    """An HDF5 result of `socbjax simulate` is a curve (probe displacement and force) that
    knows its network's dimension: a planar run fitted with a 3D model is refused, naming
    both and the option, on the command line, in a batch row and in Python."""
    curve = sj.read_curve(simulated)
    assert curve.metadata["dim"] == 2 and curve.metadata["network"] == "column" and np.all(curve.segment == 0)
    assert curve.compression.max() == pytest.approx(0.2) and curve.metadata["source"] == str(simulated)
    run = sj.load(simulated)
    assert len(curve) == int(np.sum(np.asarray(run.phase) == 1)) and curve.force.min() > 0  # no settle row
    assert len(sj.curve_from_result(sj.load(simulated))) == len(curve)
    capsys.readouterr()
    assert socbjax.cli.main(["fit", str(simulated), *SIMULATED_FIT, "--out", str(tmp_path / "fit.json")]) == 2
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert "simulated with a 2D column" in line and "column model is 3D" in line and "--dim 2" in line
    assert not (tmp_path / "fit.json").exists()
    with pytest.raises(ValueError, match=r"model_options=\{'dim': 2\}"):
        sj.check_dimension(curve, sj.ColumnModel(3))
    sj.check_dimension(curve, sj.ColumnModel(3, dim=2))
    sj.check_dimension(sj.ForceCurve([0.0, 0.1, 0.2], [0.0, 1.0, 2.0]), sj.ColumnModel(3))  # measured: no dim
    batch = sj.fit_batch([simulated], "column", model_options={"n_nodes": 4, "supports": ("pinned", "pinned")},
                         settings=sj.FitSettings(**SETTINGS))
    assert batch.rows[0]["status"] == "failed" and "--dim" not in batch.rows[0]["message"]
    assert "model_options={'dim': 2}" in batch.rows[0]["message"] and batch.exit_status == 1


@pytest.mark.slow
def test_a_simulated_result_fits_with_its_own_dimension(simulated, tmp_path):
    assert socbjax.cli.main(["fit", str(simulated), *SIMULATED_FIT, "--dim", "2", "--out", str(tmp_path / "fit.json")]) == 0
    EI = json.loads((tmp_path / "fit.json").read_text())["values"]["EI"]
    assert EI == pytest.approx(1.0, rel=1e-3)  # socbjax simulate column's EI


def test_multi_curve_files_give_a_row_per_curve(tmp_path, monkeypatch):
    """A force map (n_curves_in_file > 1 in the reader's metadata) gives one row per curve,
    in curve order, with distinct figure names (the fit itself replaced: this checks the
    bookkeeping only)."""
    path = tmp_path / "map.jpk-force-map"
    path.write_bytes(b"a force map")

    def fake_read(p, *, curve_index=0, **kwargs):
        c = np.linspace(0.0, 0.2, 5)
        return sj.ForceCurve(c, (curve_index + 1) * c, metadata={"n_curves_in_file": 3, "contact_point_um": 1.0})

    def fake_fit(curve, model, *, free, **kwargs):
        values = {"EI": float(curve.force[-1])}
        return types.SimpleNamespace(names=("EI",), values=values, standard_errors={"EI": 0.01}, units={"EI": "pN·µm²"},
                                     compression=curve.compression, r_squared=1.0, rms=0.0, converged=True,
                                     message="ok", warnings=[], chi2_reduced=1.0, noise=0.1, misfit=False)

    monkeypatch.setattr(batch_module, "read_curve", fake_read)
    monkeypatch.setattr("socbjax._fit.fit", fake_fit)
    result = sj.fit_batch([path], "column", figures=False)
    assert [r["curve_index"] for r in result.rows] == [0, 1, 2]
    assert [r["EI"] for r in result.rows] == pytest.approx([0.2, 0.4, 0.6])
    assert all(r["contact_point_um"] == 1.0 and r["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest() for r in result.rows)
    names = batch_module._Names()
    assert [names(s) for s in ("map-0", "map-0", "summary", "results")] == ["map-0.png", "map-0-2.png", "summary-2.png",
                                                                         "results.png"]


def test_compare_is_wired_to_compare_models(curves, tmp_path, capsys, monkeypatch):
    """`--compare a,b` calls socbjax.compare_models per curve with the models, the fit
    settings and --dim for every model (--model-option for the --model only), prints each
    table and writes comparison.json (compare_models replaced: the wiring only)."""
    calls = []

    class Comparison:
        def table(self):
            return "model  AIC\ncolumn 1.0"

        def to_dict(self):
            return {"best": "column", "aic": [1.0, math.nan]}

    def fake(curve, models, **kwargs):
        calls.append((len(curve), models, kwargs))
        return Comparison()

    monkeypatch.setattr(sj, "compare_models", fake, raising=False)
    out = tmp_path / "cmp"
    argv = ["fit", str(curves / "a.csv"), str(curves / "broken.csv"), "--compare", "column,unit-mesh", "--dim", "2",
            "--model-option", "mother_length=2", "--max-points", "8", "--quiet", "--out", str(out)]
    assert socbjax.cli.main(argv) == 0
    captured = capsys.readouterr().out
    assert "[1/2] a.csv:\nmodel  AIC" in captured and "[2/2] broken.csv:\nFAILED: " in captured
    (n, models, kwargs), = calls
    assert n == 8 and models == ("column", "unit-mesh") and kwargs["settings"].max_points == 8
    assert kwargs["model_options"] == {"column": {"dim": 2}, "unit-mesh": {"dim": 2, "mother_length": 2.0}}
    assert "free" not in kwargs  # each model's own default free parameters
    record = json.loads((out / "comparison.json").read_text())
    assert record["models"] == ["column", "unit-mesh"] and [c["file"] for c in record["curves"]] == [
        str(curves / "a.csv"), str(curves / "broken.csv")]
    assert record["curves"][0]["comparison"] == {"best": "column", "aic": [1.0, None]}
    assert "missing force column" in record["curves"][1]["error"]


@pytest.mark.slow
def test_compare_prints_tables_and_writes_comparison_json(curves, tmp_path, capsys):
    if not hasattr(sj, "compare_models"):
        pytest.skip("socbjax.compare_models is not available yet")
    out = tmp_path / "cmp"
    code = socbjax.cli.main(["fit", str(curves / "a.csv"), "--compare", "column,unit-mesh",
                             "--dim", "2", "--max-iterations", "3", "--max-points", "8", "--quiet", "--out", str(out)])
    captured = capsys.readouterr()
    record = json.loads((out / "comparison.json").read_text())
    assert code in (0, 1) and record["models"] == ["column", "unit-mesh"] and len(record["curves"]) == 1
    assert "[1/1] a.csv" in captured.out


@pytest.mark.slow
def test_the_shipped_curves_in_one_batch_command(tmp_path, capsys):
    """The issue's batch: the shared JPK, JPK-example, .tab and .ibw curves in one command
    with the README's 12-µm planar unit mesh; a table, a figure per curve and the summary."""
    pytest.importorskip("afmformats")
    out = tmp_path / "shipped"
    files = [str(p) for p in sj.example_files().values()]
    code = socbjax.cli.main(["fit", *files[::-1], "--dim", "2", "--model-option", "mother_length=12", "--free",
                             "EI,branch_angle", "--quiet", "--out", str(out)])
    assert code == 0
    rows = _rows(out / "results.csv")
    assert [Path(r["file"]).name for r in rows] == sorted(sj.example_files())
    for r in rows:
        if r["status"] != "failed":
            assert float(r["EI"]) > 1.0 and (out / r["figure"]).exists()
    assert (out / "summary.png").exists()


def test_contact_point_of_a_row():
    """The contact column: the curve's contact tip position, moved by a fitted contact_offset
    (the model sees c + offset: contact at c = −offset, tip = contact + offset) or a model's
    contact_point (compression at contact)."""
    curve = sj.ForceCurve([0.0, 0.1, 0.2], [0.0, 1.0, 2.0], metadata={"contact_point_um": 2.0})
    offset = types.SimpleNamespace(values={"EI": 1.0, "contact_offset": 0.1}, names=("EI", "contact_offset"))
    point, shift, source = batch_module._contact(offset, curve)
    assert (point, shift, source) == (pytest.approx(2.1), pytest.approx(-0.1), "fitted contact_offset")
    lawn = types.SimpleNamespace(values={"contact_point": 0.3}, names=("contact_point",))
    point, shift, source = batch_module._contact(lawn, curve)
    assert (point, shift, source) == (pytest.approx(1.7), pytest.approx(0.3), "fitted contact_point")
    fixed = types.SimpleNamespace(values={"EI": 1.0}, names=("EI",))
    assert batch_module._contact(fixed, curve) == (2.0, 0.0, "curve")
    point, _, _ = batch_module._contact(fixed, sj.ForceCurve([0.0, 0.1, 0.2], [0.0, 1.0, 2.0]))
    assert math.isnan(point)  # a curve given as compression has no contact tip position
