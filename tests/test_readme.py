"""The README's commands and example stay true."""

import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def test_ci_runs_exactly_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    commands = re.findall(r"```bash\n(.+?)\n```", readme)
    assert len(commands) == 2, "the README has exactly two set-up commands"
    assert commands[1] in ci.splitlines()


def test_five_line_example_runs():
    import socbjax as sj

    net = sj.cantilever(2, length=1.0, EI=1.0, dim=3)
    sol = sj.solve(net, {-1: [0.0, 2.0, 0.0]})
    np.testing.assert_allclose(np.asarray(sol.positions[-1]), [0.83927, 0.49360, 0.0], atol=1e-5)
    assert abs(sj.buckling_load(sj.column(5, supports=("pinned", "pinned"))) - np.pi**2) < 1e-3 * np.pi**2
