"""Bad input is refused at once (issue 13, "Hardening"): every public builder, settings class
and solver argument raises ``TypeError`` (wrong type) or ``ValueError`` (wrong value) before
anything is traced or compiled, and the message names the argument.

``refused`` checks all three: the exception type, the argument's name in the message, and
that nothing was traced or compiled before the refusal (JAX reports every trace and
compilation to ``jax.monitoring``).  Hypothesis draws random bad
values per numeric argument; the explicit cases reproduce every case of the issue; valid
inputs of every builder must still build.
"""

import contextlib
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import socbjax as sj

FUZZ = settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


@contextlib.contextmanager
def jax_work():
    """Collects the names of JAX trace/compile events inside the block."""
    events = []

    def listener(name, *args, **kwargs):
        events.append(name)

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield events
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


def refused(exc, name, fn, *args, **kwargs) -> str:
    """``fn(*args, **kwargs)`` raises ``exc`` naming ``name``, before any JAX work."""
    with jax_work() as events, pytest.raises(exc) as info:
        fn(*args, **kwargs)
    message = str(info.value)
    assert name in message, f"the message does not name {name!r}: {message}"
    assert not events, f"JAX traced or compiled before refusing ({sorted(set(events))}): {message}"
    return message


# ------------------------------------------------------------------ value strategies
NONFINITE = st.sampled_from([math.nan, math.inf, -math.inf])
NOT_POSITIVE = st.one_of(NONFINITE, st.just(0.0), st.floats(max_value=0.0, allow_nan=False, allow_infinity=False))
NEGATIVE = st.one_of(NONFINITE, st.floats(max_value=-1e-300, allow_nan=False, allow_infinity=False))
NOT_A_NUMBER = st.sampled_from([True, False, "1.0", None, b"1", {}, object()])
FRACTIONAL = st.floats(allow_nan=False, allow_infinity=False, min_value=-1e6, max_value=1e6).filter(
    lambda x: x != int(x))
NOT_AN_INTEGER = st.one_of(NOT_A_NUMBER, FRACTIONAL, st.integers(-5, 50).map(float))


def _outcrop(**kwargs):
    return sj.dendritic_outcrop(**{"generations": 2, **kwargs})


def _column(**kwargs):
    return sj.column(kwargs.pop("n_nodes", 4), **kwargs)


def _cantilever(**kwargs):
    return sj.cantilever(kwargs.pop("n_nodes", 4), **kwargs)


BUILDERS = {"cantilever": _cantilever, "column": _column, "unit_dendritic_mesh": sj.unit_dendritic_mesh,
            "dendritic_outcrop": _outcrop}
POSITIVE_ARGS = [("cantilever", "length"), ("cantilever", "EI"), ("column", "length"), ("column", "EI"),
                 ("unit_dendritic_mesh", "EI"), ("unit_dendritic_mesh", "mother_length"),
                 ("unit_dendritic_mesh", "segment_length"), ("unit_dendritic_mesh", "daughter_length"),
                 ("dendritic_outcrop", "gap"), ("dendritic_outcrop", "growth"), ("dendritic_outcrop", "segment_length"),
                 ("dendritic_outcrop", "EI")]
NON_NEGATIVE_ARGS = [("unit_dendritic_mesh", "perturbation"), ("dendritic_outcrop", "perturbation")]
# (builder, argument, smallest valid value)
COUNT_ARGS = [("cantilever", "n_nodes", 2), ("column", "n_nodes", 2), ("unit_dendritic_mesh", "daughter_segments", 1),
              ("dendritic_outcrop", "generations", 1), ("dendritic_outcrop", "seed", 0),
              ("dendritic_outcrop", "max_redraws", 1)]


@pytest.mark.parametrize(("builder", "arg"), POSITIVE_ARGS)
@FUZZ
@given(st.data())
def test_positive_numbers(builder, arg, data):
    bad_value = data.draw(st.one_of(NOT_POSITIVE, NOT_A_NUMBER), label=arg)
    assume(not (arg == "daughter_length" and bad_value is None))  # None: the default (grow to the surface)
    exc = TypeError if not isinstance(bad_value, float) else ValueError
    refused(exc, arg, BUILDERS[builder], **{arg: bad_value})


