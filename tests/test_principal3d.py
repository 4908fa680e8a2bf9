"""The law's 3D point update (fipy_hopper.material.principal3d): six stress components through
the same principal-space return as the axisymmetric update."""

import math

import numpy as np
import pytest

from fipy_hopper.material import APEX, ELASTIC, PLASTIC, MohrCoulomb, update, update_reference
from fipy_hopper.material import principal3d as p3

MATERIALS = {
    "cohesionless, psi = 0": MohrCoulomb(E=10e6, nu=0.3, rho=1500.0, phi=30.0),
    "cohesionless, psi = 10": MohrCoulomb(E=10e6, nu=0.3, rho=1500.0, phi=30.0, psi=10.0),
    "cohesive, psi = 0": MohrCoulomb(E=5e6, nu=0.25, rho=1600.0, phi=40.0, c=50.0, e=0.6),
    "cohesive hyperbolic": MohrCoulomb(E=20e6, nu=0.2, rho=1700.0, phi=35.0, psi=8.0, c=200.0),
}


def random_rotations(n, rng):
    """n random proper rotations (QR of Gaussian matrices, signs fixed)."""
    q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q = q * np.sign(np.einsum("nii->ni", r))[:, None, :]
    q[np.linalg.det(q) < 0, :, 0] *= -1.0
    return q


def axisymmetric_to_3d(t4, Q):
    """(rr, zz, tt, rz) as a tensor in the frame (e_r, e_t, e_z), rotated by Q: six components."""
    m = np.zeros(t4.shape[:-1] + (3, 3))
    m[..., 0, 0], m[..., 2, 2], m[..., 1, 1] = t4[..., 0], t4[..., 1], t4[..., 2]
    m[..., 0, 2] = m[..., 2, 0] = t4[..., 3]
    return p3.from_matrix(Q @ m @ np.swapaxes(Q, -1, -2))


def tolerance(trial, new, mat):
    """1e-10 of the trial stress, widened by 1e-14 |sigma_tr| / (p + c cot phi) where the return
    is ill-conditioned (the rounded tip of G), as tests/test_material.py holds the axisymmetric
    update to its reference."""
    scale = np.abs(trial).max(-1) + mat.c
    p = -(new[..., 0] + new[..., 1] + new[..., 2]) / 3.0
    cond = scale / np.maximum(p + mat.apex_stress, 1e-300)
    return scale * (1e-10 + 1e-14 * cond)


