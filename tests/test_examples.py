"""Shipped example data (socbjax._examples): real AFM curves reachable through public functions,
byte-identical to the afmformats originals (their published SHA-256 sums), and declared as
package data so an installed (non-editable) socbjax carries them."""

import hashlib
import tomllib
from fnmatch import fnmatch
from pathlib import Path

import pytest

import socbjax as sj

ROOT = Path(__file__).resolve().parents[1]


def test_every_example_exists_inside_the_package_and_matches_its_sha256():
    files = sj.example_files()
    assert len(files) == 4 and set(files) == set(sj.example_descriptions())
    package = Path(sj.__file__).resolve().parent
    sums = {}
    for line in (package / "data" / "afm" / "SHA256SUMS").read_text().splitlines():
        digest, name = line.split()
        sums[name] = digest
    for name, path in files.items():
        assert path.is_file() and path.resolve().is_relative_to(package)
        assert hashlib.sha256(path.read_bytes()).hexdigest() == sums[name], name
    assert (package / "data" / "afm" / "LICENSE-afmformats").read_text().startswith("MIT")


def test_example_file_by_name_and_clear_errors():
    name = "fmt-jpk-fd_spot3-0192.jpk-force"
    assert sj.example_file(name) == sj.example_files()[name]
    with pytest.raises(ValueError, match=r"name='nope.jpk' is not a shipped example; choose one of .*force-save-example"):
        sj.example_file("nope.jpk")
    with pytest.raises(TypeError, match="name must be a file name"):
        sj.example_file(3)


def test_example_data_is_declared_as_package_data():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    patterns = config["tool"]["setuptools"]["package-data"]["socbjax"]
    folder = Path(sj.__file__).resolve().parent
    for path in (folder / "data" / "afm").iterdir():
        rel = path.relative_to(folder).as_posix()
        assert any(fnmatch(rel, p) for p in patterns), rel


def test_an_example_curve_loads_with_its_documented_spring_constant():
    pytest.importorskip("afmformats")
    curve = sj.load_curve(sj.example_file("fmt-jpk-fd_spot3-0192.jpk-force"))
    assert curve.metadata["spring_constant_N_per_m"] == pytest.approx(0.0435, abs=1e-4)
    assert "0.0435 N/m" in sj.example_descriptions()["fmt-jpk-fd_spot3-0192.jpk-force"]