@pytest.mark.parametrize(("builder", "arg"), NON_NEGATIVE_ARGS)
@FUZZ
@given(st.data())
def test_non_negative_numbers(builder, arg, data):
    bad_value = data.draw(st.one_of(NEGATIVE, NOT_A_NUMBER), label=arg)
    exc = TypeError if not isinstance(bad_value, float) else ValueError
    refused(exc, arg, BUILDERS[builder], **{arg: bad_value})


@pytest.mark.parametrize(("builder", "arg", "minimum"), COUNT_ARGS)
@FUZZ
@given(st.data())
def test_counts_are_integers_in_range(builder, arg, minimum, data):
    bad_type = data.draw(NOT_AN_INTEGER, label="wrong type")
    assume(not (arg == "daughter_segments" and bad_type is None))  # None: the default (pieces of segment_length)
    refused(TypeError, arg, BUILDERS[builder], **{arg: bad_type})
    too_small = data.draw(st.integers(max_value=minimum - 1), label="too small")
    refused(ValueError, arg, BUILDERS[builder], **{arg: too_small})


@pytest.mark.parametrize("builder", list(BUILDERS))
@FUZZ
@given(st.data())
def test_dim_is_the_integer_2_or_3(builder, data):
    bad_value = data.draw(st.integers().filter(lambda d: d not in (2, 3)), label="dim")
    refused(ValueError, "dim", BUILDERS[builder], dim=bad_value)
    refused(TypeError, "dim", BUILDERS[builder], dim=data.draw(NOT_AN_INTEGER, label="dim type"))


@pytest.mark.parametrize(("builder", "high"), [("unit_dendritic_mesh", 180.0), ("dendritic_outcrop", 90.0)])
@FUZZ
@given(st.data())
def test_branch_angles_outside_the_range(builder, high, data):
    outside = st.one_of(NONFINITE, st.floats(max_value=0.0999, allow_nan=False),
                        st.floats(min_value=high - 0.0999, allow_nan=False))
    refused(ValueError, "branch_angle", BUILDERS[builder], branch_angle=data.draw(outside, label="branch_angle"),
            **({"daughter_length": 0.5} if builder == "unit_dendritic_mesh" else {}))
    refused(TypeError, "branch_angle", BUILDERS[builder], branch_angle=data.draw(NOT_A_NUMBER, label="type"))


PATH_STEPS = ["initial_step", "min_step", "max_step", "max_corrector_ratio", "corrector_floor", "atol"]
PATH_COUNTS = ["max_steps", "max_attempts", "fast_iterations", "max_iterations", "max_backtracks"]


@pytest.mark.parametrize("field", [*PATH_STEPS, "grow", "max_turn"])
@FUZZ
@given(st.data())
def test_path_settings_real_fields(field, data):
    bad = {"grow": st.one_of(NONFINITE, st.floats(max_value=0.999, allow_nan=False)),
           "max_turn": st.one_of(NOT_POSITIVE, st.floats(min_value=3.1416, allow_nan=False))}.get(field, NOT_POSITIVE)
    refused(ValueError, field, sj.PathSettings, **{field: data.draw(bad, label=field)})
    refused(TypeError, field, sj.PathSettings, **{field: data.draw(NOT_A_NUMBER.filter(lambda v: v is not None))})


@pytest.mark.parametrize("field", [*PATH_COUNTS, "quadrature_order"])
@FUZZ
@given(st.data())
def test_path_settings_counts(field, data):
    minimum = 2 if field == "quadrature_order" else 1
    refused(ValueError, field, sj.PathSettings, **{field: data.draw(st.integers(max_value=minimum - 1))})
    refused(TypeError, field, sj.PathSettings,
            **{field: data.draw(NOT_AN_INTEGER.filter(lambda v: v is not None), label=field)})
    limit = {"max_steps": 10**6, "quadrature_order": 16}.get(field, 2**31 - 1)
    refused(ValueError, field, sj.PathSettings, **{field: data.draw(st.integers(min_value=limit + 1))})


