"""The README's commands and example stay true."""

import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_ci_runs_exactly_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    commands = re.findall(r"```bash\n(.+?)\n```", readme)
    assert len(commands) == 2, "the README has exactly two set-up commands"
    assert commands[1] in ci.splitlines()


def python_block(heading: str) -> str:
    """The first ```python block after the README heading ``heading``."""
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index(heading):]
    return re.search(r"```python\n(.+?)\n```", section, re.S).group(1)


def test_five_line_example_prints_what_its_comments_say(capsys):
    code = python_block("## Five lines")
    exec(compile(code, "README.md", "exec"), {})
    tip_line, buckling_line = capsys.readouterr().out.strip().splitlines()
    # the comment after the first print is the documented output, to its printed digits
    documented = re.search(r"print\(sol\.positions\[-1\], sol\.converged\)\s+# \[(.+?)\] (\w+)", code)
    expected = [float(v) for v in documented.group(1).split()]
    printed = re.search(r"\[(.+?)\] (\w+)", tip_line)
    np.testing.assert_allclose([float(v) for v in printed.group(1).split()], expected, atol=1e-5)
    assert printed.group(2) == documented.group(2) == "True"
    # Euler's pinned–pinned load π² EI/L² (EI = L = 1), independent of the code
    assert abs(float(buckling_line) - np.pi**2) < 1e-4 * np.pi**2


def readme_table(heading_text: str) -> list[list[str]]:
    """Rows (cells as strings) of the first Markdown table after the line containing ``heading_text``."""
    readme = (ROOT / "README.md").read_text()
    rest = readme[readme.index(heading_text):].splitlines()
    start = next(i for i, line in enumerate(rest) if line.startswith("|"))
    rows = []
    for line in rest[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip("|").split("|")])
    return rows


CANTILEVER_TABLE = "Cantilever with a fixed-direction perpendicular tip load"
MATTIASSON = (0.16064, 0.49346)  # ΔX/L, ΔY/L of the exact elastica at PL²/EI = 2 (Mattiasson 1981)


def check_cantilever_row(row):
    import socbjax as sj

    model, nodes, dX, dY, error = row[0].lower(), int(row[1]), float(row[2]), float(row[3]), float(row[4].split()[0])
    tip = np.asarray(sj.solve(sj.cantilever(nodes, dim=2), {-1: [0.0, 2.0]}, model=model).positions[-1])
    np.testing.assert_allclose([1.0 - tip[0], tip[1]], [dX, dY], atol=1.5e-6)  # the printed digits
    exact = np.array([-MATTIASSON[0], MATTIASSON[1]])
    measured = np.linalg.norm(tip - [1.0, 0.0] - exact) / np.linalg.norm(exact)
    # the published values have 5 digits (±5e-6): the printed error holds to that accuracy
    assert abs(measured - error) <= max(0.06 * error, 1.2e-5), (row, measured)


def test_curved_filaments_block_runs_and_thermal_shapes_remove_the_step_at_zero():
    """The README's curved-filament block; the straight mesh's force jumps at u = 0 (its
    strands carry load unbent until they buckle), the thermally curved one starts from 0."""
    scope = {}
    exec(compile(python_block("## Curved filaments and thermal shapes"), "README.md", "exec"), scope)
    res, mesh = scope["res"], scope["mesh"]
    assert res.completed and np.any(np.asarray(mesh.natural_curvature) != 0)
    straight = scope["sj"].compress(scope["sj"].unit_dendritic_mesh(dim=2), 0.5, method="arclength", throw=False)

    def first_step_force(r):
        loading = (np.asarray(r.phase) == 1) & (np.asarray(r.displacement) > 1e-9)
        return float(np.asarray(r.force)[loading][0])

    assert first_step_force(res) < 0.5 * first_step_force(straight)


def test_readme_validation_rows_for_two_and_three_socb_nodes():
    rows = [r for r in readme_table(CANTILEVER_TABLE) if r[0] == "SOCB" and r[1] in ("2", "3")]
    assert len(rows) == 2
    for row in rows:
        check_cantilever_row(row)


@pytest.mark.slow
def test_readme_validation_table_every_row():
    rows = readme_table(CANTILEVER_TABLE)
    assert len(rows) == 7
    for row in rows:
        check_cantilever_row(row)


def test_readme_outcrop_has_the_stated_segment_count():
    import socbjax as sj

    stated = re.search(r"dendritic_outcrop\(generations=8, gap=6\.0, seed=0\)\s+# paper Fig\. 7a: (\d+) segments",
                       (ROOT / "README.md").read_text())
    assert sj.dendritic_outcrop(generations=8, gap=6.0, seed=0).n_segments == int(stated.group(1))


@pytest.mark.slow
def test_fitting_block_runs_on_the_shipped_curve(capsys):
    pytest.importorskip("afmformats")
    import socbjax as sj

    code = python_block("## Gradients and fitting force curves")
    exec(compile(code, "README.md", "exec"), {"sj": sj})
    out = capsys.readouterr().out
    assert "R²" in out or "R^2" in out


def test_every_command_line_in_the_readme_parses():
    import shlex

    import socbjax as sj
    from socbjax.cli import build_parser

    readme = (ROOT / "README.md").read_text()
    lines, fenced = [], False
    for line in readme.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif fenced and line.startswith("socbjax "):
            lines.append(line)
    assert len(lines) >= 6
    for line in lines:
        line = re.sub(r'"\$\(socbjax examples (\S+)\)"', lambda m: str(sj.example_file(m.group(1))), line)
        argv = shlex.split(line, comments=True)[1:]
        args = build_parser().parse_args(argv)  # argparse exits (SystemExit) on anything it rejects
        assert args.command == argv[0]


def test_contact_block_runs_and_keeps_the_column_inside_the_channel():
    """The README's contact block: the column reaches the wall (contacts carry force at the
    end) and never crosses it (gap ≥ −1 % of d); its figures have the contact-count axis."""
    scope = {}
    exec(compile(python_block("## Contact with walls, obstacles, the probe and other filaments"), "README.md", "exec"), scope)
    res = scope["result"]
    assert res.completed and int(res.contact_count[-1]) >= 1 and float(res.contact_force[-1]) > 0
    assert np.all(np.asarray(res.min_gap) > -0.01 * 0.01)
    y = np.asarray(res.positions)[..., 1]
    assert np.all(np.abs(y) < 0.1 - 0.005 + 0.01 * 0.01)  # node axes inside the channel
