"""Trilinear momentum of the 3D model (fipy_hopper.space.momentum): patch tests, hourglass
damping, and the compiled kernels against the numpy reference."""

import math

import numpy as np
import pytest

from fipy_hopper.space import momentum as sm

H = 0.02
SHAPE = (5, 4, 6)          # (nz, ny, nx) cells


def node_coordinates(shape=SHAPE, h=H):
    nz, ny, nx = shape
    z, y, x = np.meshgrid(h * np.arange(nz + 1), h * np.arange(ny + 1), h * np.arange(nx + 1),
                          indexing="ij")
    return np.stack([x, y, z])


def test_uniform_stress_gives_zero_interior_force_and_the_boundary_traction():
    """A uniform stress in full cells: every interior node's force vanishes; the forces on the
    faces of the block sum to the traction sigma.n times the face area."""
    rng = np.random.default_rng(0)
    s = rng.normal(size=6) * 1e3
    stress = np.broadcast_to(s, SHAPE + (6,)).copy()
    f = sm.internal_force(stress, np.full(SHAPE, H ** 3), H)
    assert np.abs(f[:, 1:-1, 1:-1, 1:-1]).max() < 1e-12 * np.abs(s).max() * H ** 2
    nz, ny, nx = SHAPE
    top = f[:, -1].sum(axis=(1, 2))       # the face z = max: the force of the nodes is
    sig = np.array([[s[0], s[5], s[4]], [s[5], s[1], s[3]], [s[4], s[3], s[2]]])
    # f_int = B^T sigma V: on the top plane half of each cell's B^T sigma, i.e. sigma e_z A
    assert np.allclose(top, sig @ [0, 0, 1] * nx * ny * H ** 2, rtol=1e-12, atol=0)
    assert np.allclose(f.sum(axis=(1, 2, 3)), 0.0, atol=1e-12 * np.abs(s).max() * H ** 2)


def test_linear_velocity_gives_the_exact_strain_rate_spin_and_open_divergence():
    """v = L x + b: D = sym(L), W = skew(L) in every cell, the open divergence of full cells
    is tr L, and no hourglass force acts."""
    rng = np.random.default_rng(1)
    L = rng.normal(size=(3, 3))
    b = rng.normal(size=3)
    X = node_coordinates()
    v = np.einsum("ij,j...->i...", L, X) + b[:, None, None, None]
    D, W = sm.strain_rate(v, H)
    sym, skew = 0.5 * (L + L.T), 0.5 * (L - L.T)
    expect_D = [sym[i, j] for i, j in sm.PAIRS]
    expect_W = [skew[i, j] for i, j in sm.SPIN]
    assert np.allclose(D, expect_D, rtol=0, atol=1e-12)
    assert np.allclose(W, expect_W, rtol=0, atol=1e-12)
    nz, ny, nx = SHAPE
    div = sm.open_divergence(v, np.ones((nz + 1, ny, nx)), np.ones((nz, ny + 1, nx)),
                             np.ones((nz, ny, nx + 1)), np.ones(SHAPE), H)
    assert np.allclose(div, np.trace(L), rtol=0, atol=1e-12)
    assert np.abs(sm.hourglass_force(v, np.ones(SHAPE))).max() < 1e-12


def test_jaumann_rotation_is_the_rate_of_a_rigid_spin():
    """sigma + (W sigma - sigma W) dt equals R sigma R^T to first order for R = exp(W dt)."""
    from fipy_hopper.material.principal3d import from_matrix, to_matrix
    rng = np.random.default_rng(2)
    sigma = rng.normal(size=(4, 6))
    spin = rng.normal(size=(4, 3))
    dt = 1e-6
    out = sm.jaumann_rotate(sigma, spin, dt)
    w = np.zeros((4, 3, 3))
    for k, (i, j) in enumerate(sm.SPIN):
        w[:, i, j], w[:, j, i] = spin[:, k], -spin[:, k]
    R = np.eye(3) + w * dt + 0.5 * (w @ w) * dt ** 2
    exact = from_matrix(R @ to_matrix(sigma) @ np.swapaxes(R, 1, 2))
    assert np.allclose(out, exact, rtol=0, atol=1e-10)
    # the trace and the invariants are kept to first order
    assert np.allclose(out[:, :3].sum(1), sigma[:, :3].sum(1), atol=1e-14)


