"""The XLA option socbjax adds at import (legacy CPU fusion emitters, faster compilation):
added once, never over the user's own setting or opt-out, never for a jaxlib where it was
not measured (XLA stops on an unknown flag), accepted by the installed jaxlib, and the same
results with and without it."""

import json
import os
import subprocess
import sys

import numpy as np

import socbjax as sj

FLAG = "--xla_cpu_use_fusion_emitters=false"


def test_the_flag_is_added_once_after_the_users_flags():
    env = {"XLA_FLAGS": "--xla_force_host_platform_device_count=2"}
    assert sj.add_default_xla_flags(env, jaxlib_series=(0, 10))
    assert env["XLA_FLAGS"] == f"--xla_force_host_platform_device_count=2 {FLAG}"
    assert not sj.add_default_xla_flags(env, jaxlib_series=(0, 10))  # already there
    assert env["XLA_FLAGS"].count("fusion_emitters") == 1


def test_the_users_choice_an_opt_out_and_an_unmeasured_jaxlib_are_left_alone():
    mine = {"XLA_FLAGS": "--xla_cpu_use_fusion_emitters=true"}
    assert not sj.add_default_xla_flags(mine, jaxlib_series=(0, 10))
    assert mine == {"XLA_FLAGS": "--xla_cpu_use_fusion_emitters=true"}
    for value in ("off", "0", "False", " no "):
        env = {"SOCBJAX_XLA_DEFAULTS": value}
        assert not sj.add_default_xla_flags(env, jaxlib_series=(0, 10)) and "XLA_FLAGS" not in env
    env = {"SOCBJAX_XLA_DEFAULTS": "on"}
    assert sj.add_default_xla_flags(env, jaxlib_series=(0, 10)) and env["XLA_FLAGS"] == FLAG
    for series in ((0, 4), (0, 11), (1, 0)):
        env = {}
        assert not sj.add_default_xla_flags(env, jaxlib_series=series) and env == {}


_TIP = ("import json, os, socbjax as sj, numpy as np; "
        "s = sj.solve(sj.cantilever(4, dim=2, EI=1.0), {3: [0.0, -1.5]}); "
        "print(os.environ.get('XLA_FLAGS', ''), '|', json.dumps(np.asarray(s.positions[-1]).tolist()))")


def _tip(**env):
    run = subprocess.run([sys.executable, "-c", _TIP], env={**os.environ, "SOCBJAX_CACHE_DIR": "off", **env},
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    flags, tip = run.stdout.strip().rsplit("|", 1)
    return flags, np.array(json.loads(tip))


def test_the_installed_jaxlib_runs_with_and_without_the_flag_to_the_same_solution():
    """In fresh processes (the flag applies when the CPU backend starts): with socbjax's
    default and with the opt-out, the same cantilever tip to 1e-12 µm."""
    base = os.environ.get("XLA_FLAGS", "").replace(FLAG, "").strip()
    on_flags, on = _tip(XLA_FLAGS=base)
    off_flags, off = _tip(XLA_FLAGS=base, SOCBJAX_XLA_DEFAULTS="off")
    assert FLAG not in off_flags and (FLAG in on_flags) == sj.add_default_xla_flags({})  # on where measured
    np.testing.assert_allclose(on, off, rtol=0, atol=1e-12)
    assert on[1] < -0.3  # the tip force really bends it