# ------------------------------------------------------------------ make_network
def chain(dim=2, n=4, direction=None, origin=None, length=1.0):
    """A straight clamped–free chain: positions, tangents, segments, lengths and supports."""
    t = np.eye(dim)[0] if direction is None else np.asarray(direction, float) / np.linalg.norm(direction)
    o = np.zeros(dim) if origin is None else np.asarray(origin, float)
    s = np.linspace(0.0, length, n)
    fixed = [np.eye(dim)] + [np.zeros((0, dim))] * (n - 1)
    clamped = np.zeros(n, bool)
    clamped[0] = True
    return {"positions": o + s[:, None] * t, "tangents": np.tile(t, (n, 1)), "segments": [(k, k + 1) for k in range(n - 1)],
            "lengths": np.full(n - 1, length / (n - 1)), "EI": 1.0, "fixed_directions": fixed, "clamped": clamped}


def network(**changes):
    args = {**chain(), **changes}
    return sj.make_network(args.pop("positions"), args.pop("tangents"), args.pop("segments"), args.pop("lengths"),
                           args.pop("EI"), **args)


def branched(angle_deg=70.0, dim=2):
    """A chain with a daughter from node 1 at ``angle_deg`` (make_network keyword arguments)."""
    base = chain(dim)
    phi = np.deg2rad(angle_deg)
    t_d = np.cos(phi) * np.eye(dim)[0] + np.sin(phi) * np.eye(dim)[1]
    pos = np.vstack([base["positions"], base["positions"][1], base["positions"][1] + 0.5 * t_d])
    tan = np.vstack([base["tangents"], t_d, t_d])
    return {**base, "positions": pos, "tangents": tan, "segments": [*base["segments"], (4, 5)],
            "lengths": np.append(base["lengths"], 0.5), "fixed_directions": base["fixed_directions"] + [np.zeros((0, dim))] * 2,
            "clamped": np.append(base["clamped"], [False, False]), "attach": [(1, 4)]}


@FUZZ
@given(st.integers(0, 3), st.sampled_from(["float", "bool", "high", "negative"]), st.data())
def test_bad_index_arrays(which, kind, data):
    arg = data.draw(st.sampled_from(["segments", "probe", "attach", "strand"]), label="argument")
    good = {"segments": [[0, 1], [1, 2], [2, 3]], "probe": [3, 2], "attach": None, "strand": [0, 0, 0]}[arg]
    base = branched() if arg == "attach" else chain()
    values = np.array(base["attach"] if arg == "attach" else good, dtype=object).ravel()
    i = which % values.size
    values[i] = {"float": values[i] + data.draw(st.sampled_from([0.5, 0.0, 1e-9])), "bool": True,
                 "high": data.draw(st.sampled_from([2**31, 2**33, 2**63, 2**70])),
                 "negative": -data.draw(st.integers(7, 2**40))}[kind]
    shape = np.shape(base["attach"] if arg == "attach" else good)
    bad = values.tolist() if kind == "high" and values[i] >= 2**63 else np.asarray(values.tolist()).reshape(shape)
    if kind == "bool":
        bad = np.zeros(shape, bool) if arg != "strand" else [True, False, True]
    exc = TypeError if kind in ("float", "bool") else ValueError  # probe allows −4..−1 (from the end): −7 and below
    refused(exc, arg, network, **{**base, arg: bad})


@FUZZ
@given(angle=st.floats(1e-4, 179.0), axis=st.sampled_from([0, 1]), node=st.sampled_from([0, 3]))
def test_tangents_not_along_their_chord(angle, axis, node):
    tangents = chain()["tangents"].copy()
    phi = np.deg2rad(angle)
    tangents[node] = [np.cos(phi), np.sin(phi) * (1 if axis else -1)]
    refused(ValueError, "tangents", network, tangents=tangents)


