"""Ensembles (socbjax.compress_ensemble): one vmapped, compiled continuation for a batch of
networks of equal structure equals the member-by-member compressions; physics through the
batch (F ∝ EI, the elastica of a column); input errors; sharding over 2 host devices."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import equinox as eqx
import numpy as np
import pytest

import socbjax as sj

ROOT = Path(__file__).resolve().parents[1]
SCALES = (0.5, 1.0, 2.0)
KW = dict(unload=True, settings=sj.PathSettings(max_steps=200))


def _outcrop():
    return sj.dendritic_outcrop(generations=3, gap=3.0, seed=0, dim=2, perturbation=0.0)


def _scaled(net, scales):
    return [eqx.tree_at(lambda n: n.EI, net, net.EI * s) for s in scales]


@pytest.fixture(scope="module")
def outcrop_ensemble():
    nets = _scaled(_outcrop(), SCALES)
    return nets, sj.compress_ensemble(nets, 0.45, **KW)  # a node reaches the surface at u ≈ 0.47 µm


def test_members_equal_sequential_compress(outcrop_ensemble):
    """Each member of the vmapped batch is the sequential compress of that member: same steps,
    forces and displacements to round-off."""
    nets, ens = outcrop_ensemble
    assert ens.completed.all() and len(ens) == len(nets)
    assert ens.force.shape == ens.displacement.shape == (len(nets), ens.n_steps.max())
    for i, net in enumerate(nets):
        ref, got = sj.compress(net, 0.45, **KW), ens.member(i)
        assert got.n_steps == ref.n_steps == ens.n_steps[i]
        np.testing.assert_allclose(got.force, ref.force, rtol=1e-10, atol=1e-10 * np.abs(ref.force).max())
        np.testing.assert_allclose(got.displacement, ref.displacement, rtol=1e-10, atol=1e-12)
        np.testing.assert_array_equal(got.phase, ref.phase)
        np.testing.assert_array_equal(got.stable, ref.stable)
        assert got.positions.shape == ref.positions.shape
        assert [p.kind for p in got.limit_points] == [p.kind for p in ref.limit_points]
        np.testing.assert_allclose(ens.force[i, : ens.n_steps[i]], ref.force, rtol=1e-10, atol=1e-14)
        assert np.isnan(ens.force[i, ens.n_steps[i]:]).all()


def test_force_scales_with_EI(outcrop_ensemble):
    """The residual is linear in EI and the default perturbation is ∝ EI: scaling EI scales the
    force at the same displacement, along the same path."""
    _, ens = outcrop_ensemble
    assert len(set(ens.n_steps.tolist())) == 1
    F = ens.force / np.asarray(SCALES)[:, None]
    np.testing.assert_allclose(F, F[[1]].repeat(len(SCALES), 0), rtol=1e-9, atol=1e-12 * np.abs(F).max())
    np.testing.assert_allclose(ens.displacement, ens.displacement[[1]].repeat(len(SCALES), 0), atol=1e-12)


@pytest.mark.slow  # suite time; in the default suite: no-retrace checks: tests/test_tracing.py
def test_new_values_do_not_recompile(outcrop_ensemble, traces):
    """All phases share one compiled program; new EI, loads and displacement reuse it, a new
    batch size traces once more (which shows that the counter is live)."""
    nets = _scaled(_outcrop(), (0.7, 1.3, 3.0))
    nets[1] = nets[1].replace(loads=sj.strand_perturbation(nets[1], 2e-4))
    before = len(traces)
    assert sj.compress_ensemble(nets, 0.4, **KW).completed.all()
    assert "_phase" not in traces[before:], traces[before:]
    assert sj.compress_ensemble(nets[:2], 0.4, **KW).completed.all()
    assert "_phase" in traces[before:]


def _pinned_pinned_force(shortening, L, EI):
    """Closed-form elastica (first mode): Δ/L = 2(1 − E(k)/K(k)), P = 4 K(k)² EI/L²."""
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipk

    def root(d):
        return brentq(lambda m: 2 * (1 - ellipe(m) / ellipk(m)) - d / L, 1e-14, 0.999)

    m = [root(d) for d in shortening]
    return 4 * ellipk(np.asarray(m)) ** 2 * EI / L**2


def test_column_members_follow_the_elastica():
    """Columns of different length and EI (same topology) in one batch: each member follows
    its own exact elastica past the Euler load."""
    params = [(1.0, 0.071), (1.2, 0.05), (0.9, 0.1)]
    nets = [sj.column(5, supports=("pinned", "pinned"), dim=2, length=L, EI=EI) for L, EI in params]
    ens = sj.compress_ensemble(nets, 0.2)
    assert ens.completed.all()
    for (L, EI), r in zip(params, ens.results):
        mask = (r.phase == 1) & (r.displacement > 0.02 * r.displacement.max())
        u, F = r.displacement[mask], r.force[mask]
        np.testing.assert_allclose(F, _pinned_pinned_force(u, L, EI), rtol=5e-4)
        assert F.min() > np.pi**2 * EI / L**2 * (1 - 1e-3)  # at or above the Euler load


@pytest.mark.slow
def test_progress_runs_in_chunks_with_the_same_curves(capsys):
    nets = [sj.column(5, supports=("pinned", "pinned"), dim=2, EI=EI) for EI in (0.05, 0.1)]
    plain = sj.compress_ensemble(nets, 0.2)
    chunked = sj.compress_ensemble(nets, 0.2, progress=True)  # 25-step chunks of the while-loop
    assert "loading: 2/2 members done" in capsys.readouterr().err
    np.testing.assert_array_equal(plain.n_steps, chunked.n_steps)
    np.testing.assert_allclose(chunked.force, plain.force, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(chunked.attempts, plain.attempts)  # [B, phases]: work per member
    assert (plain.attempts.sum(axis=1) >= plain.n_steps - 1).all()  # every recorded step was attempted
    assert (plain.newton_iterations >= 0).all() and (plain.newton_iterations[:, 1] > 0).all()  # (a linear settle may need none)


def test_failed_members_raise_or_report():
    nets = [sj.column(5, supports=("pinned", "pinned"), dim=2, EI=EI) for EI in (0.05, 0.1)]
    settings = sj.PathSettings(max_steps=4)
    with pytest.raises(sj.ConvergenceError, match=r"2 of 2 members did not complete.*member 0.*member 1") as info:
        sj.compress_ensemble(nets, 0.2, settings=settings)
    ens = info.value.result
    assert not ens.completed.any() and all(r.result == sj.RESULTS.max_steps for r in ens.results)
    again = sj.compress_ensemble(nets, 0.2, settings=settings, throw=False)
    assert all(r.result == sj.RESULTS.max_steps for r in again.results) and (again.n_steps <= 5).all()


def test_input_errors():
    col = sj.column(5, supports=("pinned", "pinned"), dim=2)
    with pytest.raises(ValueError, match="empty"):
        sj.compress_ensemble([], 0.1)
    with pytest.raises(TypeError, match="sequence"):
        sj.compress_ensemble(col, 0.1)
    with pytest.raises(TypeError, match="member 1"):
        sj.compress_ensemble([col, "column"], 0.1)
    with pytest.raises(ValueError, match=r"member 1 differs from member 0 in its topology \(segments\)"):
        sj.compress_ensemble([col, sj.column(6, supports=("pinned", "pinned"), dim=2)], 0.1)
    with pytest.raises(ValueError, match=r"member 1 differs from member 0 in its topology \(clamped\)"):
        sj.compress_ensemble([col, sj.column(5, supports=("clamped", "pinned"), dim=2)], 0.1)
    with pytest.raises(ValueError, match=r"one per member \(2\)"):
        sj.compress_ensemble([col, col], 0.1, perturbation=[1e-4, 1e-4, 1e-4])
    with pytest.raises(ValueError, match="member 1: perturbation must be a non-negative"):
        sj.compress_ensemble([col, col], 0.1, perturbation=[1e-4, -1.0])
    short = sj.column(5, supports=("pinned", "pinned"), dim=2, length=0.5)
    with pytest.raises(ValueError, match="member 1: displacement 0.6 µm reaches the opposing support"):
        sj.compress_ensemble([col, short], 0.6)
    with pytest.raises(ValueError, match="devices"):
        sj.compress_ensemble([col], 0.1, devices=99)


_SHARDED = textwrap.dedent("""
    import json, sys, jax, numpy as np, equinox as eqx, socbjax as sj
    if sys.argv[1] == "dense":  # a 2-D outcrop, 3 members padded to 4
        net = sj.dendritic_outcrop(generations=3, gap=3.0, seed=0, dim=2, perturbation=0.0)
        nets, u, kw = [eqx.tree_at(lambda n: n.EI, net, net.EI * s) for s in (0.5, 1.0, 2.0)], 0.45, {}
    else:  # the sparse LU is a jax.pure_callback: it must run on every device too
        nets = [sj.column(5, supports=("pinned", "pinned"), dim=2, EI=EI) for EI in (0.05, 0.07, 0.1)]
        u, kw = 0.2, dict(settings=sj.PathSettings(linear_solver="sparse"))
    one = sj.compress_ensemble(nets, u, unload=True, **kw)
    two = sj.compress_ensemble(nets, u, unload=True, devices=jax.devices(), **kw)
    print(json.dumps(dict(n_devices=len(jax.devices()), devices=list(two.devices), one_devices=list(one.devices),
                          same_steps=bool((one.n_steps == two.n_steps).all()),
                          completed=bool(one.completed.all() and two.completed.all()),
                          force=float(np.nanmax(np.abs(one.force - two.force)) / np.nanmax(np.abs(one.force))),
                          displacement=float(np.nanmax(np.abs(one.displacement - two.displacement))))))
""")


@pytest.mark.slow
@pytest.mark.parametrize("solver", ["dense", "sparse"])
def test_sharded_over_two_host_devices_equals_unsharded(solver):
    """The batch split over 2 host devices (jax.shard_map) gives the unsharded numbers; the
    device count must be fixed before jax starts, hence the subprocess."""
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_ENABLE_X64="1",
               OPENBLAS_NUM_THREADS="1", PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    out = subprocess.run([sys.executable, "-c", _SHARDED, solver], check=False, env=env, capture_output=True, text=True, timeout=600,
                         cwd=ROOT)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-3000:]
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["n_devices"] == 2 and len(res["devices"]) == 2 and len(res["one_devices"]) == 1, res
    assert res["completed"] and res["same_steps"], res
    assert res["force"] <= 1e-12 and res["displacement"] <= 1e-12, res
