"""Physics validation of the planar SOCB and jointed models against independent references:
the exact elastica (diffrax shooting, socbjax.testing), Mattiasson's (1981) table, and the
classical Euler buckling loads."""

import functools

import numpy as np
import pytest

import socbjax as sj
from socbjax.testing import elastica_cantilever

MATTIASSON_P2 = (0.16064, 0.49346)  # (ΔX/L, ΔY/L) at PL²/EI = 2


@functools.lru_cache(maxsize=None)
def exact_tip_displacement(px: float, py: float, guess: float | None = None) -> np.ndarray:
    """Tip displacement of the unit clamped–free elastica under a fixed tip force (px, py)."""
    sol = elastica_cantilever((px, py), base_moment_guess=guess)
    assert sol.converged
    return np.asarray(sol.tip_position) - np.array([1.0, 0.0])


def tip_displacement(solution) -> np.ndarray:
    return np.asarray(solution.positions[-1]) - np.array([1.0, 0.0])


def relative_error(a, b) -> float:
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(b))


def propped_cantilever_load() -> float:
    """x² with x the first positive root of tan x = x (clamped–pinned Euler load)."""
    lo, hi = np.pi + 1e-9, 1.5 * np.pi - 1e-9
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if np.tan(mid) - mid < 0 else (lo, mid)
    return (0.5 * (lo + hi)) ** 2


EULER = {
    ("clamped", "free"): np.pi**2 / 4,
    ("pinned", "pinned"): np.pi**2,
    ("clamped", "clamped"): 4 * np.pi**2,
    ("clamped", "pinned"): propped_cantilever_load(),
}


def test_reference_reproduces_mattiasson():
    dx, dy = exact_tip_displacement(0.0, 2.0)
    assert abs(-dx - MATTIASSON_P2[0]) < 1e-5 and abs(dy - MATTIASSON_P2[1]) < 1e-5


def test_propped_load_value():
    assert abs(propped_cantilever_load() - 20.1907) < 1e-4


def test_two_node_cantilever_fig4a():
    """Paper Fig. 4A: PL²/EI = 2 with 2 nodes; the paper reports about 1 % error."""
    sol = sj.solve(sj.cantilever(2, dim=2), {-1: [0.0, 2.0]})
    d = tip_displacement(sol)
    exact = exact_tip_displacement(0.0, 2.0)
    assert relative_error(d, exact) < 1e-3
    assert abs(d[1] - exact[1]) / exact[1] < 1e-3
    assert abs(d[0] - exact[0]) / abs(exact[0]) < 1e-3
    assert abs(d[1] - MATTIASSON_P2[1]) / MATTIASSON_P2[1] < 1e-3


@pytest.mark.parametrize("load", np.geomspace(0.1, 10.0, 9).tolist())
def test_five_node_cantilever_all_loads(load):
    sol = sj.solve(sj.cantilever(5, dim=2), {-1: [0.0, load]})
    assert relative_error(tip_displacement(sol), exact_tip_displacement(0.0, load)) < 1e-5


def _convergence_order(ns, errors):
    h = 1.0 / (np.asarray(ns) - 1.0)
    return np.polyfit(np.log(h), np.log(errors), 1)[0]


def test_socb_convergence_order():
    exact = exact_tip_displacement(0.0, 2.0)
    ns = [2, 3, 4, 5, 6]
    errors = [relative_error(tip_displacement(sj.solve(sj.cantilever(n, dim=2), {-1: [0.0, 2.0]})), exact) for n in ns]
    assert all(e2 < e1 for e1, e2 in zip(errors, errors[1:]))
    order = _convergence_order(ns, errors)
    assert 5.5 < order < 6.5, (order, errors)  # sixth order in the segment length


@pytest.mark.slow
def test_jointed_converges_to_the_same_answer_at_second_order():
    exact = exact_tip_displacement(0.0, 2.0)
    ns = [5, 10, 20, 40]
    errors = [
        relative_error(tip_displacement(sj.solve(sj.cantilever(n, dim=2), {-1: [0.0, 2.0]}, model="jointed")), exact)
        for n in ns
    ]
    assert all(e2 < e1 for e1, e2 in zip(errors, errors[1:]))
    assert errors[-1] < 5e-4
    assert 1.8 < _convergence_order(ns, errors) < 2.2, errors


