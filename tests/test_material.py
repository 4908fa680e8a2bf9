"""Mohr–Coulomb material (fipy_hopper.material): invariants, surfaces, return mapping, element tests."""

import dataclasses
import math

import numpy as np
import pytest

from fipy_hopper import material as mm
from fipy_hopper.material import mohr_coulomb, return_fast, return_robust
from fipy_hopper.material import (
    APEX,
    ELASTIC,
    PLASTIC,
    MohrCoulomb,
    R_mc,
    R_mw,
    element_test,
    elastic_stiffness,
    elastic_trial,
    flow_direction,
    flow_potential,
    invariants,
    plastic_strain_from_stress,
    principal_stresses,
    update,
    update_reference,
    yield_function,
)

W = np.array([1.0, 1.0, 1.0, 2.0])  # tensor inner product in the (rr, zz, tt, rz) layout
MATERIALS = {
    "cohesionless, psi = 0": MohrCoulomb(E=10e6, nu=0.3, rho=1500.0, phi=30.0),
    "cohesionless, psi = 10": MohrCoulomb(E=10e6, nu=0.3, rho=1500.0, phi=30.0, psi=10.0),
    "cohesive, psi = 0": MohrCoulomb(E=5e6, nu=0.25, rho=1600.0, phi=40.0, c=50.0, e=0.6),
    "cohesive hyperbolic": MohrCoulomb(E=20e6, nu=0.2, rho=1700.0, phi=35.0, psi=8.0, c=200.0),
    "circular G": MohrCoulomb(E=10e6, nu=0.3, rho=1500.0, phi=25.0, psi=20.0, c=10.0, e=1.0),
}


def principal_to_sigma(s, angle=0.0):
    """Stress with principal values s = (in-plane a, in-plane b, tt), the a-axis at `angle` from r."""
    s = np.asarray(s, dtype=float)
    a, b, tt = s[..., 0], s[..., 1], s[..., 2]
    m, h = 0.5 * (a + b), 0.5 * (a - b)
    return np.stack([m + h * np.cos(2 * angle), m - h * np.cos(2 * angle), tt, h * np.sin(2 * angle)], -1)


def lode_principal(p, q, theta):
    """Sorted principal stresses s1 >= s2 >= s3 with invariants (p, q, Theta)."""
    angles = (0.0, 2 * np.pi / 3, -2 * np.pi / 3)
    return np.stack([-p + 2.0 / 3.0 * q * np.cos(theta - a) for a in angles], -1)


