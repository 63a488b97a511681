"""The XLA option socbjax sets by default at import: XLA's legacy CPU fusion emitters.

XLA compiles a program before its first run, and for socbjax's programs (a Newton solve or a
whole continuation path, with the segment physics and its derivatives inlined) that is most
of the wall time of a first call.  With jaxlib 0.10's default CPU fusion emitters it takes
about 1.3–1.8 times as long as with the legacy ones (``--xla_cpu_use_fusion_emitters=false``),
and the compiled programs run as fast or faster.  Measured on 2 CPU cores, jaxlib 0.10.2, cold cache:

* first ``sj.solve`` of a 5-node 3D cantilever: 4.75 s against 7.85 s (compile only);
* first ``sj.compress`` of the 6-generation outcrop by 1 µm: 34.8 s against 43.7 s; the
  second call 3.68 s against 3.78 s, with the same steps and forces;
* the 8-generation outcrop 3 µm and back by arclength: 63 s against 87 s first call, 36 s
  against 37 s second; the 6-generation one 1.5 µm and back with contact on the probe face
  and substrate: 196 s against 243 s first call, 104 s against 126 s second (same steps);
* ``tests/test_twist.py`` and ``tests/test_curved.py``: 57.8 s against 89.6 s.

So :func:`add_default_xla_flags` adds it to ``XLA_FLAGS`` when socbjax is imported, unless

* ``SOCBJAX_XLA_DEFAULTS`` is ``0``/``off``/``no``/``false``/``none`` (opt out);
* ``XLA_FLAGS`` already sets it (the user's choice wins);
* the installed jaxlib is not of a release series where the flag was measured
  (:data:`MEASURED_SERIES`): XLA stops the process on an unknown flag, so a jaxlib that
  dropped it must never see it.

XLA reads ``XLA_FLAGS`` when JAX starts its CPU backend (the first computation), so the flag
applies when socbjax is imported before any JAX computation; afterwards it has no effect.
It changes how XLA generates code, not the arithmetic the program asks for.
"""

from __future__ import annotations

import os
import re
from collections.abc import MutableMapping

__all__ = ["add_default_xla_flags", "DEFAULT_XLA_FLAG", "MEASURED_SERIES", "XLA_DEFAULTS_ENV"]

DEFAULT_XLA_FLAG = "--xla_cpu_use_fusion_emitters=false"
XLA_DEFAULTS_ENV = "SOCBJAX_XLA_DEFAULTS"
MEASURED_SERIES = ((0, 10),)  # jaxlib (major, minor) release series with the flag, measured
_OFF = ("0", "off", "no", "false", "none")


def _jaxlib_series() -> tuple[int, ...] | None:
    from importlib import metadata

    try:
        version = metadata.version("jaxlib")
    except metadata.PackageNotFoundError:
        return None
    return tuple(int(part) for part in re.findall(r"\d+", version)[:2])


def add_default_xla_flags(environ: MutableMapping[str, str] | None = None, jaxlib_series: tuple | None = None) -> bool:
    """Add :data:`DEFAULT_XLA_FLAG` to ``environ["XLA_FLAGS"]`` (default ``os.environ``)
    unless opted out, already set, or the jaxlib series (default: the installed one) is not
    in :data:`MEASURED_SERIES` (see the module docstring).  Returns whether it was added."""
    environ = os.environ if environ is None else environ
    choice = environ.get(XLA_DEFAULTS_ENV)
    if choice is not None and choice.strip().lower() in _OFF:
        return False
    flags = environ.get("XLA_FLAGS", "")
    if "xla_cpu_use_fusion_emitters" in flags:
        return False
    if (jaxlib_series or _jaxlib_series()) not in MEASURED_SERIES:
        return False
    environ["XLA_FLAGS"] = f"{flags} {DEFAULT_XLA_FLAG}".strip()
    return True