@FUZZ
@given(st.floats(1e-5, 10.0), st.sampled_from([-1, 1]))
def test_lengths_unequal_to_the_chord(delta, sign):
    lengths = chain()["lengths"] * (1 + sign * min(delta, 0.9))
    refused(ValueError, "lengths", network, lengths=lengths)


@FUZZ
@given(st.floats(-1e3, 1e3), st.floats(1e-3, 1e3), st.floats(0, 2 * np.pi), st.integers(2, 40))
def test_valid_straight_chains_build(offset, length, heading, n):
    """Straight chains anywhere, of any size and direction, pass the reference-state checks."""
    direction = [np.cos(heading), np.sin(heading)]
    net = network(**chain(n=n, direction=direction, origin=[offset, -offset], length=length))
    assert net.n_segments == n - 1


# ------------------------------------------------------------------ explicit cases of the issue
def _tangents(row, value):
    t = chain()["tangents"].copy()
    t[row] = value
    return t


def _free(i, value):
    fixed = list(chain()["fixed_directions"])
    fixed[i] = value
    return fixed


ZERO_OR_NONFINITE = [
    ("zero tangent", ValueError, "tangents", lambda: network(tangents=_tangents(2, [0.0, 0.0]))),
    ("NaN tangent", ValueError, "tangents", lambda: network(tangents=_tangents(1, [np.nan, 0.0]))),
    ("tangent of length 2", ValueError, "tangents", lambda: network(tangents=_tangents(1, [2.0, 0.0]))),
    ("tangent 2e-3 off unit", ValueError, "tangents", lambda: network(tangents=_tangents(1, [1 + 2e-3, 0.0]))),
    ("zero fixed direction", ValueError, "fixed_directions", lambda: network(fixed_directions=_free(0, np.zeros((1, 2))))),
    ("NaN fixed direction", ValueError, "fixed_directions", lambda: network(fixed_directions=_free(0, [[np.nan, 1.0]]))),
    ("inf fixed direction", ValueError, "fixed_directions", lambda: network(fixed_directions=_free(0, [[np.inf, 0.0]]))),
    ("3-vector in 2D", ValueError, "fixed_directions", lambda: network(fixed_directions=_free(0, np.eye(3)))),
    ("fixed_directions not a list", TypeError, "fixed_directions", lambda: network(fixed_directions=5)),
    ("zero probe_direction", ValueError, "probe_direction", lambda: network(probe=[3], probe_direction=[0.0, 0.0])),
    ("zero builder direction", ValueError, "direction", lambda: sj.cantilever(3, direction=(0, 0, 0))),
    ("NaN origin", ValueError, "origin", lambda: sj.column(3, origin=(0, np.nan, 0))),
]
INDICES = [
    ("fractional segment", TypeError, "segments", lambda: network(segments=[[0, 1], [1, 2.5], [2, 3]])),
    ("boolean segments", TypeError, "segments", lambda: network(segments=[[False, True], [True, 2], [2, 3]])),
    ("segment index 2**33", ValueError, "segments", lambda: network(segments=[[0, 1], [1, 2], [2, 2**33]])),
    ("fractional probe", TypeError, "probe", lambda: network(probe=[2.5])),
    ("boolean probe mask", TypeError, "probe", lambda: network(probe=[False, False, False, True])),
    ("probe 2**33", ValueError, "probe", lambda: network(probe=[2**33])),
    ("fractional attach", TypeError, "attach", lambda: network(**{**branched(), "attach": [(1.5, 4)]})),
    ("boolean attach", TypeError, "attach", lambda: network(**{**branched(), "attach": [(True, True)]})),
    ("attach 2**33", ValueError, "attach", lambda: network(**{**branched(), "attach": [(2**33, 4)]})),
    ("fractional strand", TypeError, "strand", lambda: network(strand=[0, 0.5, 1])),
    ("strand 2**33", ValueError, "strand", lambda: network(strand=[0, 2**33, 1])),
    ("clamped floats", TypeError, "clamped", lambda: network(clamped=[0.5, 0, 0, 0])),
    ("fractional load key", TypeError, "forces", lambda: sj.solve(sj.cantilever(3, dim=2), {1.5: [0.0, 1.0]})),
    ("boolean load key", TypeError, "forces", lambda: sj.solve(sj.cantilever(3, dim=2), {True: [0.0, 1.0]})),
    ("load key 2**33", ValueError, "forces", lambda: sj.solve(sj.cantilever(3, dim=2), {2**33: [0.0, 1.0]})),
    ("fractional couple key", TypeError, "couples", lambda: sj.solve(sj.cantilever(3, dim=2), couples={0.5: 1.0})),
    ("string force", TypeError, "forces", lambda: sj.solve(sj.cantilever(3, dim=2), {-1: ["a", "b"]})),
]
REFERENCE_STATE = [
    ("tangent perpendicular to chord", ValueError, "tangents", lambda: network(tangents=_tangents(1, [0.0, 1.0]))),
    ("tangents against the segments", ValueError, "tangents", lambda: network(tangents=-chain()["tangents"])),
    ("length unequal to chord", ValueError, "lengths", lambda: network(lengths=[0.5, 1 / 3, 1 / 3])),
    ("coincident nodes", ValueError, "positions", lambda: network(positions=np.array([[0, 0], [0, 0], [1, 0], [2, 0.0]]))),
    ("daughter parallel (0°)", ValueError, "attach", lambda: network(**branched(0.0))),
    ("daughter antiparallel (180°)", ValueError, "attach", lambda: network(**branched(180.0))),
    ("daughter at 0.05°", ValueError, "attach", lambda: network(**branched(0.05))),
    ("daughter away from its mother", ValueError, "positions",
     lambda: network(**{**branched(), "positions": branched()["positions"] + np.r_[np.zeros((4, 2)), [[0, 0.1]] * 2]})),
    ("closed ring", ValueError, "segments", lambda: sj.make_network(
        [[0, 0], [1, 0], [0.5, 0.8]], [[1, 0]] * 3, [[0, 1], [1, 2], [2, 0]], 1.0, 1.0, fixed_directions=[np.eye(2)] * 3)),
    ("two segments start at a node", ValueError, "segments", lambda: network(segments=[[0, 1], [1, 2], [3, 2]])),
    ("unit mesh at 0.01°", ValueError, "branch_angle", lambda: sj.unit_dendritic_mesh(branch_angle=0.01)),
    ("unit mesh at 179.99°", ValueError, "branch_angle", lambda: sj.unit_dendritic_mesh(branch_angle=179.99,
                                                                                          daughter_length=0.5)),
    ("outcrop at 0.05°", ValueError, "branch_angle", lambda: sj.dendritic_outcrop(branch_angle=0.05)),
]
SIZES = [
    ("unit mesh at 89.999999°", ValueError, "branch_angle", lambda: sj.unit_dendritic_mesh(branch_angle=89.999999)),
    ("unit mesh daughter_length 1e6", ValueError, "daughter_length",
     lambda: sj.unit_dendritic_mesh(branch_angle=89.99999, daughter_length=1e6)),
    ("unit mesh segment_length 1e-9", ValueError, "segment_length", lambda: sj.unit_dendritic_mesh(segment_length=1e-9)),
    ("unit mesh daughter_segments 10**9", ValueError, "daughter_segments",
     lambda: sj.unit_dendritic_mesh(daughter_segments=10**9)),
    ("column n_nodes 10**9", ValueError, "n_nodes", lambda: sj.column(10**9)),
    ("cantilever n_nodes 200,002", ValueError, "n_nodes", lambda: sj.cantilever(200_002)),
    ("outcrop segment_length 1e-7", ValueError, "segment_length", lambda: sj.dendritic_outcrop(segment_length=1e-7)),
    ("outcrop generations 10**6 (slow climb)", ValueError, "generations",
     lambda: sj.dendritic_outcrop(generations=10**6, branch_angle=89.9, dim=2)),
    ("PathSettings max_steps 10**7", ValueError, "max_steps", lambda: sj.PathSettings(max_steps=10**7)),
]
PERTURBATIONS = [
    ("unit mesh NaN", ValueError, "perturbation", lambda: sj.unit_dendritic_mesh(perturbation=np.nan)),
    ("unit mesh negative", ValueError, "perturbation", lambda: sj.unit_dendritic_mesh(perturbation=-1e-3)),
    ("unit mesh NaN jax array", ValueError, "perturbation", lambda: sj.unit_dendritic_mesh(perturbation=jnp.nan)),
    ("outcrop NaN", ValueError, "perturbation", lambda: sj.dendritic_outcrop(perturbation=np.nan)),
    ("outcrop negative", ValueError, "perturbation", lambda: sj.dendritic_outcrop(perturbation=-1.0)),
    ("strand_perturbation NaN", ValueError, "magnitude",
     lambda: sj.strand_perturbation(sj.unit_dendritic_mesh(dim=2), np.nan)),
    ("strand_perturbation seed -1", ValueError, "seed",
     lambda: sj.strand_perturbation(sj.unit_dendritic_mesh(dim=2), 1e-3, seed=-1)),
]
SETTINGS = [(f"PathSettings {f}={v}", TypeError if f in PATH_COUNTS and isinstance(v, float) else ValueError, f,
             (lambda f=f, v=v: sj.PathSettings(**{f: v})))
            for f in PATH_STEPS + PATH_COUNTS + ["grow"] for v in (0, -1, math.nan)] + [
    ("PathSettings max_steps=True", TypeError, "max_steps", lambda: sj.PathSettings(max_steps=True)),
    ("PathSettings max_iterations=2.0", TypeError, "max_iterations", lambda: sj.PathSettings(max_iterations=2.0)),
    ("PathSettings quadrature_order=40", ValueError, "quadrature_order", lambda: sj.PathSettings(quadrature_order=40)),
    ("PathSettings detect_critical_points=1", TypeError, "detect_critical_points",
     lambda: sj.PathSettings(detect_critical_points=1)),
    ("PathSettings initial_step > max_step", ValueError, "initial_step",
     lambda: sj.PathSettings(initial_step=0.5, max_step=0.1)),
    ("Parameter NaN value", ValueError, "value", lambda: sj.Parameter("EI", math.nan, "pN·µm²")),
    ("Parameter boolean bound", TypeError, "lower", lambda: sj.Parameter("EI", 1.0, "pN·µm²", lower=False)),
]
_COLUMN = sj.column(4, supports=("pinned", "pinned"))
SOLVER_ARGUMENTS = [
    ("solve throw='yes'", TypeError, "throw", lambda: sj.solve(sj.cantilever(3, dim=2), throw="yes")),
    ("solve model=3", TypeError, "model", lambda: sj.solve(sj.cantilever(3, dim=2), model=3)),
    ("solve model='fem'", ValueError, "model", lambda: sj.solve(sj.cantilever(3, dim=2), model="fem")),
    ("solve settings=dict", TypeError, "settings", lambda: sj.solve(sj.cantilever(3, dim=2), settings={})),
    ("solve network=str", TypeError, "network", lambda: sj.solve("net")),
    ("default_atol atol=NaN", ValueError, "atol", lambda: sj.default_atol(sj.cantilever(3), math.nan)),
    ("compress displacement NaN", ValueError, "displacement", lambda: sj.compress(_COLUMN, math.nan)),
    ("compress displacement inf", ValueError, "displacement", lambda: sj.compress(_COLUMN, math.inf)),
    ("compress displacement -0.1", ValueError, "displacement", lambda: sj.compress(_COLUMN, -0.1)),
    ("compress displacement >= gap", ValueError, "displacement", lambda: sj.compress(_COLUMN, 1.0)),
    ("compress displacement True", TypeError, "displacement", lambda: sj.compress(_COLUMN, True)),
    ("compress displacement '0.1'", TypeError, "displacement", lambda: sj.compress(_COLUMN, "0.1")),
    ("compress method unknown", ValueError, "method", lambda: sj.compress(_COLUMN, 0.1, method="newton")),
    ("compress perturbation NaN", ValueError, "perturbation", lambda: sj.compress(_COLUMN, 0.1, perturbation=math.nan)),
    ("compress perturbation < 0", ValueError, "perturbation", lambda: sj.compress(_COLUMN, 0.1, perturbation=-1.0)),
]
MESSAGES = [
    *[(f"{b} dim=2.0", TypeError, "dim", (lambda b=b: BUILDERS[b](dim=2.0))) for b in BUILDERS],
    ("outcrop seed=-1", ValueError, "seed", lambda: sj.dendritic_outcrop(seed=-1)),
    ("unit mesh branch_angle=179", ValueError, "branch_angle", lambda: sj.unit_dendritic_mesh(branch_angle=179)),
    ("outcrop branch_angle=179", ValueError, "branch_angle", lambda: sj.dendritic_outcrop(branch_angle=179)),
    ("column n_nodes=2.5", TypeError, "n_nodes", lambda: sj.column(2.5)),
    ("outcrop generations=-1", ValueError, "generations", lambda: sj.dendritic_outcrop(generations=-1)),
    ("column supports=None", TypeError, "supports", lambda: sj.column(3, supports=None)),
]
CASES = ZERO_OR_NONFINITE + INDICES + REFERENCE_STATE + SIZES + PERTURBATIONS + SETTINGS + SOLVER_ARGUMENTS + MESSAGES


