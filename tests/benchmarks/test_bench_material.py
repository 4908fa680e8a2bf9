"""Benchmarks of the stress update (pytest-benchmark).

A hopper-like mix of 100,000 states (2,000 when benchmarks are disabled and these run once as
plain tests): admissible stresses at 0.1-30 kPa, with mostly deviatoric strain increments that
leave about 43 % of them elastic, return 52 % to the yield surface and send 5 % in tension to the
apex (or into the rounded tip of G).  And the flowing cells of a discharging hopper, where almost
every point is plastic at every step: stresses on the yield surface at 0.1-20 kPa and strain
increments of 1e-5 to 3e-3, about 90 % of them plastic.  Run with
``pytest tests/benchmarks/test_bench_material.py --benchmark-only -p no:cacheprovider -o addopts=""``.
"""

import numpy as np
import pytest

from fipy_hopper.material import (APEX, ELASTIC, PLASTIC, MohrCoulomb, R_mc, elastic_trial,
                                  invariants, update, update_reference, yield_function)

MATERIALS = {
    "c=0,psi=0": MohrCoulomb(E=5e6, nu=0.3, rho=1600.0, phi=32.0),
    "c=20Pa,psi=5": MohrCoulomb(E=5e6, nu=0.3, rho=1600.0, phi=32.0, psi=5.0, c=20.0),
}


def hopper_mix(mat, n, seed=0):
    """(sigma, d_eps) of n points: 42 % small increments (0.02 p/E), 58 % large (2 p/E), of
    which 5 % of all points expand (20x, volumetric) into tension."""
    rng = np.random.default_rng(seed)
    p0 = 10.0 ** rng.uniform(2.0, 4.5, n)
    sig = np.zeros((n, 4))
    sig[:, :3] = -p0[:, None] * (1.0 + 0.3 * rng.normal(size=(n, 3)))
    sig[:, 3] = 0.3 * p0 * rng.normal(size=n)
    sig, _ = update(sig, np.zeros_like(sig), mat)  # admissible starting states
    kind = rng.uniform(size=n)
    de = rng.normal(size=(n, 4)) * (p0 / mat.E)[:, None] * np.where(kind < 0.42, 0.02, 2.0)[:, None]
    de[:, :3] -= de[:, :3].mean(-1, keepdims=True) + 0.2 * np.abs(de[:, :3]).mean(-1, keepdims=True)
    tension = kind > 0.95  # expansion: the apex, or the tip of G
    de[tension, :3] = np.abs(de[tension, :3]) * 20.0
    return sig, de


def flowing_mix(mat, n, seed=0, loading=0.8):
    """(sigma, d_eps) of n flowing cells: stresses on the yield surface (p = 0.1-20 kPa, Lode
    angle uniform, random axes and hoop position) and strain increments of 1e-5 to 3e-3
    (log-uniform), deviatoric with a small volumetric part, signed to load (leave the yield
    surface) in a fraction ``loading`` of the points and to unload in the others where that is
    possible (a large increment loads either way): about 90 % plastic, 9 % elastic, 1 % apex."""
    rng = np.random.default_rng(seed)
    p = 10.0 ** rng.uniform(2.0, np.log10(2e4), n)
    theta = rng.uniform(0.0, np.pi / 3, n)
    q = (p * np.tan(mat.phi_rad) + mat.c) / R_mc(theta, mat.phi_rad)  # F = 0
    s = np.stack([-p + 2.0 / 3.0 * q * np.cos(theta - a)
                  for a in (0.0, 2 * np.pi / 3, -2 * np.pi / 3)], -1)
    s = rng.permuted(s, axis=-1)  # the hoop stress in any position
    w = rng.uniform(0.0, np.pi, n)  # in-plane axes
    m, h = 0.5 * (s[:, 0] + s[:, 1]), 0.5 * (s[:, 0] - s[:, 1])
    sig = np.stack([m + h * np.cos(2 * w), m - h * np.cos(2 * w), s[:, 2], h * np.sin(2 * w)], -1)
    de = rng.normal(size=(n, 4))
    de[:, :3] -= de[:, :3].mean(-1, keepdims=True) + 0.01 * rng.normal(size=(n, 1))
    de *= (10.0 ** rng.uniform(-5.0, np.log10(3e-3), n) / np.abs(de).max(-1))[:, None]
    f_plus = yield_function(elastic_trial(sig, de, mat), mat)
    f_minus = yield_function(elastic_trial(sig, -de, mat), mat)
    load = rng.uniform(size=n) < loading
    flip = np.where(load, (f_plus <= 0.0) & (f_minus > 0.0), (f_plus > 0.0) & (f_minus <= 0.0))
    de[flip] *= -1.0
    return sig, de


def size(benchmark):
    return 2_000 if benchmark.disabled else 100_000


def check(mat, sig_new, status):
    p = invariants(sig_new)[0]
    assert np.isfinite(sig_new).all()
    assert (yield_function(sig_new, mat) <= 1e-8 * np.maximum(p + mat.apex_stress, 1.0)).all()
    frac = np.bincount(status, minlength=3) / status.size
    assert 0.3 < frac[ELASTIC] < 0.7 and 0.3 < frac[PLASTIC] < 0.7 and frac[APEX] > 0.01
    return frac


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_bench_update(benchmark, name):
    mat = MATERIALS[name]
    sig, de = hopper_mix(mat, size(benchmark))
    update(sig[:8], de[:8], mat)  # compile (or load from the cache) outside the timing
    sig_new, _, status = benchmark(update, sig, de, mat, True)
    frac = check(mat, sig_new, status)
    benchmark.extra_info.update(n=len(sig), elastic=frac[0], plastic=frac[1], apex=frac[2])
    if not benchmark.disabled:
        benchmark.extra_info["updates_per_second"] = len(sig) / benchmark.stats.stats.mean


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_bench_update_reference(benchmark, name):
    mat = MATERIALS[name]
    sig, de = hopper_mix(mat, size(benchmark))
    sig_new, _, status = benchmark(update_reference, sig, de, mat, True)
    frac = check(mat, sig_new, status)
    if not benchmark.disabled:
        benchmark.extra_info["updates_per_second"] = len(sig) / benchmark.stats.stats.mean


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_bench_update_flowing(benchmark, name):
    """The flowing cells of a discharging hopper: about 90 % plastic returns."""
    mat = MATERIALS[name]
    sig, de = flowing_mix(mat, size(benchmark))
    update(sig[:8], de[:8], mat)  # compile (or load from the cache) outside the timing
    sig_new, _, status = benchmark(update, sig, de, mat, True)
    p = invariants(sig_new)[0]
    assert np.isfinite(sig_new).all()
    assert (yield_function(sig_new, mat) <= 1e-8 * np.maximum(p + mat.apex_stress, 1.0)).all()
    frac = np.bincount(status, minlength=3) / status.size
    assert frac[PLASTIC] > 0.85 and frac[APEX] < 0.03
    benchmark.extra_info.update(n=len(sig), elastic=frac[0], plastic=frac[1], apex=frac[2])
    if not benchmark.disabled:
        benchmark.extra_info["ns_per_plastic_point"] = (
            1e9 * benchmark.stats.stats.mean / max((status != ELASTIC).sum(), 1))
