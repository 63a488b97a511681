"""Example data shipped with socbjax: small real AFM force curves (:func:`example_files`).

The curves are copied unchanged from the source distribution of ``afmformats`` 0.18.7
(Paul Müller, MIT licence; the Igor file CC0), with their licence and SHA-256 sums in the
same package folder (``socbjax/data/afm``).  Reading the JPK, Asylum and afmformats
formats needs the optional extra ``afm`` (``pip install ".[afm]"``).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["example_files", "example_file", "example_descriptions"]

_PACKAGE = "socbjax"
_FOLDER = ("data", "afm")
# name -> what it is (kept with the files' README.md in the same folder)
_DESCRIPTIONS = {
    "force-save-example.jpk-force": "JPK force curve, 6000 approach + 2400 retract points, spring constant 0.0223 N/m, 6 nN setpoint",
    "fmt-jpk-fd_spot3-0192.jpk-force": "JPK force curve, 2000 + 2000 points, spring constant 0.0435 N/m, 4 nN setpoint",
    "fmt-tab-fd_version_0.13.3.tab": "afmformats' tab-separated export of a JPK curve, 3146 + 882 points, 0.0223 N/m, 6 nN setpoint",
    "fmt-igor-fd_SiN_FD_plot.ibw": "Asylum Research (Igor) force curve, 2016 points, 1.1841 N/m, 10 nN setpoint",
}


def _folder() -> Path:
    # The package is installed as files (setuptools, not a zip), so the traversable is a real path.
    return Path(str(resources.files(_PACKAGE).joinpath(*_FOLDER)))


def example_files() -> dict[str, Path]:
    """The shipped example AFM force curves: ``{file name: absolute path}``.

    Four real curves (JPK ``.jpk-force`` ×2, afmformats ``.tab``, Asylum ``.ibw``), each a
    few hundred kB; :func:`example_file` gives one by name, ``socbjax examples`` lists them
    on the command line.  Read them with :func:`socbjax.load_curve` (extra ``afm``).
    """
    folder = _folder()
    return {name: folder / name for name in _DESCRIPTIONS}


def example_file(name: str) -> Path:
    """The path of one shipped example curve, e.g. ``example_file("force-save-example.jpk-force")``.

    Raises ``ValueError`` naming the available files when ``name`` is not one of them.
    """
    if not isinstance(name, str):
        raise TypeError(f"name must be a file name (str), got {type(name).__name__} {name!r}")
    files = example_files()
    if name not in files:
        raise ValueError(f"name={name!r} is not a shipped example; choose one of {', '.join(files)}")
    return files[name]


def example_descriptions() -> dict[str, str]:
    """``{file name: one-line description}`` of the shipped example curves."""
    return dict(_DESCRIPTIONS)