@pytest.mark.parametrize(("case", "exc", "name", "call"), CASES, ids=[c[0] for c in CASES])
def test_issue_cases_are_refused_at_once(case, exc, name, call):
    refused(exc, name, call)


# compress checks its protocol options before any work (a bad ``parameters`` used to fail
# only after the whole run, when the result's metadata was written).
COMPRESS_OPTIONS = [
    ("parameters list", TypeError, "parameters", {"parameters": [1, 2]}),
    ("parameters object", TypeError, "parameters", {"parameters": object()}),
    ("parameters non-JSON value", ValueError, "parameters", {"parameters": {"a": object()}}),
    ("parameters NaN value", ValueError, "parameters", {"parameters": {"a": math.nan}}),
    ("parameters int key", TypeError, "parameters", {"parameters": {1: 2}}),
    ("unload 'yes'", TypeError, "unload", {"unload": "yes"}),
    ("throw 0", TypeError, "throw", {"throw": 0}),
    ("progress 5", TypeError, "progress", {"progress": 5}),
    ("method 5", TypeError, "method", {"method": 5}),
]


@pytest.mark.parametrize(("case", "exc", "name", "kwargs"), COMPRESS_OPTIONS, ids=[c[0] for c in COMPRESS_OPTIONS])
def test_compress_refuses_bad_options_before_running(case, exc, name, kwargs):
    refused(exc, name, sj.compress, _COLUMN, 0.1, **kwargs)


