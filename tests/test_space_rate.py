"""The law's rate-dependent overstress in 3D (fipy_hopper.space.rate3d): compiled against its
numpy reference, the sections' overstress on an axisymmetric state, simple shear, and the 3D
model's compiled steps against its numpy reference in a flowing discharge."""

import numpy as np
import pytest

from fipy_hopper.material.rate import InertialRheology, overstress
from fipy_hopper.space.config import small_silo
from fipy_hopper.space.model import SpaceModel
from fipy_hopper.space.rate3d import overstress6, overstress6_compiled

RATE = InertialRheology().kernel_parameters()


def random_points(n, seed):
    rng = np.random.default_rng(seed)
    sigma = rng.normal(size=(n, 6)) * 1e3 - np.array([3e3, 3e3, 3e3, 0, 0, 0])
    D = rng.normal(size=(n, 6)) * 10.0
    flowing = rng.uniform(size=n) < 0.7
    sigma[:5, :3] = 1e3                             # tension: no overstress
    D[5:8] = 0.0                                    # at rest: none
    return sigma, D, flowing


def test_compiled_overstress_equals_numpy_to_the_bit():
    """Random stresses (some in tension), strain rates (some zero) and flowing flags: the
    compiled point functions give the numpy reference's overstress to the bit, zero where not
    flowing, in tension or with no rate dependence (``d = 0``)."""
    sigma, D, flowing = random_points(2000, 1)
    ref = overstress6(sigma, D, flowing, RATE)
    out = overstress6_compiled(sigma, D, flowing, RATE)
    assert np.array_equal(out, ref)
    assert np.all(ref[~flowing] == 0.0) and np.all(ref[:5] == 0.0)
    assert np.abs(ref[flowing][5:]).max() > 0.0
    assert np.all(overstress6_compiled(sigma, D, flowing, np.zeros(4)) == 0.0)


def test_axisymmetric_state_gives_the_sections_overstress():
    """A state of the sections' ``(rr, zz, tt, rz)`` placed in the plane ``y = 0`` (``xx =
    rr``, ``yy = tt``, ``zz = zz``, ``xz = rz``) gives the sections' overstress
    (:func:`fipy_hopper.material.rate.overstress`) in the same places to 1e-12 (the sums run
    in another order), and nothing in ``yz``, ``xy``."""
    sigma, D, flowing = random_points(500, 2)
    s4 = sigma[:, [0, 2, 1, 4]]
    d4 = D[:, [0, 2, 1, 4]]
    sigma6 = np.zeros_like(sigma)
    D6 = np.zeros_like(D)
    sigma6[:, [0, 2, 1, 4]] = s4
    D6[:, [0, 2, 1, 4]] = d4
    two_d = overstress(s4, d4, flowing, RATE)
    three_d = overstress6(sigma6, D6, flowing, RATE)
    scale = np.abs(two_d).max()
    assert np.abs(three_d[:, [0, 2, 1, 4]] - two_d).max() <= 1e-12 * scale
    assert np.all(three_d[:, [3, 5]] == 0.0)


def test_simple_shear_adds_the_friction_rise():
    """Simple shear at rate ``g`` in any plane (``D_xy = D_xz = D_yz = g / 2`` one at a time,
    the others zero) under an isotropic pressure ``p``: the overstress is a shear stress
    ``delta_mu(I) p`` with ``I = g d / sqrt(p / rho_s)``, the law's friction rise."""
    rheology = InertialRheology()
    p, g = 2000.0, 30.0
    I = g * rheology.grain_diameter / np.sqrt(p / rheology.grain_density)
    rise = rheology.friction_rise * I / (rheology.inertial_number_i0 + I)
    for c in (3, 4, 5):
        sigma = np.array([-p, -p, -p, 0.0, 0.0, 0.0])
        D = np.zeros(6)
        D[c] = 0.5 * g
        out = overstress6(sigma, D, True, RATE)
        assert out[c] == pytest.approx(rise * p, rel=1e-12)
        assert np.all(out[[k for k in range(6) if k != c]] == 0.0)


def test_compiled_steps_with_the_overstress_equal_the_numpy_reference():
    """The small eccentric silo's half with the default law (the mu(I) overstress, d = 1 mm):
    from a discharging state (300 steps of fill, 400 of discharge), 200 more steps with
    transports by the compiled path and by the numpy reference: velocities, stresses, alpha
    and the flowing flags agree to 1e-9 of their scales (the eigen-solves differ in the last
    bits), with flowing cells present and the overstress acting (the same steps without it
    differ by more than 1e-6)."""
    cfg = small_silo(outlet_offset=0.03)
    assert cfg.material.law().rate is not None
    fast = SpaceModel(cfg, backend="numba", threads=1)
    state = fast.initial_state()
    while state.step < 300:
        fast.advance(state, 300 - state.step)
    fast.transport_step(state)
    fast.open_outlet(state)
    while state.step < 700:
        fast.advance(state, 700 - state.step)
    assert state.flowing.sum() > 20
    ref = SpaceModel(cfg, backend="numpy")
    a, b = state.copy(), state.copy()
    while a.step < 900:
        fast.advance(a, 900 - a.step)
    while b.step < 900:
        ref.advance(b, 900 - b.step)
    assert a.t == b.t
    for name in ("v", "sigma", "alpha", "eps_p", "flowing"):
        x, y = getattr(a, name), getattr(b, name)
        assert np.abs(x - y).max() <= 1e-9 * max(np.abs(y).max(), 1e-30), name
    plain = SpaceModel(cfg.with_(material={"rate_dependence": "none"}), threads=1)
    c = state.copy()
    while c.step < 900:
        plain.advance(c, 900 - c.step)
    assert np.abs(c.v - a.v).max() > 1e-6 * np.abs(a.v).max()
