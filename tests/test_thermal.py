"""Thermal stress-free shapes (``sj.thermal_network``) against the worm-like chain's exact
statistics in the plane: the tangent angle is a Brownian motion in arc length, so each
segment's turn is N(0, l/Lp), independent of the others, and ⟨cos(θ(s) − θ(0))⟩ =
exp(−s / 2Lp), with Lp = EI / k_B T."""

import numpy as np
import pytest

import socbjax as sj

KB_J_PER_K = 1.380649e-23  # CODATA (exact SI); 1 pN·µm = 1e-18 J


def test_persistence_length_is_EI_over_kT():
    assert sj.persistence_length(0.071, 298.0) == pytest.approx(0.071 * 1e-18 / (KB_J_PER_K * 298.0), rel=1e-12)
    assert 17.0 < sj.persistence_length(0.071) < 17.5  # actin at room temperature (measured: 17.7 ± 1.1 µm)


def turns(net):
    return np.asarray(net.natural_curvature) * np.asarray(net.lengths)


def test_turn_variance_is_l_over_Lp_and_turns_are_independent():
    EI, T, l = 0.02, 300.0, 0.25
    Lp = EI * 1e-18 / (KB_J_PER_K * T)  # 4.83 µm
    chain = sj.cantilever(101, length=100 * l, EI=EI, dim=2)
    samples = np.concatenate([turns(sj.thermal_network(chain, temperature=T, seed=k)) for k in range(60)])
    N = samples.size  # 6000 turns
    var = np.mean(samples**2)
    assert abs(var / (l / Lp) - 1.0) < 4 * np.sqrt(2.0 / N)  # 4 standard errors of a variance
    assert abs(np.mean(samples)) < 4 * np.sqrt(l / Lp / N)
    per_chain = samples.reshape(60, 100)
    lag1 = np.mean(per_chain[:, 1:] * per_chain[:, :-1]) / var
    assert abs(lag1) < 4 / np.sqrt(60 * 99)


def test_tangent_correlation_decays_as_exp_minus_s_over_2Lp():
    EI, T = 0.01, 298.0
    Lp = EI * 1e-18 / (KB_J_PER_K * T)  # 2.43 µm
    chain = sj.cantilever(61, length=6.0, EI=EI, dim=2)  # 2.5 Lp in 0.1 µm segments
    cosines = []
    for seed in range(300):
        t = np.asarray(sj.thermal_network(chain, temperature=T, seed=seed).tangents)
        cosines.append(t @ t[0])  # cos(θ(s) − θ(0)) at every node
    cosines = np.array(cosines)
    s = np.linspace(0.0, 6.0, 61)
    mean, se = cosines.mean(axis=0), cosines.std(axis=0, ddof=1) / np.sqrt(len(cosines))
    z = (mean - np.exp(-s / (2 * Lp)))[1:] / se[1:]
    assert np.all(np.abs(z) < 4.5), np.abs(z).max()
    assert mean[-1] < 0.5  # the strand really decorrelates (expected 0.29)


def test_in_3d_the_bending_angle_has_mean_square_2l_over_Lp_and_tangents_decorrelate_as_exp_minus_s_over_Lp():
    EI, T = 0.01, 298.0
    Lp = EI * 1e-18 / (KB_J_PER_K * T)  # 2.43 µm
    chain = sj.cantilever(61, length=6.0, EI=EI, dim=3, GJ=0.01)
    bends, cosines = [], []
    for seed in range(200):
        net = sj.thermal_network(chain, temperature=T, seed=seed)
        t = np.asarray(net.tangents)
        bends.append(np.arccos(np.clip(np.sum(t[1:] * t[:-1], axis=1), -1, 1)))  # bending angle per segment
        cosines.append(t @ t[0])
    bends, cosines = np.concatenate(bends), np.array(cosines)
    l = 0.1
    # ⟨θ²⟩ = 2l/Lp; the arc's exact angle is the norm of the two Gaussian bending angles
    assert abs(np.mean(bends**2) / (2 * l / Lp) - 1) < 4 / np.sqrt(bends.size)  # θ²: exponential, rel. SE 1/√N
    s = np.linspace(0.0, 6.0, 61)
    mean, se = cosines.mean(axis=0), cosines.std(axis=0, ddof=1) / np.sqrt(len(cosines))
    z = (mean - np.exp(-s / Lp))[1:] / se[1:]
    assert np.all(np.abs(z) < 4.5), np.abs(z).max()
    assert mean[-1] < 0.2  # decorrelated (expected 0.085)


def test_thermal_shapes_are_seeded_stress_free_and_keep_the_network():
    mesh = sj.unit_dendritic_mesh(dim=2)
    a, b = sj.thermal_network(mesh, seed=3), sj.thermal_network(mesh, seed=3)
    np.testing.assert_array_equal(a.positions, b.positions)
    assert not np.array_equal(a.positions, sj.thermal_network(mesh, seed=4).positions)
    assert a.topology == mesh.topology
    sol = sj.solve(a)
    np.testing.assert_allclose(sol.positions, a.positions, atol=1e-12)
    np.testing.assert_allclose(sol.moments, 0.0, atol=1e-12)


def test_bad_thermal_inputs_are_refused_with_the_fix():
    with pytest.raises(ValueError, match="shorter than"):
        sj.thermal_network(sj.cantilever(3, length=2.0, EI=1e-4, dim=2))  # l = 40 Lp
    with pytest.raises(ValueError, match="GJ"):  # a curved 3D rod needs its material frame
        sj.thermal_network(sj.cantilever(3, dim=3))
    with pytest.raises(ValueError, match="temperature"):
        sj.thermal_network(sj.cantilever(3, dim=2), temperature=-1.0)
    with pytest.raises(TypeError, match="seed"):
        sj.thermal_network(sj.cantilever(3, dim=2), seed=1.5)
    with pytest.raises(TypeError, match="Network"):
        sj.thermal_network("mesh.h5")