def test_buckling_three_nodes_clamped_free():
    P = sj.buckling_load(sj.column(3, supports=("clamped", "free"), dim=2))
    assert abs(P - np.pi**2 / 4) / (np.pi**2 / 4) < 1e-4


@pytest.mark.parametrize("dim", [2, pytest.param(3, marks=pytest.mark.slow)])
@pytest.mark.parametrize("supports", list(EULER))
def test_buckling_all_supports_five_nodes(supports, dim):
    P = sj.buckling_load(sj.column(5, supports=supports, dim=dim))
    assert abs(P - EULER[supports]) / EULER[supports] < 5e-4


def test_buckling_scales_with_EI_and_length():
    base = sj.buckling_load(sj.column(4, supports=("pinned", "pinned"), dim=2))
    scaled = sj.buckling_load(sj.column(4, supports=("pinned", "pinned"), dim=2, EI=0.071, length=2.5))
    assert abs(scaled - base * 0.071 / 2.5**2) / scaled < 1e-10


def test_jointed_buckling_converges():
    ref = EULER[("clamped", "free")]
    errors = [abs(sj.buckling_load(sj.column(n, dim=2), model="jointed") - ref) / ref for n in (5, 10, 20, 40)]
    assert all(e2 < e1 for e1, e2 in zip(errors, errors[1:]))
    assert errors[-1] < 1e-3


@pytest.mark.parametrize("overload", [1.01, 1.05, 1.1, 1.3])
def test_post_buckling_follows_the_elastica(overload):
    """Clamped–free column just past critical with a small lateral imperfection force."""
    P = overload * EULER[("clamped", "free")]
    force = (-P, 1e-3 * P)
    sol = sj.solve(sj.column(5, supports=("clamped", "free"), dim=2), {-1: list(force)})
    d = tip_displacement(sol)
    assert d[1] > 0.02  # it really buckled, in the direction of the imperfection
    m0 = float(sol.moments[0])  # picks the branch; the reference then converges on its own
    exact = exact_tip_displacement(*force, guess=m0)
    assert relative_error(d, exact) < 1e-3


@pytest.mark.slow  # suite time; in the default suite: the default order is checked by every elastica comparison
def test_quadrature_order_is_configurable_and_converged_at_default():
    exact = exact_tip_displacement(0.0, 2.0)
    errors = {
        order: relative_error(tip_displacement(sj.solve(sj.cantilever(3, dim=2), {-1: [0.0, 2.0]}, settings=sj.PathSettings(quadrature_order=order))), exact)
        for order in (2, 8, 12)
    }
    assert errors[2] > 10 * errors[8]  # too few points: quadrature error dominates
    assert abs(errors[12] - errors[8]) < 1e-3 * errors[8]  # order 8 is converged: discretisation error remains


def test_buckling_load_reports_its_status_and_refuses_networks_that_are_not_columns():
    P, result = sj.buckling_load(sj.column(4, supports=("pinned", "pinned"), dim=2), throw=False)
    assert result == sj.RESULTS.successful
    assert abs(P - np.pi**2) / np.pi**2 < 5e-4
    with pytest.raises(ValueError, match="straight column"):
        sj.buckling_load(sj.dendritic_outcrop(generations=2))


def test_buckling_load_refuses_what_has_no_column_buckling_load():
    """Networks and columns whose loaded end is held axially get a clear
    ValueError (not a number such as 5e-16 pN, nor a LinAlgError)."""
    with pytest.raises(ValueError, match="straight column"):
        sj.buckling_load(sj.unit_dendritic_mesh(dim=2))
    free = [np.zeros((0, 2))] * 3
    column = sj.column(5, supports=("clamped", "clamped"), dim=2)
    held = sj.make_network(np.asarray(column.positions), np.asarray(column.tangents), column.segments,
                           np.asarray(column.lengths), 1.0, fixed_directions=[np.eye(2), *free, np.eye(2)],
                           clamped=[True, False, False, False, True])
    with pytest.raises(ValueError, match="held along the column axis"):
        sj.buckling_load(held)