def states_2d(mat, n, seed, strain=2e-3):
    """Admissible axisymmetric stresses (0.1-100 kPa) and strain increments: elastic, plastic
    and apex updates, a few zero."""
    rng = np.random.default_rng(seed)
    p0 = 10.0 ** rng.uniform(2, 5, n)
    sig = np.zeros((n, 4))
    sig[:, :3] = -p0[:, None] * (1.0 + 0.4 * rng.normal(size=(n, 3)))
    sig[:, 3] = 0.4 * p0 * rng.normal(size=n)
    sig, _ = update(sig, np.zeros_like(sig), mat)
    de = rng.normal(size=(n, 4)) * strain * rng.uniform(0, 1, (n, 1))
    de[: n // 20] = 0.0
    sig[n // 20: n // 10] = 0.0
    return sig, de


def states_3d(mat, n, seed, strain=2e-3):
    """Admissible general 3D stresses and strain increments (random axes)."""
    rng = np.random.default_rng(seed)
    p0 = 10.0 ** rng.uniform(2, 5, n)
    sig = -p0[:, None] * np.concatenate([1.0 + 0.4 * rng.normal(size=(n, 3)),
                                         0.4 * rng.normal(size=(n, 3))], axis=1)
    sig, _ = p3.update6(sig, np.zeros_like(sig), mat)
    de = rng.normal(size=(n, 6)) * strain * rng.uniform(0, 1, (n, 1))
    de[: n // 20] = 0.0
    sig[n // 20: n // 10] = 0.0
    return sig, de


@pytest.mark.parametrize("name", list(MATERIALS))
def test_rotated_axisymmetric_state_gives_the_rotated_axisymmetric_update(name):
    """An axisymmetric state and increment rotated into a random frame: the 3D update (compiled
    and numpy) is the rotated result of the axisymmetric update, stress and plastic strain,
    with the same status (but for points whose trial lies on the yield surface to round-off,
    |F_tr| <= 1e-10 of the stress, where elastic or plastic is decided by the last bit).
    Tolerance as the axisymmetric update's own against its reference: 1e-10 of the trial
    stress, widened where the return is ill-conditioned (a > 0 near the apex, sensitivity
    |sigma_tr| / (p + c cot phi)); the principal values come from a 3 x 3 eigen-solve here and
    from the closed-form 2 x 2 one there (round-off of the norm)."""
    mat = MATERIALS[name]
    sig4, de4 = states_2d(mat, 3000, seed=1)
    rng = np.random.default_rng(2)
    Q = random_rotations(len(sig4), rng)
    new4, dp4, st4 = update(sig4, de4, mat, return_status=True)
    new4r, _, st4r = update_reference(sig4, de4, mat, return_status=True)
    assert np.array_equal(st4, st4r)
    sig6, de6 = axisymmetric_to_3d(sig4, Q), axisymmetric_to_3d(de4, Q)
    expected, expected_p = axisymmetric_to_3d(new4, Q), axisymmetric_to_3d(dp4, Q)
    trial = p3.elastic_trial6(sig6, de6, mat)
    scale = np.abs(trial).max(axis=1, keepdims=True) + mat.c
    decided = np.abs(p3.yield_function6(trial, mat)) > 1e-10 * scale[:, 0]
    for fn in (p3.update6, p3.update6_reference):
        new6, dp6, st6 = fn(sig6, de6, mat, return_status=True)
        assert np.array_equal(st6[decided], st4[decided])
        tol = tolerance(trial, new6, mat)[:, None]
        assert np.all(np.abs(new6 - expected) <= tol)
        assert np.all(np.abs(dp6 - expected_p) <= tol / mat.shear_modulus)
    assert set(np.unique(st4)) == {ELASTIC, PLASTIC, APEX}


@pytest.mark.parametrize("name", list(MATERIALS))
def test_random_states_admissible_coaxial_and_compiled_equals_numpy(name):
    """Random 3D states and increments: after the update F <= 1e-10 of the stress scale, the
    new stress commutes with the trial (coaxial return), elastic points keep the trial exactly,
    the plastic strain is C^-1 (sigma_tr - sigma_new), and the compiled update equals the
    numpy twin to 1e-10 of the stress scale, widened where the return is ill-conditioned as in
    the axisymmetric update's test (two eigen-solvers: not bit-identical)."""
    mat = MATERIALS[name]
    sig, de = states_3d(mat, 4000, seed=3)
    trial = p3.elastic_trial6(sig, de, mat)
    scale = np.abs(trial).max(axis=1) + mat.c + 1.0
    new, dp, st = p3.update6(sig, de, mat, return_status=True)
    ref, dpr, str_ = p3.update6_reference(sig, de, mat, return_status=True)
    decided = np.abs(p3.yield_function6(trial, mat)) > 1e-10 * scale
    assert np.array_equal(st[decided], str_[decided])
    tol = tolerance(trial, new, mat)[:, None]
    assert np.all(np.abs(new - ref) <= tol)
    assert np.all(np.abs(dp - dpr) <= tol / mat.shear_modulus)
    assert np.all(p3.yield_function6(new, mat) <= 1e-10 * scale)
    A, B = p3.to_matrix(new), p3.to_matrix(trial)
    commutator = A @ B - B @ A
    assert np.all(np.abs(commutator).max(axis=(1, 2)) <= 1e-10 * scale ** 2)
    elastic = st == ELASTIC
    assert elastic.any() and (st == PLASTIC).any() and (st == APEX).any()
    assert np.array_equal(new[elastic], trial[elastic]) and np.all(dp[elastic] == 0.0)
    assert np.allclose(dp, p3.plastic_strain6(trial - new, mat), rtol=0,
                       atol=1e-13 * scale.max() / mat.shear_modulus)


def test_cohesionless_apex_is_exactly_zero_and_cohesive_apex_is_c_cot_phi():
    """Pulled apart: the stress-free apex exactly (c = 0), c cot(phi) I with cohesion."""
    de = np.array([[1e-3, 2e-3, 1.5e-3, 1e-4, -2e-4, 3e-4]])
    sig = np.array([[-100.0, -80.0, -120.0, 5.0, -3.0, 2.0]])
    for mat in (MATERIALS["cohesionless, psi = 0"], MATERIALS["cohesive, psi = 0"]):
        for fn in (p3.update6, p3.update6_reference):
            new, _, st = fn(sig, de, mat, return_status=True)
            assert st[0] == APEX
            apex = mat.c / math.tan(mat.phi_rad)
            assert np.array_equal(new[0], [apex, apex, apex, 0.0, 0.0, 0.0])


def test_jacobi_eigen_solve_on_degenerate_and_diagonal_tensors():
    """The compiled eigen-solve on repeated eigenvalues, a diagonal tensor and a tiny
    off-diagonal part: the principal values of np.linalg.eigh to round-off."""
    rng = np.random.default_rng(5)
    Q = random_rotations(4, rng)
    cases = [np.diag([-3.0, -3.0, -1.0]), np.diag([-2.0, -5.0, -1.0]),
             np.diag([-1.0, -1.0, -1.0]) + 1e-13, np.diag([-4.0, -1.0, -1.0])]
    a, v = np.empty((3, 3)), np.empty((3, 3))
    for q, m in zip(Q, cases):
        t = q @ m @ q.T
        t = 0.5 * (t + t.T)
        a[:] = t
        p3._eigh3(a, v)
        assert np.allclose(np.sort(np.diag(a)), np.linalg.eigvalsh(t), rtol=0, atol=1e-14 * 5)
        assert np.allclose(v @ np.diag(np.diag(a)) @ v.T, t, rtol=0, atol=1e-14 * 5)
        assert np.allclose(v.T @ v, np.eye(3), rtol=0, atol=1e-14)


def test_block_eigen_solve_gives_each_matrix_its_own_result_to_the_bit():
    """The lockstep eigen-solve of a block (``_eigh3_block``) against each matrix solved
    alone (``_eigh3``, a block of one): the same eigenvalues and vectors to the bit, for a
    block mixing matrices that converge at once (diagonal, +-0 entries), after a few sweeps
    (random) and in the last sweeps (near-repeated eigenvalues, tiny off-diagonal parts), in
    two orders; and each the decomposition of its matrix to round-off."""
    rng = np.random.default_rng(11)
    Q = random_rotations(40, rng)
    mats = [np.diag([-2.0, -5.0, -1.0]), np.diag([-0.0, 0.0, -0.0]), np.zeros((3, 3))]
    for q, gap in zip(Q, np.tile([0.0, 1e-15, 1e-10, 1e-6, 0.3], 8)):
        mats.append(q @ np.diag([-1.0, -1.0 - gap, -7.0 * rng.random()]) @ q.T * 1e4)
    mats += list(rng.normal(size=(60, 3, 3)))
    m = np.array([np.triu(t) + np.triu(t, 1).T for t in mats])     # exactly symmetric
    m[5, 0, 1] = m[5, 1, 0] = -0.0
    for order in (np.arange(len(m)), rng.permutation(len(m))):
        block = m[order]
        A = np.array([block[:, 0, 0], block[:, 1, 1], block[:, 2, 2], block[:, 1, 2],
                      block[:, 0, 2], block[:, 0, 1]])
        V = np.empty((9, len(block)))
        p3._eigh3_block(len(block), A, V)
        a, v = np.empty((3, 3)), np.empty((3, 3))
        for j, t in enumerate(block):
            a[:] = t
            p3._eigh3(a, v)
            alone = np.concatenate([np.diag(a), v.ravel()])
            together = np.concatenate([A[:3, j], V[:, j]])
            assert np.array_equal(alone.view(np.int64), together.view(np.int64)), j
            scale = max(np.abs(t).max(), 1e-300)
            assert np.allclose(v @ np.diag(np.diag(a)) @ v.T, t, rtol=0, atol=1e-13 * scale)
            assert np.allclose(v.T @ v, np.eye(3), rtol=0, atol=1e-13)


def test_shapes_and_invalid_layout():
    mat = MATERIALS["cohesionless, psi = 0"]
    sig = np.zeros((2, 3, 6))
    new, dp = p3.update6(sig, np.zeros(6), mat)
    assert new.shape == (2, 3, 6) and dp.shape == (2, 3, 6)
    with pytest.raises(ValueError):
        p3.update6(np.zeros((2, 4)), np.zeros((2, 4)), mat)