# ------------------------------------------------------------------ valid inputs still build
VALID = [
    *[(f"column {s} {d}D", lambda s=s, d=d: sj.column(5, supports=s, dim=d))
      for s in [("clamped", "free"), ("pinned", "pinned"), ("clamped", "pinned"), ("clamped", "clamped")] for d in (2, 3)],
    ("cantilever along (1, 2, 3) at an offset", lambda: sj.cantilever(7, direction=(1, 2, 3), origin=(10, -5, 3))),
    ("cantilever numpy ints and 0-d arrays", lambda: sj.cantilever(np.int64(4), length=np.array(2.0), dim=np.int32(2))),
    ("cantilever jax scalars", lambda: sj.cantilever(4, length=jnp.asarray(2.0), EI=jnp.asarray(0.5))),
    *[(f"unit mesh {a}° {d}D", lambda a=a, d=d: sj.unit_dendritic_mesh(branch_angle=a, dim=d))
      for a in (0.1, 20.0, 70.0, 89.9) for d in (2, 3)],
    ("unit mesh 179.9° with daughter_length", lambda: sj.unit_dendritic_mesh(branch_angle=179.9, daughter_length=0.3)),
    ("unit mesh 120° with daughter_segments", lambda: sj.unit_dendritic_mesh(branch_angle=120, daughter_length=1,
                                                                            daughter_segments=3)),
    *[(f"outcrop {g} generations {d}D seed {s}", lambda g=g, d=d, s=s: sj.dendritic_outcrop(generations=g, dim=d, seed=s,
                                                                                           perturbation=0.0))
      for g in (1, 4, 8) for d in (2, 3) for s in (0, 5)],
    ("outcrop at 0.1° and 89.9°", lambda: [sj.dendritic_outcrop(generations=3, branch_angle=a, perturbation=0.0)
                                           for a in (0.1, 89.9)]),
    ("outcrop that stops growing early", lambda: sj.dendritic_outcrop(generations=10**9, gap=2.0, perturbation=0.0)),
    ("make_network tangents 1e-7 off unit", lambda: network(tangents=chain()["tangents"] * (1 + 1e-7))),
    ("make_network dependent fixed directions", lambda: network(fixed_directions=_free(0, [[1, 0], [0, 1], [1, 1.0]]))),
    ("make_network single attach pair", lambda: network(**{**branched(), "attach": (1, 4)})),
    ("make_network negative probe index", lambda: network(probe=[-1])),
    ("PathSettings all given", lambda: sj.PathSettings(initial_step=0.1, min_step=1e-6, max_step=0.1, max_steps=10,
                                                       grow=1.0, max_turn=math.pi, quadrature_order=16)),
]


