"""The axisymmetric Q1 momentum kernels: equilibrium, consistency with transport, contact."""

import numpy as np
import pytest
from fipy import CylindricalGrid2D

from fipy_hopper import momentum

H = 0.01
NR, NZ = 6, 8
R_C = H * (np.arange(NR) + 0.5)
VOL = np.repeat((R_C * H * H)[None, :], NZ, axis=0)


def interior(a):
    return a[..., 1:-1, 1:-1]


def test_uniform_pressure_is_in_equilibrium():
    """sigma = -p I gives zero net force at interior nodes (hoop term balances d(r s_rr)/dr)."""
    stress = np.zeros((NZ, NR, 4))
    stress[..., :3] = -1234.0
    f = momentum.internal_force(stress, VOL, R_C, H)
    assert np.max(np.abs(interior(f))) < 1e-12 * 1234 * H * H
    # and on the axis nodes the radial force is irrelevant (v_r = 0) but the axial one vanishes
    assert np.max(np.abs(f[1, 1:-1, 0])) < 1e-12 * 1234 * H * H


def test_hydrostatic_column_balances_gravity_exactly():
    rho, g, top = 1500.0, 9.81, NZ * H
    z_c = H * (np.arange(NZ) + 0.5)
    stress = np.zeros((NZ, NR, 4))
    for k in (0, 1, 2):
        stress[..., k] = (-rho * g * (top - z_c))[:, None]
    f = momentum.internal_force(stress, VOL, R_C, H)
    m = momentum.node_mass(rho, np.ones((NZ, NR)), VOL)
    residual = -f[1] - m * g
    assert np.max(np.abs(interior(residual))) < 1e-10 * np.max(m * g)


def test_divergence_of_element_equals_transport_divergence():
    """tr(D) V_c equals the sum of face fluxes with face velocity = mean of its two nodes."""
    rng = np.random.default_rng(1)
    v = rng.normal(size=(2, NZ + 1, NR + 1))
    v[0, :, 0] = 0.0
    D, _ = momentum.strain_rate(v, R_C, H)
    div_fe = (D[..., 0] + D[..., 1] + D[..., 2]) * VOL
    mesh = CylindricalGrid2D(dx=np.full(NR, H), dy=np.full(NZ, H))
    normals = np.asarray(mesh.faceNormals)
    nzf = NR * (NZ + 1)
    sign = np.concatenate([normals[1, :nzf], normals[0, nzf:]])
    flux = momentum.face_normal_velocity(v) * sign * np.asarray(mesh._faceAreas)
    ids = np.asarray(mesh.faceCellIDs.filled(-1))
    div_fv = np.zeros(NR * NZ)
    np.add.at(div_fv, ids[0], flux)
    inner = ids[1] >= 0
    np.add.at(div_fv, ids[1][inner], -flux[inner])
    assert np.allclose(div_fv.reshape(NZ, NR), div_fe, rtol=1e-12, atol=1e-15)


def test_rigid_translation_has_no_strain_rate():
    v = np.zeros((2, NZ + 1, NR + 1))
    v[1] = -0.7
    D, omega = momentum.strain_rate(v, R_C, H)
    assert np.all(D == 0.0) and np.all(omega == 0.0)


def test_hourglass_force_ignores_linear_fields_and_damps_checkerboard():
    r = H * np.arange(NR + 1)
    z = H * np.arange(NZ + 1)
    RN, ZN = np.meshgrid(r, z)
    linear = np.stack([0.3 * RN - 0.2 * ZN, 0.1 + 0.5 * RN])
    coef = np.full((NZ, NR), 2.0)
    assert np.max(np.abs(momentum.hourglass_force(linear, coef))) < 1e-12
    checker = np.zeros((2, NZ + 1, NR + 1))
    checker[1] = (-1.0) ** (np.add.outer(np.arange(NZ + 1), np.arange(NR + 1)))
    f = momentum.hourglass_force(checker, coef)
    # the force opposes the mode everywhere (power < 0) and grows with it
    assert np.sum(f * checker) < 0
    assert np.all(f[1, 1:-1, 1:-1] * checker[1, 1:-1, 1:-1] < 0)


def test_contact_removes_penetration_and_applies_coulomb_friction():
    n = np.zeros((2, 1, 3))
    n[0] = 1.0
    v = np.array([[[1.0, -1.0, 0.1]], [[0.5, 0.5, 2.0]]])  # (2, 1, 3)
    mask = np.ones((1, 3), bool)
    momentum.apply_wall_contact(v, n, mask, mu=0.3)
    # node 0: normal 1.0 removed, tangential 0.5 reduced by 0.3
    assert v[:, 0, 0] == pytest.approx([0.0, 0.2])
    # node 1: moving away from the wall, untouched
    assert v[:, 0, 1] == pytest.approx([-1.0, 0.5])
    # node 2: friction impulse 0.03 reduces 2.0 to 1.97
    assert v[:, 0, 2] == pytest.approx([0.0, 1.97])


def test_dual_momentum_transport_conserves_momentum_and_keeps_uniform_velocity():
    rng = np.random.default_rng(3)
    rho = 1500.0
    alpha = rng.uniform(0.5, 1.0, (NZ, NR))
    flux_z = np.zeros((NZ + 1, NR))
    flux_r = np.zeros((NZ, NR + 1))
    flux_z[1:-1] = rng.normal(scale=1e-3, size=(NZ - 1, NR)) * VOL[1:] * 0.1
    flux_r[:, 1:-1] = rng.normal(scale=1e-3, size=(NZ, NR - 1)) * VOL[:, 1:] * 0.1
    # new alpha from the primal fluxes (closed boundaries)
    d = np.zeros((NZ, NR))
    d -= flux_z[1:]
    d += flux_z[:-1]
    d -= flux_r[:, 1:]
    d += flux_r[:, :-1]
    new_alpha = alpha + d / VOL
    m_old = momentum.node_mass(rho, alpha, VOL)
    m_new = momentum.node_mass(rho, new_alpha, VOL)
    v = np.zeros((2, NZ + 1, NR + 1))
    v[0], v[1] = 0.2, -0.4
    v_new = momentum.dual_momentum_transport(v, m_old, m_new, flux_z, flux_r, rho)
    assert np.allclose(v_new[0], 0.2, atol=1e-12) and np.allclose(v_new[1], -0.4, atol=1e-12)
    v = rng.normal(size=(2, NZ + 1, NR + 1))
    v_new = momentum.dual_momentum_transport(v, m_old, m_new, flux_z, flux_r, rho)
    P_old = (m_old * v).sum(axis=(1, 2))
    P_new = (m_new * v_new).sum(axis=(1, 2))
    assert np.allclose(P_old, P_new, rtol=1e-12, atol=1e-15)