@pytest.mark.parametrize("mode", range(4))
def test_hourglass_modes_decay_at_the_sections_rate(mode):
    """Each of the four hourglass patterns, repeated over a block of full cells of density rho
    (an inner node sees eight cells), decays at 16 kappa_hg sqrt(g/h), the sections' rate;
    rigid motion and the other modes feel nothing."""
    rho, kappa_hg, g = 1500.0, 0.1, 9.81
    shape = (4, 4, 4)
    nz, ny, nx = shape
    k, j, i = np.meshgrid(np.arange(nz + 1), np.arange(ny + 1), np.arange(nx + 1), indexing="ij")
    sx, sy, sz = (-1.0) ** i, (-1.0) ** j, (-1.0) ** k
    pattern = [sx * sy, sy * sz, sx * sz, sx * sy * sz][mode]
    v = np.zeros((3,) + pattern.shape)
    v[1] = pattern
    w = np.full(shape, H ** 3)
    C = kappa_hg * rho * math.sqrt(g * H) * w / (4.0 * H)
    f = sm.hourglass_force(v, C)
    m = sm.node_mass(rho, np.ones(shape), w)
    rate = -f[1, 2, 2, 2] / (m[2, 2, 2] * v[1, 2, 2, 2])
    assert rate == pytest.approx(16.0 * kappa_hg * math.sqrt(g / H), rel=1e-12)
    assert np.abs(f[[0, 2]]).max() == 0.0
    modes = sm.hourglass_modes(v)
    others = [m_ for m_ in range(4) if m_ != mode]
    assert np.abs(modes[others]).max() == 0.0


def test_lumped_mass_sums_to_the_cells_mass():
    rng = np.random.default_rng(3)
    alpha = rng.uniform(0, 1, SHAPE)
    w = rng.uniform(0, 1, SHAPE) * H ** 3
    m = sm.node_mass(1500.0, alpha, w)
    assert m.sum() == pytest.approx(1500.0 * (alpha * w).sum(), rel=1e-13)


def test_compiled_forces_and_node_update_equal_the_numpy_reference_to_the_bit():
    """The compiled corner forces (internal force of alpha (sigma + eta_b tr(D) I), hourglass)
    of a list of carrying cells and the node update (gather in corner order, velocity,
    gravity, light nodes at rest), without walls: the same numbers as the numpy functions."""
    from fipy_hopper.space import stepping
    rng = np.random.default_rng(7)
    shape = SHAPE
    alpha = rng.uniform(0, 1, shape)
    alpha[rng.uniform(size=shape) < 0.3] = 0.0
    alpha[0, 0, 0] = 5e-4                                    # carrying, not loaded
    sigma = rng.normal(size=shape + (6,)) * 1e3
    v = rng.normal(size=(3,) + tuple(n + 1 for n in shape)) * 0.1
    w = rng.uniform(0.2, 1, shape) * H ** 3
    hg = rng.uniform(0, 1, shape)
    eta_b, alpha_min, rho = 3.0, 1e-3, 1500.0
    loaded = alpha >= alpha_min
    D, _ = sm.strain_rate(v, H)
    p_b = eta_b * (D[..., 0] + D[..., 1] + D[..., 2])
    stress = sigma.copy()
    stress[..., :3] = np.where(loaded[..., None], sigma[..., :3] + p_b[..., None], sigma[..., :3])
    expected = (-sm.corner_forces(alpha[..., None] * stress, w, H)
                + sm.hourglass_corner_forces(v, hg * alpha))
    cells = np.argwhere(alpha != 0.0).astype(np.int64)
    contrib = np.zeros((8, 3) + shape)
    stepping.cell_forces(cells, len(cells), alpha, sigma, v, w, H, hg, alpha_min, eta_b,
                         contrib, np.zeros(shape), np.zeros(4))
    carrying = alpha != 0.0
    assert np.array_equal(contrib[:, :, carrying], expected[:, :, carrying])
    # the node update
    m = sm.node_mass(rho, alpha, w)
    light = 1e-12 * rho * H ** 3
    dt, gravity = 1e-4, 9.81
    force = sm.gather(np.where(carrying, expected, 0.0))
    heavy = m > light
    safe = np.where(heavy, m, 1.0)
    ref = v + dt * force / safe
    ref[2] = v[2] + dt * (force[2] / safe - gravity)
    ref = np.where(heavy[None], ref, 0.0)
    nodes = np.zeros((m.size, 5), np.int64)
    nodes[:, :3] = np.argwhere(np.ones(m.shape, bool))
    vc = v.copy()
    none = np.zeros((0, 3))
    stepping.node_update(nodes, len(nodes), vc, m, contrib, gravity, dt, 0.0, light, none,
                         np.zeros(0), np.zeros(0, np.int8), np.zeros(0, np.int64), True, False,
                         False, none, none, np.zeros(4), np.zeros((len(nodes), 3)))
    assert np.array_equal(vc, ref)