@pytest.mark.parametrize(("case", "build"), VALID, ids=[c[0] for c in VALID])
def test_valid_inputs_still_build(case, build):
    build()


def test_traced_values_skip_the_value_checks():
    """Traced positions/tangents cannot be checked: the network builds inside jax.jit."""
    args = chain()
    tangents = args.pop("tangents")

    @jax.jit
    def total(t):
        return sj.make_network(args["positions"], t, args["segments"], args["lengths"], 1.0,
                               fixed_directions=args["fixed_directions"], clamped=args["clamped"]).tangents.sum()

    assert float(total(tangents)) == pytest.approx(4.0)
    length = jax.jit(lambda L: sj.cantilever(3, length=L, dim=2).lengths.sum())(2.0)
    assert float(length) == pytest.approx(2.0)
    with pytest.raises(TypeError, match="segments fixes the network's topology"):
        jax.jit(lambda s: network(segments=s).EI)(jnp.asarray(args["segments"]))


def test_normalised_tangents_are_unit():
    net = network(tangents=chain()["tangents"] * (1 + 5e-7))
    np.testing.assert_allclose(np.linalg.norm(np.asarray(net.tangents), axis=1), 1.0, rtol=1e-15)


def test_hand_typed_unit_tangents_are_accepted_and_normalised():
    """(0.7071, 0.7071) is 1e-5 short of unit: accepted (within 1e-3) and normalised."""
    s = 0.7071
    direction = np.array([s, s]) / np.hypot(s, s)
    positions = np.outer(np.linspace(0.0, 1.0, 3), direction)
    net = sj.make_network(positions, np.tile([s, s], (3, 1)), [[0, 1], [1, 2]], 0.5, 1.0,
                          fixed_directions=[np.eye(2), np.zeros((0, 2)), np.zeros((0, 2))], clamped=[True, False, False])
    np.testing.assert_allclose(np.linalg.norm(np.asarray(net.tangents), axis=1), 1.0, rtol=0, atol=1e-15)