def mixed_states(mat, n, seed, strain=1e-3):
    """Admissible stresses at depths of 0.1 to 100 kPa plus strain increments: a mix of elastic,
    plastic and apex (tension) updates, a few exactly zero or hydrostatic."""
    rng = np.random.default_rng(seed)
    p0 = 10.0 ** rng.uniform(2, 5, n)
    sig = np.zeros((n, 4))
    sig[:, :3] = -p0[:, None] * (1.0 + 0.4 * rng.normal(size=(n, 3)))
    sig[:, 3] = 0.4 * p0 * rng.normal(size=n)
    sig, _ = update(sig, np.zeros_like(sig), mat)
    de = rng.normal(size=(n, 4)) * strain * rng.uniform(0, 1, (n, 1))
    de[: n // 20] = 0.0
    sig[n // 20: n // 10] = 0.0
    de[n // 10: n // 8, :3] = rng.normal(size=(n // 8 - n // 10, 1)) * strain
    de[n // 10: n // 8, 3] = 0.0
    return sig, de


def flowing_states(mat, n, seed, strain=(1e-5, 3e-3)):
    """The flowing cells of a discharging hopper: stresses on the yield surface at p = 0.1-20 kPa
    (Lode angle uniform, random axes and hoop position) and log-uniform strain increments in the
    range ``strain``, deviatoric with a small volumetric part, signed to load where they can."""
    rng = np.random.default_rng(seed)
    p = 10.0 ** rng.uniform(2.0, np.log10(2e4), n)
    theta = rng.uniform(0.0, np.pi / 3, n)
    q = (p * math.tan(mat.phi_rad) + mat.c) / R_mc(theta, mat.phi_rad)
    sig = principal_to_sigma(rng.permuted(lode_principal(p, q, theta), axis=-1),
                             rng.uniform(0.0, np.pi, n))
    de = rng.normal(size=(n, 4))
    de[:, :3] -= de[:, :3].mean(-1, keepdims=True) + 0.01 * rng.normal(size=(n, 1))
    de *= (10.0 ** rng.uniform(*np.log10(strain), n) / np.abs(de).max(-1))[:, None]
    unloads = yield_function(elastic_trial(sig, de, mat), mat) <= 0.0
    de[unloads] *= -1.0
    return sig, de


def cosine(a, b):
    with np.errstate(invalid="ignore", divide="ignore"):
        a = a / np.abs(a).max(-1, keepdims=True)
        b = b / np.abs(b).max(-1, keepdims=True)
        return (a * b * W).sum(-1) / np.sqrt((a * a * W).sum(-1) * (b * b * W).sum(-1))


def check_update(mat, sig, de, sig_new, dep, status):
    """The guarantees of every update: finite; on or inside the yield surface; an elastic step
    is the trial stress; the apex return is the apex; the plastic strain is C^-1 of the stress
    returned and parallel to the flow direction there.  Returns the masks used."""
    assert np.isfinite(sig_new).all() and np.isfinite(dep).all()
    trial = elastic_trial(sig, de, mat)
    p, q, _, _ = invariants(sig_new)
    pa = p + mat.apex_stress
    assert (yield_function(sig_new, mat) <= 1e-8 * np.maximum(pa, 1.0)).all()
    el = status == ELASTIC
    assert (sig_new[el] == trial[el]).all() and (dep[el] == 0.0).all()
    apex = status == APEX
    assert (sig_new[apex] == mat.apex_stress * np.array([1.0, 1.0, 1.0, 0.0])).all()
    # plastic strain = C^-1 (sigma_tr - sigma_new), parallel to dG/dsigma at the returned stress
    np.testing.assert_allclose(dep, plastic_strain_from_stress(trial - sig_new, mat),
                               rtol=1e-9, atol=1e-15 * np.abs(de).max())
    # ... wherever the increment is resolved (above the round-off of the trial stress)
    scale = np.abs(trial).max(-1)
    well = (status == PLASTIC) & (np.abs(trial - sig_new).max(-1) > 1e-7 * scale)
    cos = cosine(dep, flow_direction(sig_new, mat))
    assert (cos[well] > 1.0 - 1e-8).all(), cos[well].min()
    return el, well, apex


# --- parameters -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "field, value",
    [("phi", 0.0), ("phi", 90.0), ("psi", -1.0), ("psi", 31.0), ("c", -1.0), ("E", 0.0),
     ("nu", 0.5), ("nu", -1.0), ("rho", 0.0), ("eps", 0.0), ("e", 0.5), ("e", 1.01),
     ("E", float("nan")), ("c", float("inf"))],
)
def test_invalid_parameters_name_the_field(field, value):
    kwargs = dict(E=10e6, nu=0.3, rho=1500.0, phi=30.0)
    kwargs[field] = value
    with pytest.raises(ValueError, match=rf"\b{field}\b"):
        MohrCoulomb(**kwargs)


def test_defaults_and_derived_properties():
    mat = MohrCoulomb(E=10e6, nu=0.3, rho=1500.0, phi=30.0)
    s = 0.5
    assert mat.psi == 0.0 and mat.c == 0.0 and mat.eps == 0.1
    assert mat.e == pytest.approx((3 - s) / (3 + s))
    mu, K, lam = mat.shear_modulus, mat.bulk_modulus, mat.lame_lambda
    assert mu == pytest.approx(10e6 / 2.6) and K == pytest.approx(10e6 / 1.2)
    assert lam + 2 * mu / 3 == pytest.approx(K) and mat.p_wave_modulus == pytest.approx(lam + 2 * mu)
    assert mat.p_wave_speed == pytest.approx(math.sqrt(10e6 * 0.7 / (1.3 * 0.4 * 1500.0)))
    assert mat.phi_rad == pytest.approx(math.pi / 6) and mat.apex_stress == 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        mat.phi = 20.0


# --- invariants and surfaces ------------------------------------------------------------------
def test_lode_angle_of_classical_states():
    p, q, r, th = invariants(np.array([[1.0, 0, 0, 0], [0, -1.0, 0, 0], [-1.0, -3.0, -1.0, 0.0],
                                       [-3.0, -1.0, -3.0, 0], [1.0, -1.0, 0.0, 0.0]]))
    # uniaxial tension and triaxial extension (one principal stress algebraically largest, the
    # other two equal) are Theta = 0; uniaxial and triaxial compression pi/3; pure shear pi/6
    np.testing.assert_allclose(th, [0.0, np.pi / 3, np.pi / 3, 0.0, np.pi / 6], atol=1e-12)
    np.testing.assert_allclose(p, [-1 / 3, 1 / 3, 5 / 3, 7 / 3, 0.0])
    np.testing.assert_allclose(q, [1.0, 1.0, 2.0, 2.0, math.sqrt(3.0)])
    np.testing.assert_allclose(r, [1.0, -1.0, -2.0, 2.0, 0.0], atol=1e-12)


def test_invariants_on_random_states():
    rng = np.random.default_rng(1)
    sig = rng.normal(size=(500, 4)) * 1e4
    p, q, r, th = invariants(sig)
    full = np.zeros((500, 3, 3))
    full[:, 0, 0], full[:, 1, 1], full[:, 2, 2] = sig[:, 0], sig[:, 1], sig[:, 2]
    full[:, 0, 1] = full[:, 1, 0] = sig[:, 3]
    np.testing.assert_allclose(p, -np.trace(full, axis1=1, axis2=2) / 3)
    S = full + p[:, None, None] * np.eye(3)
    np.testing.assert_allclose(q, np.sqrt(1.5 * (S * S).sum((1, 2))))
    np.testing.assert_allclose(r ** 3, 4.5 * np.einsum("nij,njk,nki->n", S, S, S), rtol=1e-9, atol=1e-3)
    np.testing.assert_allclose(np.cos(3 * th), (r / q) ** 3, atol=1e-10)
    assert ((th >= 0) & (th <= np.pi / 3)).all()
    np.testing.assert_allclose(principal_stresses(sig), np.linalg.eigvalsh(full)[:, ::-1], atol=1e-9)
    assert invariants(np.zeros(4))[3] == 0.0


def test_radii_end_values():
    for phi_deg in (5.0, 30.0, 60.0):
        phi, s, c = math.radians(phi_deg), math.sin(math.radians(phi_deg)), math.cos(math.radians(phi_deg))
        e = (3 - s) / (3 + s)
        assert R_mc(0.0, phi) == pytest.approx((3 + s) / (6 * c))
        assert R_mc(np.pi / 3, phi) == pytest.approx((3 - s) / (6 * c))
        # with the default e, G's section passes through both corners of the hexagon
        np.testing.assert_allclose(R_mw([0.0, np.pi / 3], e, phi), R_mc(np.array([0.0, np.pi / 3]), phi))
        assert R_mw(0.0, 0.8, phi) == pytest.approx((3 - s) / (6 * c) / 0.8)
        np.testing.assert_allclose(R_mw(np.linspace(0, np.pi / 3, 7), 1.0, phi), (3 - s) / (6 * c))


@pytest.mark.parametrize("e", [0.5001, 0.6, 0.75, 0.95, 1.0])
def test_menetrey_willam_derivatives_and_convexity(e):
    th = np.linspace(0.0, np.pi / 3, 41)
    r, r1, r2 = mohr_coulomb._mw_radius(th, e)
    h = 1e-6
    inner = slice(1, -1)  # the central differences at the ends leave [0, pi/3]
    fd1 = (mohr_coulomb._mw_radius(th + h, e)[0]
           - mohr_coulomb._mw_radius(th - h, e)[0]) / (2 * h)
    fd2 = (mohr_coulomb._mw_radius(th + h, e)[1]
           - mohr_coulomb._mw_radius(th - h, e)[1]) / (2 * h)
    np.testing.assert_allclose(r1[inner], fd1[inner], atol=1e-6 * np.abs(r1).max() + 1e-9)
    np.testing.assert_allclose(r2[inner], fd2[inner], rtol=1e-5, atol=1e-6 * np.abs(r2).max() + 1e-9)
    # smooth on both meridians (to round-off, which grows like 1/(2e - 1) towards the triangle)
    np.testing.assert_allclose(r1[[0, -1]], 0.0, atol=1e-12 * np.abs(r1).max() / (2 * e - 1))
    assert (r + r2 > 0).all()  # convex section: the gauge R_mw q is convex


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_yield_function_equals_linear_principal_form(name):
    mat = MATERIALS[name]
    rng = np.random.default_rng(2)
    sig = rng.normal(size=(1000, 4)) * 1e5
    s = principal_stresses(sig)
    sp, cp = math.sin(mat.phi_rad), math.cos(mat.phi_rad)
    linear = ((s[:, 0] - s[:, 2]) + (s[:, 0] + s[:, 2]) * sp) / (2 * cp) - mat.c
    np.testing.assert_allclose(yield_function(sig, mat), linear, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("phi_deg, c", [(10.0, 0.0), (30.0, 0.0), (30.0, 500.0), (55.0, 20.0)])
def test_meridian_points_are_on_the_yield_surface(phi_deg, c):
    mat = MohrCoulomb(E=10e6, nu=0.3, rho=1500.0, phi=phi_deg, c=c)
    s = math.sin(mat.phi_rad)
    p = np.array([1.0, 1e3, 1e5]) - 0.5 * mat.apex_stress
    q_c = 6 * s * (p + mat.apex_stress) / (3 - s)
    q_e = 6 * s * (p + mat.apex_stress) / (3 + s)
    for q, theta in ((q_c, np.pi / 3), (q_e, 0.0)):
        sp = lode_principal(p, q, theta)
        for perm in ((0, 1, 2), (2, 0, 1), (1, 2, 0)):  # the hoop stress in every position
            sig = principal_to_sigma(sp[:, perm], angle=0.3)
            pp, qq, _, th = invariants(sig)
            np.testing.assert_allclose(th, theta, atol=1e-6)
            np.testing.assert_allclose(yield_function(sig, mat), 0.0,
                                       atol=1e-10 * (p + mat.apex_stress).max())


# --- flow direction ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_flow_direction_is_the_gradient_of_G(name):
    mat = MATERIALS[name]
    rng = np.random.default_rng(3)
    sig = rng.normal(size=(300, 4)) * 1e5 - 5e4 * np.array([1, 1, 1, 0])
    n = flow_direction(sig, mat)
    h = 1e-2  # Pa
    step = h * np.eye(4)
    fd = np.stack([(flow_potential(sig + step[k], mat) - flow_potential(sig - step[k], mat)) / (2 * h)
                   for k in range(4)], -1)
    fd[:, 3] /= 2.0  # sigma_rz enters the tensor twice: dG/dsigma_rz(vector) = 2 n_rz
    np.testing.assert_allclose(n, fd, atol=1e-7)
    np.testing.assert_allclose(n[:, :3].sum(-1), math.tan(mat.psi_rad), atol=1e-12)


def test_flow_direction_at_the_vertex_and_apex_is_finite():
    for mat in MATERIALS.values():
        sig = np.array([[0.0, 0, 0, 0], [-1e4, -1e4, -1e4, 0], [1e3, 1e3, 1e3, 0],
                        [mat.apex_stress] * 3 + [0.0]])
        n = flow_direction(sig, mat)
        np.testing.assert_allclose(n, np.tile([1, 1, 1, 0], (4, 1)) * math.tan(mat.psi_rad) / 3, atol=1e-15)


# --- elasticity -------------------------------------------------------------------------------
def test_elastic_stiffness_tensor_shear_layout():
    mat = MATERIALS["cohesive hyperbolic"]
    C = elastic_stiffness(mat)
    lam, mu = mat.lame_lambda, mat.shear_modulus
    de = np.array([1e-3, -2e-3, 5e-4, 7e-4])
    expected = lam * de[:3].sum() * np.array([1, 1, 1, 0]) + 2 * mu * de
    np.testing.assert_allclose(C @ de, expected)
    np.testing.assert_allclose(C, C.T)
    np.testing.assert_allclose(plastic_strain_from_stress(C @ de, mat), de, rtol=1e-12)
    np.testing.assert_allclose(elastic_trial(np.ones(4), de, mat), 1.0 + C @ de, rtol=1e-14)


# --- the stress update ------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(MATERIALS))
@pytest.mark.parametrize("strain", [1e-5, 1e-3, 1e-1])
def test_update_guarantees_on_mixed_states(name, strain):
    mat = MATERIALS[name]
    sig, de = mixed_states(mat, 4000, seed=11, strain=strain)
    sig_new, dep, status = update(sig, de, mat, return_status=True)
    el, well, apex = check_update(mat, sig, de, sig_new, dep, status)
    assert el.any() and (status == PLASTIC).any()
    if mat.flow_hyperbola == 0.0:
        assert apex.any()


@pytest.mark.parametrize("mat", [
    MohrCoulomb(E=1e5, nu=0.0, rho=1500.0, phi=89.0, psi=89.0, e=0.50006),  # near-triangular G
    MohrCoulomb(E=1e5, nu=0.45, rho=1500.0, phi=60.0, psi=30.0, c=1.0, e=0.5001, eps=1.0),
    MohrCoulomb(E=1e9, nu=-0.9, rho=1500.0, phi=0.5, psi=0.5, c=1e4, eps=0.01),
])
@pytest.mark.parametrize("strain", [1e-2, 1.0])
def test_update_guarantees_for_extreme_parameters(mat, strain):
    """Sharp corners of G at the compression meridian (e -> 1/2), phi -> 90 and phi -> 0."""
    sig, de = mixed_states(mat, 4000, seed=13, strain=strain)
    sig_new, dep, status = update(sig, de, mat, return_status=True)
    check_update(mat, sig, de, sig_new, dep, status)
    assert (status == PLASTIC).sum() > 1000


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_update_equals_reference(name):
    mat = MATERIALS[name]
    sig, de = mixed_states(mat, 3000, seed=12, strain=1e-3)
    a = update(sig, de, mat, return_status=True)
    b = update_reference(sig, de, mat, return_status=True)
    np.testing.assert_array_equal(a[2], b[2])
    assert set(np.unique(a[2])) >= {ELASTIC, PLASTIC}
    # 1e-10 of the trial stress, widened where the return is ill-conditioned (a > 0 near the
    # apex: sensitivity |sigma_tr| / (p + c cot phi), see update_reference)
    scale = np.abs(elastic_trial(sig, de, mat)).max(-1)
    cond = scale / np.maximum(invariants(a[0])[0] + mat.apex_stress, 1e-300)
    tol = scale * (1e-10 + 1e-14 * cond)
    assert (np.abs(a[0] - b[0]).max(-1) <= tol).all()
    assert (np.abs(a[1] - b[1]).max(-1) <= tol / mat.shear_modulus).all()


FLOWING = dict(MATERIALS, **{
    "dense, psi = 0": MohrCoulomb(E=5e6, nu=0.3, rho=1600.0, phi=40.0),
    "loose, psi = 0": MohrCoulomb(E=5e6, nu=0.3, rho=1600.0, phi=20.0),
    "hopper default, c = 20": MohrCoulomb(E=5e6, nu=0.3, rho=1600.0, phi=32.0, psi=5.0, c=20.0),
    "sharp G": MohrCoulomb(E=5e6, nu=0.3, rho=1600.0, phi=30.0, e=0.52),
})


@pytest.mark.parametrize("name", sorted(FLOWING))
def test_update_on_flowing_states_guarantees_and_reference(name):
    """Hopper-like flowing states, nearly all plastic (the compiled fast path): every guarantee,
    and the compiled update equal to the reference as in test_update_equals_reference."""
    mat = FLOWING[name]
    sig, de = flowing_states(mat, 3000, seed=21)
    a = update(sig, de, mat, return_status=True)
    check_update(mat, sig, de, *a)
    assert (a[2] == PLASTIC).mean() > 0.9
    b = update_reference(sig, de, mat, return_status=True)
    np.testing.assert_array_equal(a[2], b[2])
    scale = np.abs(elastic_trial(sig, de, mat)).max(-1)
    assert (np.abs(a[0] - b[0]).max(-1) <= 1e-10 * scale).all()
    assert (np.abs(a[1] - b[1]).max(-1) <= 1e-10 * scale / mat.shear_modulus).all()


def _fast_path(mat, sig, de, block=None):
    """The compiled fast return (return_fast._fast_block) of the plastic trial states, in blocks
    of ``block`` points (default: one block): sorted trial principal stresses, whether the fast
    path accepted each, and its returned sorted stresses."""
    s = principal_stresses(elastic_trial(sig, de, mat))
    sp, cp = math.sin(mat.phi_rad), math.cos(mat.phi_rad)
    f = ((s[:, 0] - s[:, 2]) + (s[:, 0] + s[:, 2]) * sp) / (2 * cp) - mat.c
    s, f = s[f > 0], f[f > 0]
    m = len(f)
    block = block or m
    cst = return_fast._fast_constants(mat.kernel_parameters())
    ok, returned = np.empty(m, dtype=bool), np.empty((m, 3))
    rows = [return_fast._W_N1, return_fast._W_N2, return_fast._W_N3]
    for b0 in range(0, m, block):
        n = min(block, m - b0)
        S = np.ascontiguousarray(np.vstack([s[b0:b0 + n].T, f[b0:b0 + n]]))
        W = np.empty((return_fast._W_ROWS, n))
        flags = np.empty((return_fast._F_ROWS, n), dtype=bool)
        return_fast._fast_block(n, S, W, flags, cst)
        ok[b0:b0 + n], returned[b0:b0 + n] = flags[return_fast._F_OK], W[rows].T
    return s, ok, returned


@pytest.mark.parametrize("name", ["cohesionless, psi = 10", "hopper default, c = 20"])
def test_fast_return_of_a_point_does_not_depend_on_its_block(name):
    """The lockstep sweeps gather the points still open and sweep them on their own: a point's
    iterates, its acceptance and its returned stress are the same, to the bit, whether it is
    returned alone, in blocks of 7 or among all 1500."""
    mat = FLOWING[name]
    sig, de = flowing_states(mat, 1500, seed=23)
    s, ok, returned = _fast_path(mat, sig, de)
    assert ok.mean() > 0.9
    for block in (1, 7):
        _, ok_b, returned_b = _fast_path(mat, sig, de, block)
        np.testing.assert_array_equal(ok_b, ok)
        np.testing.assert_array_equal(returned_b, returned)


@pytest.mark.parametrize("name", sorted(FLOWING))
def test_fast_return_equals_robust_return_and_takes_the_flowing_states(name):
    """The fast path (one scalar equation in the Lode angle) returns what the robust algorithm
    (_return_sorted, the one of update_reference) returns wherever it accepts a point, and it
    accepts the regular returns of flowing states: (almost) none fall back to the slow one."""
    mat = FLOWING[name]
    sig, de = flowing_states(mat, 1500, seed=22)
    s, ok, fast = _fast_path(mat, sig, de)
    prm = mat.kernel_parameters()
    robust = np.array([return_robust._return_sorted(*row, prm) for row in s])
    regular = robust[:, 3] == PLASTIC
    # (for e -> 1/2 the sharp corner of G sends a few to the robust return)
    assert ok[regular].mean() >= (0.999 if mat.e > 0.55 else 0.9)
    assert (robust[ok, 3] == PLASTIC).all()
    scale = np.abs(s).max(-1)
    assert (np.abs(fast[ok] - robust[ok, :3]).max(-1) <= 1e-11 * scale[ok]).all()


def test_update_shapes_and_broadcasting():
    mat = MATERIALS["cohesionless, psi = 10"]
    sig = np.array([-1e4, -2e4, -1e4, 3e3])
    de = np.random.default_rng(4).normal(size=(2, 3, 4)) * 1e-3
    out, dep, st = update(sig, de, mat, return_status=True)
    assert out.shape == dep.shape == (2, 3, 4) and st.shape == (2, 3)
    ref = update(np.broadcast_to(sig, de.shape).reshape(-1, 4), de.reshape(-1, 4), mat)
    np.testing.assert_array_equal(out.reshape(-1, 4), ref[0])
    one, _ = update(sig, de[0, 0], mat)
    assert one.shape == (4,)
    with pytest.raises(ValueError):
        update(np.zeros(3), np.zeros(3), mat)


@pytest.mark.parametrize("psi", [0.0, 10.0])
def test_cohesionless_apex_returns_to_exactly_zero_stress(psi):
    mat = MohrCoulomb(E=10e6, nu=0.3, rho=1500.0, phi=30.0, psi=psi)
    sig = np.array([[0.0, 0, 0, 0], [-1e3, -1e3, -1e3, 0], [-1e3, -2e3, -5e2, 4e2]])
    de = np.array([[1e-3, 1e-3, 1e-3, 0.0], [1e-2, 2e-2, 1e-2, 1e-3], [5e-2, 1e-2, 3e-2, -1e-2]])
    out, dep, st = update(sig, de, mat, return_status=True)
    assert (st == APEX).all() and (out == 0.0).all()
    np.testing.assert_allclose(dep, plastic_strain_from_stress(elastic_trial(sig, de, mat), mat))


def test_cohesive_apex_is_c_cot_phi():
    mat = MATERIALS["cohesive, psi = 0"]
    out, _, st = update(np.zeros(4), np.array([1e-2, 1e-2, 1e-2, 1e-3]), mat, return_status=True)
    assert st == APEX
    np.testing.assert_array_equal(out, mat.c / math.tan(mat.phi_rad) * np.array([1, 1, 1, 0]))


def test_no_nan_for_extreme_inputs():
    states = np.array([[0.0, 0, 0, 0], [-1e5] * 3 + [0.0], [1e5] * 3 + [0.0], [-1e12, 1e12, 0, 1e12],
                       [1e-300, 0, 0, 0], [-1e5, -1e5, -1e5, 1e-20], [1e300, -1e300, 0.0, 1e300],
                       [-1e200, -2e200, -1e200, 0.0]])
    strains = np.array([[0.0, 0, 0, 0], [1e3, -1e3, 1e3, 1e3], [-1e3] * 4, [1e-300, 0, 0, 0],
                        [0, 0, 0, 1e2], [5.0, 5.0, 5.0, 0.0]])
    sig = np.repeat(states, len(strains), axis=0)
    de = np.tile(strains, (len(states), 1))
    for mat in MATERIALS.values():
        for fn in (update, update_reference):
            out, dep, st = fn(sig, de, mat, return_status=True)
            check_update(mat, sig, de, out, dep, st)


def test_elastic_points_are_untouched_exactly():
    mat = MATERIALS["cohesive hyperbolic"]
    sig = np.array([[-1e4, -1.2e4, -1.1e4, 1e2]] * 3)
    de = np.array([[0.0, 0, 0, 0], [1e-6, -2e-6, 0, 1e-7], [-1e-5, -1e-5, -1e-5, 0]])
    for fn in (update, update_reference):
        out, dep, st = fn(sig, de, mat, return_status=True)
        assert (st == ELASTIC).all()
        np.testing.assert_array_equal(out, elastic_trial(sig, de, mat))
        np.testing.assert_array_equal(out[0], sig[0])
        assert (dep == 0.0).all()


# --- element tests ----------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["cohesionless, psi = 0", "cohesive hyperbolic", "circular G"])
@pytest.mark.parametrize("p0", [2e4, 2e5])
def test_triaxial_failure_deviators(name, p0):
    mat = MATERIALS[name]
    s = math.sin(mat.phi_rad)
    for path, sign, theta in (("triaxial_compression", -1.0, np.pi / 3), ("triaxial_extension", 1.0, 0.0)):
        res = element_test(mat, path, -p0, 0.2, 100)
        p, q, _, th = res.invariants
        assert res.status[-1] != ELASTIC and res.residual.max() <= 1e-9 * p0
        np.testing.assert_allclose(res.stress[:, [0, 2]], -p0, rtol=1e-12)  # lateral stress held
        np.testing.assert_allclose(q[-1], 6 * s * (p[-1] + mat.apex_stress) / (3 + sign * s), rtol=1e-10)
        np.testing.assert_allclose(th[-1], theta, atol=1e-7)
        # while elastic the deviator grows at 3 mu per unit deviatoric strain, and p by q/3
        el = np.nonzero(res.status == ELASTIC)[0]
        d_eps_q = np.diff(res.deviatoric(res.strain))
        np.testing.assert_allclose(np.diff(q)[el], 3 * mat.shear_modulus * d_eps_q[el], rtol=1e-9)


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_plastic_dilatancy_in_triaxial_flow(name):
    """At failure the ratio of plastic volumetric to deviatoric strain rates follows from G:
    n = dG/dsigma on the meridian Theta has tr n = tan(psi) and eps_q(n) = R^2 q / g, so
    d eps_v^p / d eps_q^p = tan(psi) g / (R^2 q), R = R_mw(Theta), g = sqrt(a^2 + (R q)^2),
    a = eps c tan(psi)
    (-> tan(psi)/R far from the apex); positive = dilation (volume increase)."""
    mat = MATERIALS[name]
    for path, theta in (("triaxial_compression", np.pi / 3), ("triaxial_extension", 0.0)):
        res = element_test(mat, path, -1e5, 0.2, 100)
        assert res.status[-1] == PLASTIC
        dep = np.diff(res.plastic_strain, axis=0)[-1]
        ratio = res.volumetric(dep) / res.deviatoric(dep)
        p, q, _, _ = res.invariants
        R = float(R_mw(theta, mat.e, mat.phi_rad))
        g = math.hypot(mat.flow_hyperbola, R * q[-1])
        expected = math.tan(mat.psi_rad) * g / (R * R * q[-1])
        np.testing.assert_allclose(ratio, expected, rtol=1e-8, atol=1e-12)
        if mat.psi == 0.0:
            eps_p = res.plastic_strain[-1]
            assert abs(res.volumetric(eps_p)) <= 1e-12 * np.abs(eps_p).max()
        else:
            assert res.volumetric(dep) > 0


def _simple_shear_limit(mat):
    """tau/(sigma_n + c cot phi) of steady simple shear (eps_rr = eps_tt = 0, sigma_zz held).

    Steady flow has constant stress, so the plastic rate has n_rr = n_tt = 0: the hoop stress is the
    intermediate principal stress at the Lode angle where n_2 = 0 (solved here by bisection on
    flow_direction of a diagonal stress, a = 0 so n depends on Theta only); with the in-plane axes
    at cos 2w = -(n1 + n3)/(n1 - n3), F = 0 and sigma_zz = -sigma_n give
    tau = (sigma_n + c cot phi) sin(phi) sin 2w / (1 + sin(phi) cos 2w)  (Davis's sin(phi) for psi = 0).
    """
    def n_sorted(theta):
        return flow_direction(np.append(lode_principal(1.0, 1.0, theta), 0.0), mat)[:3]

    lo, hi = 0.0, np.pi / 3
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if n_sorted(mid)[1] < 0 else (lo, mid)
    n1, _, n3 = n_sorted(0.5 * (lo + hi))
    cos2w = -(n1 + n3) / (n1 - n3)
    s = math.sin(mat.phi_rad)
    return s * math.sqrt(1 - cos2w ** 2) / (1 + s * cos2w)


@pytest.mark.parametrize("psi, c", [(0.0, 0.0), (0.0, 300.0), (10.0, 0.0), (25.0, 0.0)])
def test_simple_shear_steady_state(psi, c):
    mat = MohrCoulomb(E=10e6, nu=0.3, rho=1500.0, phi=30.0, psi=psi, c=c)
    res = element_test(mat, "simple_shear", -1e5, 1.0, 200)
    sig = res.stress[-1]
    np.testing.assert_allclose(sig[1], -1e5, rtol=1e-12)  # normal stress held
    assert abs(yield_function(sig, mat)) <= 1e-8 * 1e5
    tau_ratio = sig[3] / (1e5 + mat.apex_stress)
    expected = _simple_shear_limit(mat)
    if psi == 0.0:
        assert expected == pytest.approx(math.sin(mat.phi_rad), rel=1e-12)
    np.testing.assert_allclose(tau_ratio, expected, rtol=1e-8)
    de = np.diff(res.strain, axis=0)[-1]
    dep = np.diff(res.plastic_strain, axis=0)[-1]
    np.testing.assert_allclose(dep, de, atol=1e-9 * abs(de[3]))  # all the strain is plastic
    assert res.volumetric(de) == pytest.approx(0.0, abs=1e-12) if psi == 0 else res.volumetric(de) > 0


def test_oedometric_loading_stays_elastic_at_K0():
    mat = MohrCoulomb(E=10e6, nu=0.3, rho=1500.0, phi=30.0)  # K0 = 0.43 > Ka = 1/3
    res = element_test(mat, "oedometric", 0.0, 0.02, 20)
    assert (res.status == ELASTIC).all()
    np.testing.assert_allclose(res.stress[1:, 0] / res.stress[1:, 1], mat.nu / (1 - mat.nu), rtol=1e-12)
    np.testing.assert_allclose(res.stress[1:, 2], res.stress[1:, 0], rtol=1e-12)


def test_oedometric_loading_yields_at_the_active_ratio():
    mat = MohrCoulomb(E=10e6, nu=0.2, rho=1500.0, phi=30.0)  # K0 = 0.25 < Ka = 1/3: yields at once
    s = math.sin(mat.phi_rad)
    res = element_test(mat, "oedometric", 0.0, 0.02, 20)
    assert (res.status == PLASTIC).all()
    np.testing.assert_allclose(res.stress[1:, 0] / res.stress[1:, 1], (1 - s) / (1 + s), rtol=1e-10)
    np.testing.assert_allclose(yield_function(res.stress, mat), 0.0, atol=1e-8)
    np.testing.assert_allclose(res.invariants[3][1:], np.pi / 3, atol=1e-7)


def test_drive_with_prescribed_stress_increments_is_elastic_compliance():
    mat = MATERIALS["cohesive hyperbolic"]
    ds = np.array([-1e3, -2e3, -1e3, 5e2])
    res = mm.drive(mat, -1e5 * np.array([1, 1, 1, 0]), np.zeros((5, 4)), np.eye(4), d_sigma=ds)
    assert (res.status == ELASTIC).all()
    np.testing.assert_allclose(res.strain[-1], plastic_strain_from_stress(5 * ds, mat), rtol=1e-9)
    with pytest.raises(ValueError, match="path"):
        element_test(mat, "torsion", -1e5, 0.01)
