"""Property-based tests (hypothesis, derandomised) of the Mohr–Coulomb stress update.

Each example draws a material over the whole admissible parameter range and a seed from which a
batch of trial states is built (compression and tension, hydrostatic and zero stresses, strain
increments from 1e-9 to 10), so every example checks many updates at once.
"""

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fipy_hopper.material import (
    APEX,
    ELASTIC,
    PLASTIC,
    MohrCoulomb,
    elastic_trial,
    flow_direction,
    invariants,
    plastic_strain_from_stress,
    update,
    update_reference,
    yield_function,
)

SETTINGS = settings(derandomize=True, database=None, max_examples=200, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])
W = np.array([1.0, 1.0, 1.0, 2.0])
N = 64


@st.composite
def materials(draw):
    phi = draw(st.floats(0.5, 89.5))
    psi = phi * draw(st.one_of(st.just(0.0), st.floats(0.0, 1.0)))
    return MohrCoulomb(
        E=draw(st.floats(1e5, 1e9)),
        nu=draw(st.floats(-0.9, 0.49)),
        rho=1500.0,
        phi=phi,
        psi=psi,
        c=draw(st.one_of(st.just(0.0), st.floats(1e-3, 1e4))),
        eps=draw(st.floats(0.01, 2.0)),
        e=draw(st.one_of(st.none(), st.floats(0.51, 1.0))),
    )


@st.composite
def batches(draw):
    """(sigma, d_eps): N states at stress level 10^[-2, 7] Pa, strain level 10^[-9, 1]."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    level = 10.0 ** draw(st.floats(-2.0, 7.0))
    strain = 10.0 ** draw(st.floats(-9.0, 1.0))
    sig = rng.normal(size=(N, 4)) * level - level * draw(st.floats(-1.0, 3.0)) * np.array([1, 1, 1, 0])
    sig[: N // 8] = 0.0
    sig[N // 8: N // 4, :3] = sig[N // 8: N // 4, :1]  # hydrostatic
    sig[N // 8: N // 4, 3] = 0.0
    de = rng.normal(size=(N, 4)) * strain
    de[N // 4: N // 3] = 0.0
    de[N // 3: N // 2, 1:3] = de[N // 3: N // 2, :1]  # volumetric
    de[N // 3: N // 2, 3] = 0.0
    return sig, de


def resolved(trial, sig_new, status):
    """Plastic returns whose increment is above the round-off of the trial stress."""
    scale = np.abs(trial).max(-1)
    return (status == PLASTIC) & (np.abs(trial - sig_new).max(-1) > 1e-7 * scale)


@SETTINGS
@given(materials(), batches())
def test_consistency_and_no_nan(mat, batch):
    sig, de = batch
    sig_new, dep, status = update(sig, de, mat, return_status=True)
    assert np.isfinite(sig_new).all() and np.isfinite(dep).all()
    p = invariants(sig_new)[0]
    assert (yield_function(sig_new, mat) <= 1e-8 * np.maximum(p + mat.apex_stress, 1.0)).all()
    trial = elastic_trial(sig, de, mat)
    np.testing.assert_allclose(dep, plastic_strain_from_stress(trial - sig_new, mat), rtol=1e-9,
                               atol=1e-15 * np.abs(trial).max() / mat.shear_modulus)


@SETTINGS
@given(materials(), batches())
def test_elastic_states_untouched_and_apex_exact(mat, batch):
    sig, de = batch
    sig_new, dep, status = update(sig, de, mat, return_status=True)
    trial = elastic_trial(sig, de, mat)
    el = yield_function(trial, mat) < -1e-12 * np.abs(trial).max(-1)  # safely inside
    assert (status[el] == ELASTIC).all()
    elastic = status == ELASTIC
    assert (sig_new[elastic] == trial[elastic]).all() and (dep[elastic] == 0.0).all()
    apex = status == APEX
    assert (sig_new[apex] == mat.apex_stress * np.array([1.0, 1.0, 1.0, 0.0])).all()
    if mat.c == 0.0:
        assert (sig_new[apex] == 0.0).all()


@SETTINGS
@given(materials(), batches())
def test_plastic_increment_parallel_to_flow_direction(mat, batch):
    sig, de = batch
    sig_new, dep, status = update(sig, de, mat, return_status=True)
    well = resolved(elastic_trial(sig, de, mat), sig_new, status)
    n = flow_direction(sig_new[well], mat)
    d = dep[well]
    cos = (d * n * W).sum(-1) / np.sqrt((d * d * W).sum(-1) * (n * n * W).sum(-1))
    assert (cos > 1.0 - 1e-8).all(), cos.min()


@SETTINGS
@given(materials(), batches())
def test_compiled_update_equals_reference(mat, batch):
    sig, de = batch
    a = update(sig, de, mat, return_status=True)
    b = update_reference(sig, de, mat, return_status=True)
    trial = elastic_trial(sig, de, mat)
    well = resolved(trial, a[0], a[2]) | (a[2] == ELASTIC)
    assert (a[2][well] == b[2][well]).all()
    scale = np.abs(trial).max(-1, keepdims=True)
    assert (np.abs(a[0] - b[0])[well] <= 1e-10 * scale[well]).all()


@SETTINGS
@given(materials(), batches(), st.floats(0.0, 2.0 * math.pi))
def test_update_is_objective_under_rotation_in_the_rz_plane(mat, batch, angle):
    """Rotating the trial by Q in the (r, z) plane rotates the result (isotropy of F and G)."""
    sig, de = batch

    def rotate(t):
        c, s = math.cos(angle), math.sin(angle)
        rr, zz, tt, rz = t.T
        return np.stack([c * c * rr + s * s * zz - 2 * c * s * rz, s * s * rr + c * c * zz + 2 * c * s * rz,
                         tt, c * s * (rr - zz) + (c * c - s * s) * rz], -1)

    a, dep_a, st_a = update(sig, de, mat, return_status=True)
    b, dep_b, st_b = update(rotate(sig), rotate(de), mat, return_status=True)
    trial = elastic_trial(sig, de, mat)
    well = resolved(trial, a, st_a) | (st_a == APEX) | (st_a == ELASTIC)
    well &= np.abs(yield_function(trial, mat)) > 1e-9 * np.abs(trial).max(-1)  # not on the boundary
    scale = np.abs(trial).max(-1, keepdims=True)
    assert (np.abs(rotate(a) - b)[well] <= 1e-9 * scale[well]).all()
